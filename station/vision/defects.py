"""Surface defects of the honed bore wall: pores, scratches, burrs and chips (issue 23).

What fails a master cylinder in a plant is mostly its surface: a burr at a compensating
hole's edge cuts the seal cup, porosity of the casting and scratches of the honed bore
leak. This module finds each defect in one frame and measures it: kind, position (px),
length and width (px and mm) with standard uncertainties, and a confidence.

Why it is built this way. The honed wall is itself full of dark lines (the cross-hatch
at +/-30 deg, 3-8 % deep, up to three times that for single grooves), fine grain and
low-frequency blotches; a detector that thresholds darkness finds the honing before it
finds a pore. So the wall is *modelled* and only what the model cannot explain is a
defect (docs/surface.md has the figures behind each choice):

1. **The wall's level** (illumination, vignetting, blotches), on a half-resolution
   frame: a median over ~100 px at 1/8 scale (the holes inpainted first) finds what is
   clearly dark; with that and the holes weighted out, a normalised Gaussian mean over
   ~16 px follows the blotches. Relative darkness ``d = 1 - I / level``.
2. **The cross-hatch.** Its two line directions come from the frame's power spectrum
   (``honing_directions``). Each groove family is the mean of ``d`` along its own
   direction over ~80 px (the frame rotated so the family runs along rows, a box
   filter, rotated back), the holes and the dark marks weighted out, and is subtracted.
   A pore (compact) or a scratch (crossing the grooves) barely moves a mean along 80 px
   of groove.
3. **Candidates**: hysteresis components of the residual smoothed by 1 px, in robust
   standard deviations of the frame's own residual; and, apart from them, of the
   residual's mean along short lines in 12 directions (``_line_response``), for the
   faint thin scratches no pixel of which stands out. Pieces of one scratch are joined.
4. **Each candidate at full resolution**: a patch, the frame's level, the grooves
   re-estimated *locally* as 1-D profiles across their lines (0.5 px bins, the candidate
   masked out, backfitted in turn), the patch's own noise. A mark must be significant
   against that noise integrated over its area, and must not be the cross-hatch's residue
   (along a groove direction, too faint, too soft an edge, too broad).
5. **Kind and size.** Elongated (3:1, the blur taken out by a blurred-ellipse fit) is a
   scratch, else a pore. *Pore*: its floor's contrast c from the blurred-ellipse fit; its
   outline from the darkening's angular density round its centroid, which is c r^2 / 2
   whatever the blur (a Fourier series of the pixels' angles, to the order the blur
   resolves); its greatest Feret diameter and the extent across it from that outline.
   *Scratch*: its main line (branches of groove residue left out), its centre line
   followed (a robust straight line, then a polynomial through the cross profiles' peaks
   near it), its amplitude along it (each cross profile matched-filtered by the mean one,
   less its flanks), its extent (the best box, split at gaps) and each end at half its
   local height, its width from the mean cross profile as a blurred box with the
   camera's blur (from the holes' edges, else from its own cross profile, its ends and a
   prior, combined). A scratch the patch cuts is examined again in a patch grown along it.
6. **Burrs and chips at every hole's edge.** The holes are measured first
   (``measure_holes``, and by their rays alone those whose rim defects make the
   photometric fit run away). Along rays from each hole's centre, the share of "hole"
   (W - I) / (W - H) (wall level per angle, the hole's own level, grooves modelled on a
   ring beyond and put back outside the rim); each ray's edge is where that share first
   falls below 0.75 going out. The rim's low harmonics (centre offset, ovality) are
   fitted robustly and taken off; an edge moved into the hole is a burr (bright metal in
   the dark disc), moved out a chip (a dark notch in the wall). Heights are area-true
   (the share integrated across each ray's own band: blur moves light along a ray, not
   out of it), ends at half the local height along the rim.

Sizes are never pixel counts of a thresholded blob: they come from integrated darkening
and fitted edges, sub-pixel. ``length`` is the largest dimension (a pore's greatest Feret
diameter, a scratch's length along its centre line, a rim defect's arc along the rim);
``width`` the extent across (a pore's), the mean width (a scratch's) or the mean height
into or out of the hole (a burr's, a chip's). ``size_mm`` is the length: what a
specification limits ("no pore over 0.2 mm").

Thresholds were chosen on dev frames only (``sim.camera.defects.random_defect_frame``
seeds 7000-7349, clean and with defects); ``station bench defects`` reports on others.
"""

from __future__ import annotations

import warnings

import functools
from dataclasses import asdict, dataclass, replace

import cv2
import numpy as np
from scipy.ndimage import gaussian_filter1d, map_coordinates, maximum_filter1d
from scipy.special import ive, ndtr

from station.vision.edges import SMOOTH_SIGMA_PX
from station.vision.grooves import honing_directions
from station.vision.imageio import to_8bit, to_grey

KINDS = ("pore", "scratch", "burr", "chip")
#: the smallest noise a relative darkness can have: 8-bit quantisation, 1/sqrt(12) DN on
#: a wall of ~150 DN (a synthetic frame without grain or sensor noise has none at all,
#: and every rounding step would be "significant")
NOISE_FLOOR = 0.002


#: a dark disc at least this large is a hole, not a pore: the part's smallest
#: compensating hole is 0.7 - 0.125 = 0.575 mm (part spec ZDZG-22.2-12.3851), the
#: largest pore the issue names 0.5 mm. The bore scan takes nothing smaller for a hole
#: (``station.inspection.scan.ScanSettings.min_hole_mm``)
MIN_HOLE_DIAMETER_MM = 0.55
#: the share of "hole" below which a rim's ray has left whatever is darker than the wall
#: (a chip's floor, lit up to ~0.3 of the wall-to-hole step, stands well above it; a deep
#: groove beside a hole reads ~0.25 and the groove model takes most of that away)
RIM_FLOOR_CROSSING = 0.2
#: a ray's share falls below a crossing going out (``_rim_profile``) only where it stays
#: below it over the next this many px: the rim's blurred step, and the burr's metal or
#: the wall beyond it, hold for many px, where the noise inside a dim hole dips for a
#: pixel or two (bilinear samples 0.5 px apart share their pixels). On the wide bench's
#: dim, noisy holes (5-20 e-/DN, 30 % contrast) the share inside reads 1 +/- 0.1 a
#: sample, and a dip below 0.75 at one sample 14-18 px inside the rim, the share back
#: at 0.86-1 beyond it, was that ray's "edge": 0.03-0.07 mm "burrs" 3-12 px high on
#: clean frames 1097086, 1099092 and 1100029 (session 56)
RIM_HOLD_PX = 2.0
#: a group of candidates (``_group_collinear``) that is no defect has its strongest member
#: examined alone when its peak is at least this many times every other member's
GROUP_DOMINANT_SHARE = 2.0


@dataclass(frozen=True)
class DefectConfig:
    #: a dark disc at least this large is a hole, not a pore (:data:`MIN_HOLE_DIAMETER_MM`)
    min_hole_diameter_mm: float = MIN_HOLE_DIAMETER_MM
    #: the share of a hole's rays that must agree on its circle when the rim analysis
    #: measures it by its rays alone (``_measure_holes_for_rims``; ``MeasureConfig.
    #: min_inlier_fraction`` is 0.5). Its rim defects are the rays' outliers: a dim hole
    #: (33 % contrast) with two burrs and two chips had 103 of 218 rays agree (0.47), was
    #: no hole, and its four defects were lost (wide bench frame 129068). Over 1,400 wide
    #: and station frames the candidates of a hole's size that are no hole agree 0.29 at
    #: most (and their contrast, 0.10 at most, fails ``min_relative_contrast`` besides)
    rim_hole_min_inlier_fraction: float = 0.4
    #: ... and the confidence it must reach there (``MeasureConfig.min_confidence`` is
    #: 0.15): a dim hole's noisy rim (31 % contrast, 1.9 px of blur, rays' RMS 0.47 px)
    #: with a burr and two chips read 0.116, was no hole, and its defects were lost (wide
    #: bench frame 270025). The rims need its place to within a px, not its diameter. Over
    #: 400 fresh wide and station frames (1300000-199, 1310000-199) the candidates of a
    #: hole's size that are no hole and pass the inliers and the contrast read 0.027 at most
    rim_hole_min_confidence: float = 0.05
    #: a coarse candidate is measured for the rims from this share of the least hole's
    #: diameter: the coarse detector read a dim hole with two large burrs (wide bench frame
    #: 270027: 70 px) as a 44 px blob, under the 0.8 taken before; its rays then measure it
    #: whole, and only a disc of a hole's size is kept
    rim_hole_coarse_share: float = 0.5
    #: the honing cross-hatch's line directions (deg, image sense); None: estimated per
    #: frame from its power spectrum (``honing_directions``), falling back to +/-30 deg
    #: (the renderer's and the Sunnen/Nagel guides' typical cross-hatch half-angle)
    honing_angles_deg: tuple[float, float] | None = None
    default_honing_angle_deg: float = 30.0
    #: length (half-resolution px) over which a groove family is averaged along its
    #: lines: long against the largest pore (0.5 mm = 25 half-res px), short against the
    #: grooves' fading along their length (~100 px)
    groove_window_half_px: int = 41
    #: what is darker than this (relative darkness, after the coarse level and the
    #: grooves) is surely no wall texture and is weighted out of the finer level: pores
    #: are 40-85 % dark, the blotches' residue under the coarse level a few per cent
    dark_floor: float = 0.15
    #: the finer level's Gaussian (half-resolution px): follows the blotches' ~64 px
    #: features (renderer: 64 px cells, cubic), wide against a scratch (<= 6 px)
    level_sigma_half_px: float = 8.0
    #: candidate thresholds on the 1 px-smoothed half-resolution residual, in its
    #: robust standard deviations: a component must reach ``seed_k`` somewhere and is
    #: grown down to ``grow_k`` (dev frames: 5.5 keeps grain and groove crossings out
    #: of the candidates on clean walls in all but a few frames per hundred, which the
    #: full-resolution tests then drop)
    seed_k: float = 5.5
    grow_k: float = 3.0
    #: a candidate's region is grown at full resolution down to this share of its peak
    #: (or to ``grow_k`` of the noise, whichever is higher): a blurred edge's 20 % point
    #: lies ~0.8 blur outside it, and the integration reaches 5 px beyond the region
    grow_share: float = 0.2
    #: a region that is no defect is looked at again for a pore in its core: the part
    #: darker than ``core_share`` of its peak round the peak (a pore's floor; the groove
    #: residue joined to it is a fraction of that), standing only if it is at most
    #: ``core_max_share`` of the region (``_core_pore``)
    core_share: float = 0.5
    core_max_share: float = 0.7
    #: ... and only where its peak is this dark, away from the frame's border: a cavity's
    #: floor beyond doubt (the bench's pores 0.4-0.85; the residue that the wall model
    #: leaves where the frame cuts two deep grooves reached 0.28 and was read as a
    #: 0.18 mm pore, wide clean frame 1082046)
    core_min_peak: float = 0.4
    #: the line response (``_line_response``): its length (quarter-resolution px: 40
    #: full-res px, the bench's shortest scratch above the limit is 20 px and is seen by
    #: the blob seed), and its seed and growth thresholds in its own robust sigmas (dev
    #: frames: the honing's residue off the groove directions stays under ~5)
    line_length_quarter_px: int = 10
    line_seed_k: float = 6.0
    line_grow_k: float = 3.0
    #: a furrow of a candidate that holds several (two scratches crossing: ``_furrows``)
    #: is examined within this many px of its line: half the widest scratch (0.06 mm)
    #: and the blur's reach beyond its edge
    furrow_half_band_px: float = 8.0
    #: at most this many candidates per frame are examined (the most significant):
    #: a bound on the time of a pathological frame, far above a real wall's count
    max_candidates: int = 40
    #: a pore or scratch must be this significant at full resolution: its integrated
    #: darkening over its area against the patch's own noise integrated the same way
    #: (dev frames: the faintest true scratch above the limits 11.7; the cross-hatch's
    #: residue reaches 20 and more, and is told apart by the tests below, not by this)
    min_significance: float = 8.0
    #: ... and this dark in the mean over its core (relative darkness): grain and noise
    #: integrated over a large faint area can be significant without being a defect
    min_mean_darkness: float = 0.06
    #: a pore's floor must be at least this dark (relative darkness of the fitted blurred
    #: ellipse): a cavity in shadow is 40-85 % darker than the wall (the renderer's and
    #: the holes' range); half the lowest leaves room for the fit's error on small blurred
    #: pores, and stays far above the cross-hatch's residue (dev frames: 0.05-0.1)
    min_pore_contrast: float = 0.2
    #: ... and a pore this long (px) or more at least this dark in the mean over its
    #: region: a cavity larger than a few blurs holds its floor's darkness over most of its
    #: area (dev frames 7000-7099 and wide 81000-81099, 147 true pores 0.12-0.5 mm long:
    #: 0.22 and more, 5th percentile 0.29), where the cross-hatch's residue at a crossing
    #: of two deep grooves, fitted to a steep blurred ellipse, is faint over a broad
    #: region (0.06-0.16, 0.15-0.34 mm long, most at the frame's border where the grooves'
    #: means end): 8 false defects on wide seeds 81000-87000 (1,200 frames), 6 of them cut by
    #: the border, and no true pore lost there nor on station seeds 60000 and 93000
    broad_pore_px: float = 12.0
    min_broad_pore_darkness: float = 0.17
    #: a pore is a cavity with one dark floor: the mean darkness over its region (all of
    #: it at or outside the floor's blurred edge) can exceed the fitted floor's contrast
    #: only by noise. More than this times it, and the blurred ellipse did not describe
    #: the mark: a residue peaked where two deep grooves cross, whose arms run out along
    #: them and draw the fit to a broad faint ellipse under a core darker than its floor
    #: (session 56: wide clean frame 1100002, a 0.40 mm "pore" at 1.30; on frames with
    #: defects 1.12-2.13, four false pores; 1,662 true pores of seventeen sets at most 0.93
    #: over a whole region, 0.99 over a core, ``_core_pore``, whose pixels are its darker half)
    max_pore_darkness_over_floor: float = 1.1
    #: a pore's rim is a sharp edge blurred by the camera alone: a fitted edge blur beyond
    #: this (px) is a soft shading of the wall, not a cavity (the renderer's and the
    #: endoscope's envelope is 0.8-2 px; dev frames' texture blobs fit 3-3.5 px)
    max_edge_blur_px: float = 2.8
    #: a candidate elongated along a groove direction (within this angle) is groove
    #: residue, not a scratch: the bench's scratches cross the hatch by >= 10 deg (measured
    #: down to 8.9 on dev frames); residue further off is caught by its width or contrast.
    #: 7.5, not 6: near a frame's edge the endoscope's distortion bends a groove's local
    #: direction by a few degrees, and a 0.29 mm piece of one at 6.6 deg from the hatch was
    #: the whole-surface scan's one false scratch (station bench surface, seed 23300);
    #: the defect bench's recall and sizes are the same at 6 and 8 (seed 80000)
    groove_alignment_deg: float = 7.5
    #: ... and crosses no more of the family's lines than this over its length (px across
    #: them: the chord's length x sin of its angle off the family). A groove is a line of
    #: its family and its residue runs along it (clean frames: 76 of 77 station, 332 of
    #: 345 wide and 158 of 176 twin pieces within 4 px; 3 at the frame's edge, where the
    #: endoscope's distortion bends the grooves, 8.5-17 px), where a scratch a few degrees
    #: off the hatch crosses the lines (a 2 mm scratch 4.7 deg off: 16 px). A mark that
    #: crosses more is judged as any scratch is (session 49)
    hatch_cross_px: float = 8.0
    #: ... but only when the two families read are mirrored about the bore's axis within
    #: this (deg), as a hatch is: a long dark scratch a few degrees off the hatch can draw
    #: the frame's reading of a family to itself (a 640 x 512 frame: 24.3 and 150.0 deg
    #: read for a 30 deg hatch), and the true grooves then cross "the family" by 10-50 px
    hatch_mirror_deg: float = 1.0
    #: ... unless it ends in cuts: a scratch is a furrow and ends in a step of its darkness
    #: blurred by the camera alone, where a groove fades along its length over tens of px
    #: (the renderer's amplitude field, ~96 px cells; worn stones) and runs on. At each end
    #: the raw darkness along the line (the grooves *not* removed) is fitted as a blurred
    #: step (``_square_end``); both ends must be in the frame and one of them square: no
    #: wider than this (px, Gaussian sigma) ...
    square_end_max_width_px: float = 4.0
    #: ... and each with a step of at least this share of the mark's darkness inside it
    #: (the mark ends there). Session 45,
    #: dev seeds (station envelope 520000-520059 and clean 1500000-1500099; the twin's
    #: optics 2070000-2070059 and clean 2060000-2060059; scratches drawn 0-7.5 deg off the
    #: hatch), the marks along the hatch that passed every other test: with both ends
    #: square, 135 of 167 true scratches kept and none of 172 groove pieces and duplicates; one
    #: square end and the other of any width (a step of 0.8) kept 151 and none, but read a
    #: groove piece on a fresh twin frame
    square_end_min_height: float = 0.8
    #: ... and its other end no wider than this (a ragged or bent end fits wider than the
    #: blur; a groove's fade, tens of px): on the dev marks above 144 of 167 true scratches
    #: kept (135 with both ends within 4 px) and still none of the 172 others; a fresh twin
    #: frame's groove piece (2093047) had ends of 0.6 and 11.7 px
    square_end_other_max_width_px: float = 8.0
    #: an end where the mark runs on at more than this share of its darkness, while the
    #: other end is square, makes it a piece of a longer mark: measured again with its line
    #: left out of the wall model's grooves (``_examine``)
    square_end_max_run_on: float = 0.2
    #: ... and such a mark must be at least this dark (the fitted cross profile's
    #: contrast): the twin's deep grooves (10 % on average, up to 30 %) leave pieces of
    #: 0.12-0.13 there; the true scratches along the hatch fitted 0.13 and more
    aligned_min_scratch_contrast: float = 0.14
    #: the least angle (deg) at which a groove family crosses a mark along the other for
    #: its grooves to be read along their own lines and taken out of the mark's ends'
    #: read (``_end_steps``); nearer, the lines beside the mark run along it
    crossing_min_deg: float = 20.0
    #: a furrow no wider than this (mm): the bench's scratches are 0.015-0.06 mm wide;
    #: a broad dark band is wear or the cross-hatch's residue (dev frames: 14-28 px "scratches")
    max_scratch_width_mm: float = 0.1
    #: a scratch's floor must be at least this dark (the cross profile's fitted contrast):
    #: the bench's furrows are 20-60 % dark, a thin one's contrast is fitted lower (its
    #: width and contrast trade off under the blur): dev frames' true scratches >= 0.126,
    #: the cross-hatch's residue that passed every other test <= 0.095 (300 frames)
    min_scratch_contrast: float = 0.11
    #: a scratch is one straight furrow: at least this share of the oriented gradient
    #: energy over its region (``_along_share``) must run along its own direction rather
    #: than along a groove's or elsewhere.  Deep grooves crossing each other leave a V or
    #: an X of residue whose long axis is the hatch's bisector, 30 deg off either family,
    #: so the alignment test above passes it (wide bench seeds 82000 / 1082000, 100 + 100
    #: frames: 7 of the 14 false defects, one a 1.27 mm "scratch"); their arms lie along
    #: the grooves.  True scratches 0.36-0.99 (median 0.90-0.93; 502 on station and wide
    #: seeds 81000, 82000, 83000), such residue 0.06-0.25 (9)
    min_scratch_along_share: float = 0.3
    #: ... and its contrast carried along its own direction (the fitted contrast times the
    #: square root of that share: the share is one of gradient energy, which goes as the
    #: contrast squared) at least this.  The grooves' residue that passes the two gates
    #: above can be faint *and* ragged at once. Session 58, every scratch measurement that
    #: passed the other tests with these three gates off, on two surveys: the first (station
    #: 111000, 113000, 118000; the twin's 2088000-2088059; along the hatch 542000; wide
    #: 94000, 97000, 116000, 119000: 670 true, 82 false), whose false marks that pass the
    #: two gates read 0.065-0.083 (all five on wide 116000; three on clean frames), the true
    #: ones 0.107 and more; and a fresh one (wide 120000, 125000 at 22 deg, 128000, 129000 at
    #: 26 deg: 411 true, 100 false), where a faint 0.40 mm scratch among deep grooves read
    #: 0.082 (129012: contrast 0.125, share 0.43) and the false ones 0.097 (one). Set
    #: between the false ones' 0.070 and that scratch's 0.082: a thin margin either side
    min_scratch_line_contrast: float = 0.076
    #: length/width at which a dark mark is a scratch rather than a pore (pores of the
    #: envelope are at most 1.6:1, ragged outlines up to ~2:1; scratches at least 4:1)
    scratch_elongation: float = 3.0
    #: the largest burr height / chip depth examined (mm): the band each side of a rim
    #: that is integrated; the bench's rim defects are up to 0.08 mm
    rim_reach_mm: float = 0.12
    #: a ray's edge is where the share of "hole", (W - I) / (W - H), first falls below
    #: this going out: high, so that a groove touching the rim does not carry it on (a
    #: groove 24 % dark beside a hole 40 % dark holds a share of 0.6), low enough that a
    #: chip's floor (at most 15 % of the step above the hole's level) still counts as hole
    rim_crossing: float = 0.75
    #: a rim defect must stand out of the rim's profile by this many of its robust
    #: standard deviations (smoothed over 1 px of arc) ...
    rim_k: float = 5.0
    #: ... and by at least this much (px): a clean rim's edge wanders by ~0.1-0.3 px where
    #: grooves cross it, and by up to ~0.7 px along a groove that runs tangent to the rim
    #: and touches it (dev frames: a 40 px "chip" 0.55 px deep)
    rim_min_height_px: float = 1.0
    #: ... over at least this much of the rim (px of arc)
    rim_min_length_px: float = 2.0
    #: rim defects are found on the share of "hole" averaged along the rim over this
    #: Gaussian (px of arc) before its crossing is taken (measured on the raw one)
    rim_find_smooth_px: float = 1.0
    #: the grooves at a rim: a profile on each side of the hole along their lines
    rim_groove_sides: bool = True
    #: a chip is a notch: beyond it the wall comes back.  A dark band that runs on from
    #: it outwards along a groove's direction (``_groove_run_on``: the darkest line of the
    #: hatch's two directions through the notch, read past the rim's blur) at more than
    #: this share of the hole's darkness is a deep groove running into the rim, not a
    #: chip.  Wide bench seeds 82000 (150 frames) and 1082000 (100 clean): true chips
    #: 0.05 at the median, at most 0.38 (92); the chips that were deep grooves 0.60-0.89
    #: (3 of 5 false chips; the other two, 1.5-1.7 px shallow dents, 0.28-0.30).  Since
    #: session 40 the upper quartile of the lines through the notch, not the darkest line:
    #: 128 true chips (wide seeds 82000-82149 and 78000-78059 at a 22 deg hatch) at most
    #: 0.29; the deep grooves left by the other tests 0.48 and 0.77.  Since session 50 the
    #: lines start where each leaves the notch: 153 true chips (wide seeds 82000-82059,
    #: 74000-74059, 78000-78059 at 22 deg, station 60000-60059) at most 0.22 (0.29 before),
    #: a deep groove meeting the rim obliquely 1.0 (0.11), two in a V 0.45 (0.19)
    chip_groove_share: float = 0.4
    #: a chip is a notch, and beyond its ends the rim's wall comes back.  A dark band that
    #: runs on past both its ends along a groove's line through it or just outside it
    #: (``_groove_along_rim``) at more than this share of the hole's darkness, the share at
    #: which the rim's own edge is read (``rim_crossing``), would be read as hole there by
    #: itself: a deep groove grazing the rim, not a chip.  Session 54: 276 true chips
    #: (wide seeds 94000-94099, 95000-95099, 82000-82059, 74000-74059, 78000-78059 at a 22
    #: deg hatch, station 91000-91059) at most 0.60 (a chip a groove runs through, on a
    #: 36 %-dark hole), all others under 0.3; a groove darker than the hole grazing its
    #: rim (wide clean frame 1094030, a 0.44 mm "chip") and the rendered grazing grooves
    #: of the unit test 1.14-1.33 (1094030: 1.78)
    chip_groove_along_share: float = 0.75
    #: standard uncertainties from the fits' and integrals' noise are multiplied by this,
    #: the factor the hole measurement's white-noise u took until round 12 of the vision
    #: stage (docs/vision-history.md): the texture is correlated noise the formulas do not
    #: see; the defect bench's share within 2 u was judged with it
    uncertainty_factor: float = 1.5
    #: ... and added in quadrature to a model term (px) for what the noise does not
    #: explain: where an edge lies that the blur hides (a ragged end, a pore's outline
    #: beyond the harmonics the blur resolves; about half a blur per edge), and for a
    #: scratch's length a share of it (its centre line's bend and the fading of its ends).
    #: Set on dev frames (seeds 7200-7349) for +/-2u to hold 94-97 % per kind and size
    model_u_px: tuple[tuple[str, float, float], ...] = (("pore", 0.7, 0.7), ("scratch", 1.0, 0.7),
                                                         ("burr", 1.0, 0.6), ("chip", 1.0, 0.6))
    scratch_length_u_share: float = 0.03
    #: two scratches of one frame are one furrow (``_scratch_gap``) when an end of each
    #: faces the other within this gap (px) and turn (deg), and the raw darkness along
    #: the gap holds this share of the pieces' own
    scratch_join_gap_px: float = 200.0
    scratch_join_turn_deg: float = 20.0
    scratch_join_dark_share: float = 0.5
    #: a scratch's furrow followed past its measured end (``_track_on``): at most so far
    #: (px), turning at most so much across per 2 px step (px), taken when its first
    #: ``track_min_px`` keep ``track_run_share`` of the scratch's own raw contrast
    track_max_px: float = 800.0
    track_turn_px: float = 0.1
    track_min_px: float = 12.0
    track_run_share: float = 0.7
    #: ... and the whole stretch this share (a groove's residue that a faint scratch's end
    #: runs into reads 0.76 of it; a scratch's own stretch along the hatch 1.03-1.24)
    track_hold_share: float = 0.9
    #: a run on off the hatch (``groove_alignment_deg`` or more from each family) must hold
    #: this share of the scratch's own darkness with the grooves removed (the wall model's
    #: residual, median along each): there no groove's line mean takes a furrow in, and a
    #: run on that the raw darkness carries but the residual does not is a groove the
    #: scratch meets at a shallow angle (``_run_on_grooves_only``). Session 58: the twin's
    #: 2130019 and 2115051 ran on 15 and 14 px at 0.17 and 0.26 of the body's residual
    #: (0.077 mm off each; the benches found 2110011 and 2121072 too); the one true run on
    #: of 600 frames (twin 2088000, 2091000, 2130000, station 110000, 130000, wide 94000,
    #: 100 each) held 0.76 (2091057)
    track_residual_share: float = 0.5
    #: ... followed on over a dip below half its contrast as long as this (px): a deep
    #: groove crossing a thin scratch at the hatch's angle darkens its flanks as much as
    #: its core over ~2 groove widths, and the furrow on beyond was left unread (6 px
    #: until session 50: a 17.3 mm scratch's piece stopped 2.4 mm short of a frame's
    #: border, and the rest, part of the same candidate, was never measured:
    #: whole-surface part 24602)
    track_gap_px: float = 24.0


@dataclass(frozen=True)
class Defect:
    """One defect found in a frame (image px; mm when the scale is known).

    ``length``: the largest dimension (pore: greatest Feret diameter; scratch: along
    its centre line; burr/chip: along the rim). ``width``: across it (pore), the mean
    width (scratch), the mean height into the hole (burr) or depth out of it (chip).
    ``size_mm`` is the length in mm, ``size_u_mm`` its standard uncertainty (k = 1).
    ``angle_deg``: direction of the length (pore, scratch; image sense, 0-180) or where
    round its hole (burr, chip; 0-360). ``hole``: the index of a rim defect's hole in
    the list of holes examined. ``significance``: integrated darkening over its noise.
    """

    kind: str
    x_px: float
    y_px: float
    length_px: float
    width_px: float
    confidence: float
    angle_deg: float
    length_u_px: float
    width_u_px: float
    significance: float
    partial: bool = False
    hole: int | None = None
    length_mm: float | None = None
    width_mm: float | None = None
    size_mm: float | None = None
    size_u_mm: float | None = None
    width_u_mm: float | None = None
    #: a scratch's centre line, end to end (image px, a point every ~10 px): how the
    #: whole-surface scan joins a scratch's pieces from several frames (not printed)
    line_px: tuple[tuple[float, float], ...] | None = None

    def to_dict(self) -> dict:
        return {k: v for k, v in asdict(self).items() if v is not None and k != "line_px"}


# ---------------------------------------------------------------- helpers
def _mad_sigma(v: np.ndarray) -> float:
    """Robust standard deviation (MAD x 1.4826, exact for Gaussian data)."""
    v = v[np.isfinite(v)]
    if v.size == 0:
        return float("nan")
    if v.size > 40000:  # a median's precision needs no more (its relative error ~ 1/sqrt(n))
        v = v[:: v.size // 20000]
    m = np.median(v)
    return float(1.4826 * np.median(np.abs(v - m)))


def _confidence(significance: float, threshold: float) -> float:
    """0..1 from a significance: 0.5 at the acceptance threshold, ~0.95 at 1.6x it."""
    return float(1.0 / (1.0 + np.exp(-(significance - threshold) / (0.2 * threshold))))


def _circ_diff_deg(a: float, b: float, period: float = 180.0) -> float:
    return abs((a - b + period / 2) % period - period / 2)


def _near_hatch(angle_deg: float, angles_deg, cfg: "DefectConfig") -> float | None:
    """The groove family (of ``angles_deg``) within ``cfg.groove_alignment_deg`` of
    ``angle_deg`` nearest it, or None."""
    near = [g for g in angles_deg if _circ_diff_deg(angle_deg, g) < cfg.groove_alignment_deg]
    return min(near, key=lambda g: _circ_diff_deg(angle_deg, g)) if near else None


def _along_hatch(angle_deg: float, length_px: float, angles_deg, cfg: "DefectConfig") -> bool:
    """Whether a mark of direction ``angle_deg`` and length ``length_px`` runs along a
    groove family (``angles_deg``, the frame's two): within ``cfg.groove_alignment_deg``
    of one and, when the two are mirrored about the bore's axis as a hatch is (within
    ``cfg.hatch_mirror_deg``), crossing no more than ``cfg.hatch_cross_px`` of its lines
    over its length."""
    g = _near_hatch(angle_deg, angles_deg, cfg)
    if g is None:
        return False
    if len(angles_deg) != 2 or _circ_diff_deg(float(angles_deg[0]), -float(angles_deg[1])) > cfg.hatch_mirror_deg:
        return True  # the families read are not a mirrored pair: no line to cross is known
    return bool(length_px * np.sin(np.deg2rad(_circ_diff_deg(angle_deg, g))) <= cfg.hatch_cross_px)


# ---------------------------------------------------------------- the wall, whole frame
def _family_mean(values: np.ndarray, weights: np.ndarray, angle_deg: float, window: int) -> np.ndarray:
    """Weighted mean of ``values`` along lines of direction ``angle_deg`` (image sense),
    over ``window`` px: the frame rotated so those lines run along rows, a box filter of
    the weighted values and of the weights, rotated back."""
    h, w = values.shape
    m = cv2.getRotationMatrix2D((w / 2.0, h / 2.0), angle_deg, 1.0)
    c, s = abs(np.cos(np.deg2rad(angle_deg))), abs(np.sin(np.deg2rad(angle_deg)))
    w2, h2 = int(w * c + h * s) + 4, int(w * s + h * c) + 4
    m[0, 2] += (w2 - w) / 2.0
    m[1, 2] += (h2 - h) / 2.0
    num = cv2.blur(cv2.warpAffine(values * weights, m, (w2, h2)), (window, 1))
    den = cv2.blur(cv2.warpAffine(weights, m, (w2, h2)), (window, 1))
    mean = num / np.maximum(den, 1e-3)
    mean[den < 0.05] = 0.0  # lines with almost nothing to average: no groove estimate
    return cv2.warpAffine(mean, cv2.invertAffineTransform(m), (w, h))


@functools.lru_cache(maxsize=8)
def _line_support(shape: tuple[int, int], angle_deg: float, window: int) -> np.ndarray:
    """Share of each pixel's ``window`` px line of direction ``angle_deg`` that lies in the
    frame. In a frame's corners the lines of a groove family that runs across the corner
    hold a few pixels only; a groove there has no estimate and its darkness stood as a
    false "pore" (bench frames: the same corner pixel in 1 frame in 200)."""
    ones = np.ones(shape, np.float32)
    h, w = shape
    m = cv2.getRotationMatrix2D((w / 2.0, h / 2.0), angle_deg, 1.0)
    c, s = abs(np.cos(np.deg2rad(angle_deg))), abs(np.sin(np.deg2rad(angle_deg)))
    w2, h2 = int(w * c + h * s) + 4, int(w * s + h * c) + 4
    m[0, 2] += (w2 - w) / 2.0
    m[1, 2] += (h2 - h) / 2.0
    den = cv2.blur(cv2.warpAffine(ones, m, (w2, h2)), (window, 1))
    support = cv2.warpAffine(den, cv2.invertAffineTransform(m), (w, h))
    support.setflags(write=False)
    return support


@dataclass
class _Wall:
    """The frame's wall model at half resolution and what it leaves over."""

    residual: np.ndarray  # relative darkness less the cross-hatch (half res)
    valid: np.ndarray  # bool: wall, clear of holes' rim zones (half res)
    noise: float  # robust std of the 1 px-smoothed residual
    angles_deg: tuple[float, float]
    level: np.ndarray  # the wall's level (DN, half res), blotches and illumination


def _half(image: np.ndarray) -> np.ndarray:
    h, w = image.shape
    return cv2.resize(image[: h // 2 * 2, : w // 2 * 2].astype(np.float32), (w // 2, h // 2),
                      interpolation=cv2.INTER_AREA)


def _hole_zone(shape: tuple[int, int], holes, reach_px: float, scale: float = 1.0, offset: float = 0.0) -> np.ndarray:
    """Mask of the holes' discs plus ``reach_px`` beyond their rims (full-res px), on a
    grid of ``scale`` (0.5: half resolution, whose pixel j is centred on full px 2j+0.5)."""
    zone = np.zeros(shape, np.uint8)
    for h in holes:
        r = (h.diameter_px / 2.0 + reach_px) * scale
        cx, cy = (h.x_px - offset) * scale, (h.y_px - offset) * scale
        cv2.circle(zone, (int(round(cx * 16)), int(round(cy * 16))), int(round(r * 16)), 1, -1, cv2.LINE_8, 4)
    return zone.astype(bool)


def model_wall(image: np.ndarray, holes, reach_px: float, cfg: DefectConfig,
               largest_mark_px: float | None = None) -> _Wall:
    """The wall's level and cross-hatch over the whole frame (half resolution).

    Two levels: a coarse one (a median over ~100 px at 1/8 scale, the holes inpainted
    first so they do not pull it) finds, at quarter resolution, what is clearly dark
    (pores, dark scratches); with those and the holes weighted out, a finer one (a
    normalised Gaussian mean over ~16 px) follows the blotches, whose ~64 px features
    the coarse median cannot: left in, they came through the groove removal as faint
    blobs and streaks of the size of a large pore (dev frames: most of the first
    version's false pores). The grooves are then removed from the half-resolution
    darkness under the finer level, the dark marks weighted out of their means.
    ``largest_mark_px``: the largest dark mark that is no hole (px; a pore): the coarse
    median and the coarse grooves' means reach past it (at the station's 0.010 mm/px
    their own ~100 and ~84 px already do).
    """
    small = _half(image)
    h, w = small.shape
    zone = _hole_zone((h, w), holes, reach_px, 0.5, 0.5)
    valid = ~zone
    # the coarse level, at 1/8 scale
    g = 4
    tiny = cv2.resize(small[: h // g * g, : w // g * g], (w // g, h // g), interpolation=cv2.INTER_AREA)
    tiny_zone = cv2.resize(zone[: h // g * g, : w // g * g].astype(np.float32), (w // g, h // g),
                           interpolation=cv2.INTER_AREA) > 0
    t8 = np.clip(np.rint(tiny), 0, 255).astype(np.uint8)
    if tiny_zone.any():
        t8 = cv2.inpaint(t8, cv2.dilate(tiny_zone.astype(np.uint8), np.ones((3, 3), np.uint8)), 3, cv2.INPAINT_TELEA)
    # the median's window (1/8 scale): 13 px (104 full px), or 1.8x the largest dark mark
    # that is no hole if more (a finer camera's pores are larger in px: a 0.42 mm pore at
    # 0.005 mm/px, 84 px, pulled a 104 px median down to its own level, was never marked
    # dark, and read 15 % narrow)
    k_med = 13 if not largest_mark_px else max(13, int(np.ceil(1.8 * largest_mark_px / 8.0)) | 1)
    coarse8 = cv2.GaussianBlur(cv2.medianBlur(t8, k_med).astype(np.float32), (0, 0), 2.0,
                               borderType=cv2.BORDER_REPLICATE)
    # what is clearly dark, at quarter resolution (grooves removed as below, coarsely)
    h4, w4 = h // 2, w // 2
    quarter = cv2.resize(small[: h4 * 2, : w4 * 2], (w4, h4), interpolation=cv2.INTER_AREA)
    valid4 = cv2.resize(valid[: h4 * 2, : w4 * 2].astype(np.uint8), (w4, h4), interpolation=cv2.INTER_NEAREST) > 0
    dark4 = 1.0 - quarter / np.maximum(cv2.resize(coarse8, (w4, h4), interpolation=cv2.INTER_LINEAR), 1.0)
    dark4[~valid4] = 0.0
    if cfg.honing_angles_deg is not None:
        angles = tuple(a % 180.0 for a in cfg.honing_angles_deg)
    else:
        coarse = cv2.resize(coarse8, (w, h), interpolation=cv2.INTER_LINEAR)
        darkness = 1.0 - small / np.maximum(coarse, 1.0)
        angles = honing_directions(darkness, valid, cfg.default_honing_angle_deg)
    # the grooves' means along their lines here take in the dark marks too: over no less
    # than 1.5x the largest mark (a finer camera's pores), lest a pore be its line's mean
    win4 = cfg.groove_window_half_px // 2 | 1
    if largest_mark_px:
        win4 = max(win4, int(np.ceil(1.5 * largest_mark_px / 4.0)) | 1)
    res4 = cv2.GaussianBlur(_remove_grooves(dark4, valid4.astype(np.float32), angles, win4, valid4), (0, 0), 0.7)
    noise4 = _mad_sigma(res4[valid4])
    dark = (res4 > max(cfg.dark_floor, cfg.seed_k * noise4)).astype(np.uint8)
    dark = cv2.resize(cv2.dilate(dark, np.ones((3, 3), np.uint8)), (w, h), interpolation=cv2.INTER_NEAREST)
    if dark.shape != (h, w):
        dark = cv2.copyMakeBorder(dark, 0, h - dark.shape[0], 0, w - dark.shape[1], cv2.BORDER_REPLICATE)
    weights = valid.astype(np.float32) * (1.0 - dark.astype(np.float32))
    sig = cfg.level_sigma_half_px
    num = cv2.GaussianBlur(small * weights, (0, 0), sig, borderType=cv2.BORDER_REFLECT)
    den = cv2.GaussianBlur(weights, (0, 0), sig, borderType=cv2.BORDER_REFLECT)
    coarse_half = cv2.resize(coarse8, (w, h), interpolation=cv2.INTER_LINEAR)
    level = np.where(den > 0.05, num / np.maximum(den, 1e-6), coarse_half).astype(np.float32)
    darkness = 1.0 - small / np.maximum(level, 1.0)
    darkness[~valid] = 0.0
    # where a groove family's lines hold less than a third of their window in the frame
    # (the frame's corners) the grooves are not known: no candidates there
    for a in angles:
        valid &= _line_support((h, w), round(float(a), 1), cfg.groove_window_half_px) >= 1.0 / 3.0
    residual = _remove_grooves(darkness, weights, angles, cfg.groove_window_half_px, valid)
    noise = max(_mad_sigma(cv2.GaussianBlur(residual, (0, 0), 1.0)[valid]), NOISE_FLOOR)
    return _Wall(residual, valid, float(noise), angles, level)


def _remove_grooves(darkness: np.ndarray, weights: np.ndarray, angles, window: int, valid: np.ndarray) -> np.ndarray:
    """``darkness`` less each groove family's mean along its lines, in turn."""
    residual = darkness.copy()
    for a in angles:
        residual -= _family_mean(residual, weights, a, window)
    residual[~valid] = 0.0
    return residual


def _line_response(wall: _Wall, cfg: DefectConfig) -> np.ndarray:
    """The residual's mean along short lines, the best of 12 directions 15 deg apart
    (those within ``groove_alignment_deg`` of a groove direction left out), in units of
    each direction's own robust spread; at quarter resolution over 10 px (40 full-res
    px), brought back to half resolution. A faint thin scratch (a 20 % dark furrow 1.7 px
    wide under 1.9 px of blur on 5 % grain) is ~1.5 sigma per pixel and never reaches the
    blob seed; along 40 px of its length it stands out ~6x more (dev frames: three such
    scratches of 90-140 px missed without it)."""
    h, w = wall.residual.shape
    h4, w4 = h // 2, w // 2
    q = cv2.resize(np.where(wall.valid, wall.residual, 0.0).astype(np.float32)[: h4 * 2, : w4 * 2], (w4, h4),
                   interpolation=cv2.INTER_AREA)
    v = cv2.resize(wall.valid.astype(np.float32)[: h4 * 2, : w4 * 2], (w4, h4), interpolation=cv2.INTER_AREA)
    best = np.zeros((h4, w4), np.float32)
    for a in np.arange(0.0, 180.0, 15.0):
        if _near_hatch(float(a), wall.angles_deg, cfg) is not None:
            continue
        mean = _family_mean(q, (v > 0.99).astype(np.float32), float(a), cfg.line_length_quarter_px)
        inside = v > 0.99
        z = mean / max(_mad_sigma(mean[inside]), NOISE_FLOOR / 5.0)  # a mean over ~25 half-res px
        np.maximum(best, np.where(inside, z, 0.0), out=best)
    up = cv2.resize(best, (w4 * 2, h4 * 2), interpolation=cv2.INTER_LINEAR)
    if up.shape != (h, w):
        up = cv2.copyMakeBorder(up, 0, h - up.shape[0], 0, w - up.shape[1], cv2.BORDER_REPLICATE)
    return up


def _candidates(wall: _Wall, cfg: DefectConfig) -> list[tuple[np.ndarray, int, tuple[int, int, int, int], float]]:
    """Candidates (half res), most significant first, as (label image, label, box x0,
    y0, x1, y1, peak in sigmas): hysteresis components of the 1 px-smoothed residual,
    then those of the line response that touch none of them (a faint scratch). The two
    are labelled apart: grown together, a scratch's line response merged it with pores
    and groove residue beside it (dev frames: scratch recall 117 -> 112 of 121)."""
    smooth = cv2.GaussianBlur(wall.residual, (0, 0), 1.0)
    smooth[~wall.valid] = 0.0
    z = (smooth / max(wall.noise, 1e-9)).astype(np.float32)
    out = []
    blobs = np.zeros(z.shape, bool)
    for response, grow_k, seed_k in ((z, cfg.grow_k, cfg.seed_k),
                                     (None, cfg.line_grow_k, cfg.line_seed_k)):
        if response is None:
            response = (_line_response(wall, cfg) * wall.valid).astype(np.float32)
            # only where no blob candidate is near (30 full-res px): the line response of a
            # scratch the blob seed found, spread along its groove-residue neighbours,
            # grouped with it and dragged its region along them (dev frames)
            grow = (response > grow_k) & ~cv2.dilate(blobs.astype(np.uint8), np.ones((31, 31), np.uint8)).astype(bool)
        else:
            grow = response > grow_k
        n, labels, stats, _ = cv2.connectedComponentsWithStats(grow.astype(np.uint8), 8, cv2.CV_32S)
        if n <= 1:
            continue
        peak = np.zeros(n, np.float32)
        np.maximum.at(peak, labels.ravel(), response.ravel())
        for i in np.flatnonzero(peak >= seed_k):
            if i == 0:
                continue
            x, y, bw, bh, _area = stats[i]
            out.append((labels, int(i), (int(x), int(y), int(x + bw), int(y + bh)), float(peak[i])))
            if response is z:
                blobs[y:y + bh, x:x + bw] |= labels[y:y + bh, x:x + bw] == i
    out.sort(key=lambda c: -c[3])
    return out[: cfg.max_candidates]


def _seed_in_box(labels: np.ndarray, label: int, box: tuple[int, int, int, int]) -> np.ndarray:
    """The half-resolution component ``label`` as a full-resolution mask over ``box``
    (half-res pixel j covers full pixels 2j and 2j + 1)."""
    x0, y0, x1, y1 = box
    hx0, hy0 = x0 // 2, y0 // 2
    hx1, hy1 = min((x1 + 1) // 2, labels.shape[1]), min((y1 + 1) // 2, labels.shape[0])
    comp = labels[hy0:hy1, hx0:hx1] == label
    up = np.repeat(np.repeat(comp, 2, axis=0), 2, axis=1)
    out = np.zeros((y1 - y0, x1 - x0), bool)
    sub = up[y0 - 2 * hy0:, x0 - 2 * hx0:][: y1 - y0, : x1 - x0]
    out[: sub.shape[0], : sub.shape[1]] = sub
    return out


def _furrows(seed: np.ndarray, band_px: float = 3.0, min_len_px: float = 40.0, min_turn_deg: float = 15.0,
             max_lines: int = 3, max_solidity: float = 0.6) -> list[tuple[float, float, float, float]]:
    """The straight furrows a candidate's seed holds when it holds more than one (two
    scratches crossing, an X or a V of them: one connected candidate), as lines (a point
    x, y, a direction in rad, and how far a bend of 2.5 % of its length may carry the
    furrow off it: box px); [] when it is one mark. Found one after another
    by a Hough transform of the seed's half-resolution pixels: the line with most pixels
    within ``band_px`` (half-res px), then the next among those left, at least
    ``min_turn_deg`` off every line before; each must run ``min_len_px`` (full px), and
    together they must hold 85 % of the seed. A seed that fills more than
    ``max_solidity`` of its convex hull is a blob (a pore: any band through it holds
    pixels), not furrows."""
    yy, xx = np.nonzero(seed[::2, ::2])  # the seed is the half-res candidate, doubled
    if yy.size < min_len_px:  # fewer half-res pixels than two furrows' least length
        return []
    pts = np.column_stack([xx, yy]).astype(np.float64)
    # one mark first (most candidates): its principal axis holds it, bent as a scratch
    # may be (2.5 % of its length)
    if _principal_line(pts, band_px)[3] >= 0.85:
        return []
    # ... and a blob (a pore) fills its convex hull, where crossing furrows leave most of
    # it empty (an X of 1.5 mm scratches: ~0.2 of it; a round pore: ~0.9)
    hull = cv2.convexHull(pts.astype(np.float32))
    if len(pts) >= max_solidity * cv2.contourArea(hull):
        return []
    th = np.deg2rad(np.arange(0.0, 180.0, 2.0))
    cs = np.column_stack([np.cos(th), np.sin(th)])
    lines: list[tuple[float, float, float, float]] = []
    left = np.ones(len(pts), bool)
    for _ in range(max_lines):
        p = pts[left]
        if len(p) < min_len_px / 2.0:
            break
        rho = p @ cs.T  # (n, angles): the distance along each normal
        lo = rho.min()
        nb = int(np.ceil((rho.max() - lo) / band_px)) + 2
        idx = (np.arange(th.size)[None, :] * nb + np.floor((rho - lo) / band_px).astype(int)).ravel()
        counts = np.bincount(idx, minlength=th.size * nb).reshape(th.size, nb)
        pair = counts[:, :-1] + counts[:, 1:]  # a band of two bins: a furrow astride a bin's edge
        allowed = np.ones(th.size, bool)
        for _x, _y, a, _bend in lines:  # a line's normal is its direction less 90 deg
            d = np.abs((np.rad2deg(th) - np.rad2deg(a - np.pi / 2.0) + 90.0) % 180.0 - 90.0)
            allowed &= d >= min_turn_deg
        pair[~allowed] = 0
        k, b = np.unravel_index(int(np.argmax(pair)), pair.shape)
        r0 = lo + (b + 1.0) * band_px  # the band's middle
        near = np.abs(rho[:, k] - r0) <= band_px
        along = p[near] @ np.array([-cs[k, 1], cs[k, 0]])
        if near.sum() < max(min_len_px / 2.0, 0.1 * len(pts)) or (np.ptp(along) + 1.0) * 2.0 < min_len_px:
            break  # too short, or too little of the seed to be a furrow of its own
        # the furrow's chord: the band's pixels, widened by what a bend of 2.5 % of its
        # length puts off it, fitted by their principal axis (the band at the transform's
        # 2 deg steps may hold only a chord of part of a bent scratch), twice
        bend = 0.025 * float(np.ptp(along))
        holds = np.abs(rho[:, k] - r0) <= band_px + bend
        for _ in range(2):
            q = p[holds]
            centre = q.mean(axis=0)
            _w, v = np.linalg.eigh((q - centre).T @ (q - centre))
            t_, n_ = v[:, 1], v[:, 0]
            bend = 0.025 * float(np.ptp((q - centre) @ t_))
            holds = np.abs((p - centre) @ n_) <= band_px + bend
        a = float(np.arctan2(t_[1], t_[0]))  # the line's direction
        lines.append((2.0 * centre[0] + 0.5, 2.0 * centre[1] + 0.5, a, 2.0 * bend))
        idx_left = np.flatnonzero(left)
        left[idx_left[holds]] = False
    # furrows explain the seed; a blob (a pore) holds many lines and is none of them
    return lines if len(lines) >= 2 and left.mean() <= 0.15 else []


def _principal_line(pts: np.ndarray, band_px: float) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Half-res points' principal axis: (their centre, the axis's direction, what a bend of
    2.5 % of their length along it may carry a point off it, the share of the points
    within ``band_px`` plus that bend of it)."""
    centre = pts.mean(axis=0)
    c = pts - centre
    _w, v = np.linalg.eigh(c.T @ c)
    bend = 0.025 * float(np.ptp(c @ v[:, 1]))
    return centre, v[:, 1], bend, float(np.mean(np.abs(c @ v[:, 0]) <= band_px + bend))


def _one_furrow(seed: np.ndarray, band_px: float = 3.0, min_len_px: float = 40.0, min_share: float = 0.75
                ) -> tuple[float, float, float, float] | None:
    """The line of a candidate's seed that is one furrow (``_furrows``'s test for one
    mark: its principal axis holds 85 % of its half-res pixels within ``band_px``, bent
    by 2.5 % of its length; or, where a spur tilts that axis, the axis of the points
    within reach of it holds ``min_share`` of them), at least ``min_len_px`` long (full
    px), as ``_furrows``'s lines (box px); None for any other seed."""
    yy, xx = np.nonzero(seed[::2, ::2])
    if yy.size < min_len_px / 2.0:
        return None
    pts = np.column_stack([xx, yy]).astype(np.float64)
    centre, t_, bend, share = _principal_line(pts, band_px)
    if share < 0.85:
        # a spur of a groove's residue where the furrow crosses it (the twin's 2260004: a
        # bent 1.18 mm scratch with 0.21 of its seed along a groove at its end) tilts the
        # axis of all the points: the axis of those within reach of it, twice
        for _ in range(2):
            near = np.abs((pts - centre) @ np.array([-t_[1], t_[0]])) <= band_px + bend
            if near.sum() < 3:
                return None
            centre, t_, bend, _s = _principal_line(pts[near], band_px)
        share = float(np.mean(np.abs((pts - centre) @ np.array([-t_[1], t_[0]])) <= band_px + bend))
        if share < min_share:
            return None
    if (float(np.ptp((pts - centre) @ t_)) + 1.0) * 2.0 < min_len_px:
        return None
    return 2.0 * centre[0] + 0.5, 2.0 * centre[1] + 0.5, float(np.arctan2(t_[1], t_[0])), 2.0 * bend


def _band(shape: tuple[int, int], offset: tuple[int, int], line: tuple[float, float, float, float],
          half_px: float) -> np.ndarray:
    """The pixels of a box (``shape``, its corner at ``offset`` in the frame) within
    ``half_px`` of a line (``_furrows``'s, frame px), widened by the line's allowance for
    a bend."""
    x, y, a, bend = line
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]]
    return np.abs((xx + offset[0] - x) * -np.sin(a) + (yy + offset[1] - y) * np.cos(a)) <= half_px + bend


def _group_collinear(candidates, max_gap_half_px: float = 20.0) -> list[list[int]]:
    """Candidates (indices) that are pieces of one scratch: a faint or fading scratch
    breaks into several components where its darkening dips under the growth
    threshold. Two join when one is elongated (3:1, 6 half-res px) and the other's
    centroid lies on its line (within 2 half-res px plus its half-width) and within
    ``max_gap_half_px`` beyond its end, in the same direction (10 deg) if elongated too,
    and no more than twice as wide (and 2 half-res px) if not: a piece of a scratch is as
    wide as the scratch, and a pore on its line beyond its end is a mark of its own."""
    shapes = []
    for labels, label, (x0, y0, x1, y1), _ in candidates:
        ys, xs = np.nonzero(labels[y0:y1, x0:x1] == label)
        xs, ys = xs + float(x0), ys + float(y0)
        cx, cy = xs.mean(), ys.mean()
        cov = np.cov(np.vstack([xs - cx, ys - cy])) if xs.size > 2 else np.eye(2) * 0.25
        evals, evecs = np.linalg.eigh(cov)
        d = evecs[:, 1]
        along = (xs - cx) * d[0] + (ys - cy) * d[1]
        half_len = float(np.abs(along).max()) + 0.5 if xs.size else 0.5
        half_wid = float(2.0 * np.sqrt(max(evals[0], 0.0))) + 0.5
        elongated = half_len >= 3.0 * half_wid and half_len >= 3.0
        shapes.append((cx, cy, d, half_len, half_wid, elongated))
    parent = list(range(len(candidates)))

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i, (cx, cy, d, hl, hw, el) in enumerate(shapes):
        if not el:
            continue
        for j, (cx2, cy2, d2, hl2, hw2, el2) in enumerate(shapes):
            if i == j:
                continue
            dx, dy = cx2 - cx, cy2 - cy
            along = abs(dx * d[0] + dy * d[1])
            perp = abs(-dx * d[1] + dy * d[0])
            if perp > 2.0 + hw2 + hw or along - hl - hl2 > max_gap_half_px:
                continue
            if el2 and abs(d[0] * d2[0] + d[1] * d2[1]) < np.cos(np.deg2rad(10.0)):
                continue
            if not el2 and hw2 > 2.0 * hw + 2.0:
                continue  # a compact mark much wider than the furrow is no piece of it (a pore)
            parent[find(i)] = find(j)
    groups: dict[int, list[int]] = {}
    for i in range(len(candidates)):
        groups.setdefault(find(i), []).append(i)
    return sorted(groups.values(), key=lambda g: min(g))


# ---------------------------------------------------------------- local model (full res)
def _plane(values: np.ndarray, xx: np.ndarray, yy: np.ndarray, use: np.ndarray) -> np.ndarray:
    """A robust plane through ``values`` where ``use`` (two least-squares passes, the
    second without points beyond 3 robust sigma)."""
    a = np.column_stack([np.ones(use.sum()), xx[use], yy[use]])
    v = values[use]
    coef = np.linalg.lstsq(a, v, rcond=None)[0]
    res = v - a @ coef
    keep = np.abs(res) < 3.0 * max(_mad_sigma(res), 1e-6)
    if keep.sum() > 10:
        coef = np.linalg.lstsq(a[keep], v[keep], rcond=None)[0]
    return coef[0] + coef[1] * xx + coef[2] * yy


def _groove_profiles(d: np.ndarray, xx: np.ndarray, yy: np.ndarray, use: np.ndarray, angles_deg,
                     rounds: int = 3, bin_px: float = 0.5, sides_about: tuple[float, float] | None = None
                     ) -> np.ndarray:
    """The two groove families over a patch as 1-D profiles across their lines (means in
    ``bin_px`` bins of the across-line coordinate, fitted where ``use``), backfitted in
    turn; returns their sum at every pixel of the patch.

    ``sides_about`` (x, y): a profile for each side of that point along the lines (a
    groove fades along its length, so where it crosses a hole's rim it is better read on
    the ring's own side than averaged with the far side); a bin one side lacks takes the
    two sides' profile. Along each line the two sides' readings are put at their own
    pixels' mean place along it and joined linearly between (each side's beyond): a
    groove tangent to the rim meets the line between the sides there, and a switch from
    one side's depth to the other's there left a step of ~0.5 of the hole's darkness on
    the wall beside the rim, read as a 0.15 mm "chip" (wide bench seed 85000, clean frame
    48)."""
    total = np.zeros_like(d)
    parts = []
    for a in angles_deg:
        t = np.deg2rad(a)
        u = -np.sin(t) * xx + np.cos(t) * yy
        idx = np.floor((u - u.min()) / bin_px).astype(np.int64)
        side = None
        if sides_about is not None:
            v = np.cos(t) * (xx - sides_about[0]) + np.sin(t) * (yy - sides_about[1])
            side = (v > 0, v)
        parts.append([idx, np.zeros_like(d), side])
    nb = [int(p[0].max()) + 1 for p in parts]
    centres = [np.arange(n) for n in nb]
    # per family and side (below the point, above it): each bin's pixels' mean place along
    # the lines, where that side's reading stands (fixed over the backfit's rounds)
    places = []
    for k, (idx, _, side) in enumerate(parts):
        if side is None:
            places.append(None)
            continue
        plus, v = side
        places.append([np.bincount(idx[sel], weights=v[sel], minlength=nb[k])
                       / np.maximum(np.bincount(idx[sel], minlength=nb[k]), 1) for sel in (use & ~plus, use & plus)])

    def profile(k: int, idx: np.ndarray, vals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        cnt = np.bincount(idx, minlength=nb[k]).astype(np.float64)
        s = np.bincount(idx, weights=vals, minlength=nb[k])
        have = cnt >= 3
        prof = np.zeros(nb[k])
        if have.sum() >= 2:
            prof = np.interp(centres[k], centres[k][have], s[have] / cnt[have])
        return prof, have

    for _ in range(rounds):
        for k, (idx, current, side) in enumerate(parts):
            rest = d - (total - current)
            both, _ = profile(k, idx[use], rest[use])
            new = both[idx]
            if side is not None:
                plus, v = side
                got = []
                for this in (~plus, plus):
                    sel = use & this
                    prof, have = profile(k, idx[sel], rest[sel])
                    prof = np.where(have, prof, both)
                    new = np.where(this, prof[idx], new)
                    got.append((prof, have))
                (p0, h0), (p1, h1) = got
                v0, v1 = places[k]
                span = v1 - v0
                pair = (h0 & h1 & (span > 1.0))[idx]
                w = np.clip((v - v0[idx]) / np.where(pair, span[idx], 1.0), 0.0, 1.0)
                new = np.where(pair, p0[idx] + (p1[idx] - p0[idx]) * w, new)
            total += new - current
            parts[k][1] = new
    return total


@dataclass
class _Patch:
    x0: int
    y0: int
    residual: np.ndarray  # relative darkness less level and grooves (full res)
    level: np.ndarray  # the wall's level (DN)
    excluded: np.ndarray  # bool: candidate (dilated) or hole zone
    zone: np.ndarray  # bool: the holes' zone alone
    grooves: np.ndarray  # the cross-hatch's modelled darkness (subtracted from residual)
    noise: float  # robust std of the residual per pixel
    noise_box5: float  # robust std of the residual's 5x5 box mean (correlated noise)


def _local_patch(img: np.ndarray, box: tuple[int, int, int, int], seed_mask: np.ndarray, zone: np.ndarray,
                 angles_deg, wall_level: np.ndarray) -> _Patch | None:
    """The wall model of a patch at full resolution: the frame's level (``wall_level``,
    full res) and a robust plane for what it leaves, and the grooves as local profiles,
    all fitted outside the candidate (``seed_mask``, bool over the box, dilated here)
    and the holes' zone."""
    x0, y0, x1, y1 = box
    p = img[y0:y1, x0:x1].astype(np.float32)
    if p.shape[0] < 12 or p.shape[1] < 12:
        return None
    yy, xx = np.mgrid[y0:y1, x0:x1].astype(np.float32)
    cand = cv2.dilate(seed_mask.astype(np.uint8), np.ones((9, 9), np.uint8)).astype(bool)
    excluded = cand | zone[y0:y1, x0:x1]
    use = ~excluded
    if use.sum() < 60:
        return None
    level = wall_level[y0:y1, x0:x1]
    d = 1.0 - p / np.maximum(level, 1.0)
    d -= _plane(d, xx - x0, yy - y0, use)
    grooves = _groove_profiles(d, xx, yy, use, angles_deg)
    r = (d - grooves).astype(np.float32)
    r[zone[y0:y1, x0:x1]] = 0.0
    noise = max(_mad_sigma(r[use]), NOISE_FLOOR)
    box5 = cv2.blur(r, (5, 5))
    inner = cv2.erode(use.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    noise5 = max(_mad_sigma(box5[inner]) if inner.sum() > 30 else noise / 2.0, NOISE_FLOOR / 5.0)
    return _Patch(x0, y0, r, level, excluded, zone[y0:y1, x0:x1], grooves.astype(np.float32), float(noise),
                  float(noise5))


# ---------------------------------------------------------------- fitting
@dataclass
class _Fit:
    x: np.ndarray  # parameters
    cov: np.ndarray  # their covariance from the residual's robust scale
    fun: np.ndarray  # residuals at the solution


def _gauss_newton(model, p0: np.ndarray, data: np.ndarray, lo: np.ndarray, hi: np.ndarray, iterations: int = 12,
                  huber_k: float = 2.0) -> _Fit:
    """A small bounded least-squares fit with Huber weights (IRLS): forward-difference
    Jacobian, normal equations with Levenberg damping, steps clipped to the bounds.
    scipy's trust-region solver spent 9 ms per step in an SVD of the Jacobian (several
    thousand pixels by 8 parameters) where the 8 x 8 normal equations take microseconds."""
    p = np.clip(np.asarray(p0, float), lo, hi)
    n = p.size
    lam = 1e-3
    f = model(p) - data
    scale = max(_mad_sigma(f), 1e-6)

    def cost(res, sc):
        a = np.abs(res) / (huber_k * sc)
        return float(np.sum(np.where(a < 1, a * a, 2 * a - 1)))

    jac = np.empty((data.size, n))
    for _ in range(iterations):
        for j in range(n):
            h = 1e-4 * max(abs(p[j]), 1.0)
            q = p.copy()
            q[j] = min(q[j] + h, hi[j]) if q[j] + h <= hi[j] else q[j] - h
            jac[:, j] = (model(q) - data - f) / (q[j] - p[j])
        a = np.abs(f) / (huber_k * scale)
        w = np.where(a < 1, 1.0, 1.0 / np.maximum(a, 1e-12))
        jw = jac * w[:, None]
        g = jw.T @ f
        hmat = jw.T @ jac
        c0 = cost(f, scale)
        improved = False
        for _try in range(6):
            step = np.linalg.solve(hmat + lam * np.diag(np.diag(hmat) + 1e-12), -g)
            q = np.clip(p + step, lo, hi)
            fq = model(q) - data
            if cost(fq, scale) < c0:
                p, f = q, fq
                lam = max(lam / 3, 1e-7)
                improved = True
                break
            lam *= 10
        if not improved or np.all(np.abs(step) < 1e-6 * np.maximum(np.abs(p), 1.0)):
            break
        scale = max(_mad_sigma(f), 1e-6)
    a = np.abs(f) / (huber_k * scale)
    w = np.where(a < 1, 1.0, 1.0 / np.maximum(a, 1e-12))
    hmat = (jac * w[:, None]).T @ jac
    try:
        cov = np.linalg.pinv(hmat) * float(np.sum(w * f * f)) / max(float(w.sum()) - n, 1.0)
    except np.linalg.LinAlgError:
        cov = np.full((n, n), np.inf)
    return _Fit(p, cov, f)


# ---------------------------------------------------------------- shapes
def feret(x: np.ndarray, y: np.ndarray, step_deg: float = 0.5) -> tuple[float, float, float]:
    """Greatest Feret diameter of a point set, its direction (deg, 0-180) and the extent
    across that direction."""
    a = np.deg2rad(np.arange(0.0, 180.0, step_deg))
    proj = np.cos(a)[:, None] * x[None, :] + np.sin(a)[:, None] * y[None, :]
    ext = proj.max(axis=1) - proj.min(axis=1)
    i = int(np.argmax(ext))
    across = -np.sin(a[i]) * x + np.cos(a[i]) * y
    return float(ext[i]), float(np.rad2deg(a[i])), float(across.max() - across.min())


def _weighted_pca(xx: np.ndarray, yy: np.ndarray, wts: np.ndarray) -> tuple[float, float, float, np.ndarray]:
    """Centroid, direction of the major axis (rad) and the 2x2 covariance of a weighted point set."""
    sw = wts.sum()
    cx, cy = (wts * xx).sum() / sw, (wts * yy).sum() / sw
    dx, dy = xx - cx, yy - cy
    sxy = (wts * dx * dy).sum()
    cov = np.array([[(wts * dx * dx).sum(), sxy], [sxy, (wts * dy * dy).sum()]]) / sw
    evals, evecs = np.linalg.eigh(cov)
    return float(cx), float(cy), float(np.arctan2(evecs[1, 1], evecs[0, 1])), cov


# ---------------------------------------------------------------- pores
def _ellipse_model(p, xx, yy):
    """A blurred dark ellipse: an erf edge at the ellipse's radius in each direction,
    capped by the peak darkness of a blurred disc of the same area (1 - exp(-R^2/2s^2)),
    which small pores never reach; plus an offset."""
    cx, cy, a, b, th, c, s, off = p
    dx, dy = xx - cx, yy - cy
    ct, st = np.cos(th), np.sin(th)
    xr, yr = dx * ct + dy * st, -dx * st + dy * ct
    rho = np.hypot(xr, yr)
    psi = np.arctan2(yr, xr)
    r_e = a * b / np.sqrt((b * np.cos(psi)) ** 2 + (a * np.sin(psi)) ** 2 + 1e-12)
    peak = 1.0 - np.exp(-(a * b) / (2.0 * s * s))
    return off + c * np.minimum(ndtr((r_e - rho) / s), peak)


def _fit_contrast(r, xx, yy, use, cx, cy, cov, mass,
                  blur_held: float | None = None) -> tuple[float, float, float, float]:
    """The pore floor's contrast c (relative darkness), the blur s (px), c's standard
    deviation and the fitted ellipse's aspect (major / minor axis, the blur taken out),
    from a robust fit of a blurred ellipse started from the darkening's moments; the
    blur free in 0.5-3.5 px, or held within 2 % of ``blur_held``."""
    evals, evecs = np.linalg.eigh(cov)
    evals = np.maximum(evals, 0.25)
    # a uniform ellipse of semi-axes a, b has variances a^2/4 and b^2/4 along them
    a0, b0 = 2.0 * np.sqrt(evals[1]), 2.0 * np.sqrt(evals[0])
    th0 = float(np.arctan2(evecs[1, 1], evecs[0, 1]))
    c0 = float(np.clip(mass / (np.pi * a0 * b0), 0.05, 0.95))
    p0 = np.array([cx, cy, a0, b0, th0, c0, 1.3 if blur_held is None else blur_held, 0.0])
    b_lo, b_hi = (0.5, 3.5) if blur_held is None else (0.98 * blur_held, 1.02 * blur_held)
    lo = np.array([cx - 5, cy - 5, 0.5, 0.5, th0 - np.pi, 0.01, b_lo, -0.2])
    hi = np.array([cx + 5, cy + 5, 4 * a0 + 5, 4 * a0 + 5, th0 + np.pi, 1.2, b_hi, 0.2])
    x, y, v = xx[use], yy[use], r[use]
    if v.size > 2500:  # every k-th pixel: the fit's speed, the contrast is just as well fixed
        k = int(np.ceil(v.size / 2500))
        x, y, v = x[::k], y[::k], v[::k]
    p0 = np.clip(p0, lo, hi)
    fit = _gauss_newton(lambda p: _ellipse_model(p, x, y), p0, v, lo, hi)
    c, s = float(fit.x[5]), float(fit.x[6])
    c_sd = float(np.sqrt(max(fit.cov[5, 5], 0.0))) if np.isfinite(fit.cov[5, 5]) else c
    aspect = float(max(fit.x[2], fit.x[3]) / max(min(fit.x[2], fit.x[3]), 0.25))
    return c, s, c_sd, aspect


#: a pore's outline is read to the order whose harmonic the blur still keeps this much of
#: (``_harmonic_attenuation``), at most ``OUTLINE_MAX_ORDER``, and only while the noise
#: that the harmonic's division by it carries into the radius stays under
#: ``OUTLINE_RIPPLE_NOISE_PX``: beyond, the grain's noise outweighs the shape. Faint
#: 12 px pores on 8 % grooves (noise 0.24-0.38 px at harmonic 4) read 0.9 px too wide
#: on average with harmonic 4 let in on the attenuation alone
OUTLINE_MIN_ATTENUATION = 0.5
OUTLINE_MAX_ORDER = 8
OUTLINE_RIPPLE_NOISE_PX = 0.25


@functools.lru_cache(maxsize=4096)
def _harmonic_attenuation_cached(radius_q: int, blur_q: int, kmax: int) -> tuple[float, ...]:
    rho, sigma = radius_q / 20.0, blur_q / 100.0
    s = np.linspace(max(rho - 8.0 * sigma, 0.0), rho + 8.0 * sigma, 801)
    g = (s / sigma**2) * np.exp(-((s - rho) ** 2) / (2.0 * sigma**2))
    return tuple(float(np.trapezoid(g * ive(k, s * rho / sigma**2), s)) for k in range(1, kmax + 1))


def _harmonic_attenuation(radius: float, blur: float, kmax: int = OUTLINE_MAX_ORDER) -> np.ndarray:
    """How much a Gaussian blur ``blur`` (px) keeps of the angular harmonics k = 1..kmax,
    about a centre, of darkening at ``radius`` (px) from it. A point's darkening at
    radius rho, spread by the blur sigma and read as harmonic k round the centre, keeps
    h_k = integral over s of s / sigma^2 exp(-(s^2 + rho^2) / 2 sigma^2) I_k(s rho / sigma^2) ds
    (the Rice law with the weight I_k for I_0; about exp(-k^2 sigma^2 / 2 rho^2) when
    rho >> sigma).
    A mark's outline is r(theta); a ripple of it at the rim is read attenuated by h_k at
    the rim's radius. Cached on radius to 0.05 px and blur to 0.01 px."""
    rq = int(round(max(radius, 0.5) * 20.0))
    bq = int(round(max(blur, 0.3) * 100.0))
    return np.array(_harmonic_attenuation_cached(rq, bq, int(kmax)))


def _outline(r, xx, yy, omega, cx, cy, mass: float, c: float, blur: float, with_gain: bool = False,
             deconvolve: bool = True, noise: float | None = None):
    """A dark mark's outline, radius against angle (360 angles over -pi..pi), from the
    darkening ``r`` over ``omega``: its angular density round the centroid is
    c r(theta)^2 / 2 (the area a direction holds), whatever the blur; as a Fourier series
    of the pixels' angles (no binning). The blur spreads the darkening across
    directions, which keeps only h_k of the outline's harmonic k (``_harmonic_attenuation``
    at the mark's equivalent radius): each harmonic read is divided by its h_k, up to the
    order where h_k falls under ``OUTLINE_MIN_ATTENUATION`` or, given the ``noise`` of a
    coefficient, where the division would carry more than ``OUTLINE_RIPPLE_NOISE_PX`` of
    it into the radius. Read as it was blurred (the first version, to the order
    k sigma / R < 1 and not divided), the outline was smoothed: on 445 pores of 5-50 px
    (station envelope, no hole) the greatest Feret diameter read 0.61 px short and the
    width 0.34 px short on average, with their area right to 0.01 px of radius; divided,
    -0.07 and -0.08 px (wide envelope, 359 pores: -0.39 / -0.25 -> +0.07 / -0.06 px,
    the length's spread 1.10 -> 0.96 px).

    With ``with_gain``, also the sum of 1 / h_k^2 over the harmonics kept, which is what
    the grain's noise in the outline grows with. ``deconvolve`` False: the outline as
    blurred, to the order k sigma / R < 1 (2-8; the edge-blur test's, which asks how far
    the mark departs from the blurred ellipse it was fitted with)."""
    dx, dy = xx[omega] - cx, yy[omega] - cy
    phi = np.arctan2(dy, dx)
    mv = r[omega]
    r_eq = np.sqrt(max(mass / c, 1.0) / np.pi)
    if deconvolve:
        att = _harmonic_attenuation(r_eq, blur)
        ok = att >= OUTLINE_MIN_ATTENUATION
        if noise is not None:
            # a harmonic's coefficients each carry the noise of a sum over omega; divided
            # by h_k, that is this much of the outline's radius (px)
            ok &= noise * np.sqrt(2.0) / (att * np.pi * c * r_eq) <= OUTLINE_RIPPLE_NOISE_PX
        order = int(max(2, np.sum(np.cumprod(ok))))
        att = att[:order]
    else:
        order = int(np.clip(np.floor(r_eq / max(blur, 0.7)), 2, OUTLINE_MAX_ORDER))
        att = np.ones(order)
    ks = np.arange(1, order + 1)
    cos_k, sin_k = np.cos(ks[:, None] * phi[None, :]), np.sin(ks[:, None] * phi[None, :])
    a_k, b_k = (cos_k @ mv) / att, (sin_k @ mv) / att
    th = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    harmonics = a_k @ np.cos(ks[:, None] * th[None, :]) + b_k @ np.sin(ks[:, None] * th[None, :])
    density = (mass + 2.0 * harmonics) / (2 * np.pi)
    rr = np.sqrt(np.clip(2.0 * density / c, 0.0, None))
    return (th, rr, float(np.sum(1.0 / att**2))) if with_gain else (th, rr)


def _outline_roughness(th: np.ndarray, rr: np.ndarray) -> float:
    """The RMS of an outline's radius about its ellipse (px): how far the outline departs
    from what the blurred-ellipse model can follow. An ellipse centred on the origin has
    1 / r^2 = A + B cos 2 theta + C sin 2 theta exactly; the first harmonic is let in for
    a centroid that is not the ellipse's centre (least squares on 1 / r^2)."""
    ok = rr > 0.5
    if ok.sum() < 12:
        return 0.0
    t = th[ok]
    basis = np.column_stack([np.ones_like(t), np.cos(2 * t), np.sin(2 * t), np.cos(t), np.sin(t)])
    coef, *_ = np.linalg.lstsq(basis, 1.0 / rr[ok] ** 2, rcond=None)
    q = np.column_stack([np.ones_like(th), np.cos(2 * th), np.sin(2 * th), np.cos(th), np.sin(th)]) @ coef
    fitted = 1.0 / np.sqrt(np.maximum(q, 1e-12))
    return float(np.sqrt(np.mean((rr - fitted) ** 2)))


def _measure_pore(patch: _Patch, region: np.ndarray, cfg: DefectConfig, allow_scratch: bool = True,
                  blur_hint: float | None = None, beside: np.ndarray | None = None):
    """A pore: centroid, outline from the darkening in 32 sectors, greatest Feret
    diameter and the extent across it, with standard uncertainties (px, before the
    config's factor), the significance and the floor's contrast.

    ``blur_hint``: the camera's blur, if known (the frame's holes, a calibration). The
    tests (contrast, edge blur, elongation) read the fit with the blur free; the outline
    reads a fit with the blur held at the camera's, since a pore's rim is a sharp break
    in the wall's plane. A small pore's contrast, size and edge blur trade off: with the
    blur free, 11-13 px pores of 46 % contrast on 4 % grain and 8 % grooves fitted a
    blur of 2.3-2.7 px (1.4 and 0.8 rendered) and their contrast ran to its bound, 1.2,
    which read them 40 % small (fresh bench seeds 80000, 95000). Without a known blur,
    a fit whose contrast passes 1 (a floor darker than black) is done again with the
    blur held at the station's prior (``BLUR_PRIOR_PX``).

    ``beside``: other marks beside the pore (the rest of its candidate's region,
    ``_peak_part``), left out of its integration and its fit with 2 px round them."""
    r = patch.residual.astype(np.float64)
    h, w = r.shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    off = patch.zone
    if beside is not None and beside.any():
        off = off | (cv2.dilate(beside.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool) & ~region)
    # the blurred edge reaches ~2.5 blur beyond the outline: integrate 5 px past the region
    omega = (cv2.dilate(region.astype(np.uint8), np.ones((11, 11), np.uint8)).astype(bool) & ~off) | region
    wts = np.where(omega, r, 0.0)
    mass = float(wts.sum())
    if mass <= 0:
        return None
    significance = mass / (5.0 * patch.noise_box5 * np.sqrt(omega.sum()))
    mean_darkness = float(r[region].mean())
    if significance < cfg.min_significance or mean_darkness < cfg.min_mean_darkness:
        return None  # before the fit, which costs most of a candidate's time
    pos = np.clip(wts, 0.0, None)
    cx, cy, _, cov = _weighted_pca(xx, yy, pos)
    fit_area = cv2.dilate(omega.astype(np.uint8), np.ones((9, 9), np.uint8)).astype(bool) & ~off
    c, blur, c_sd, aspect = _fit_contrast(r, xx, yy, fit_area, cx, cy, cov, mass)
    if allow_scratch and aspect >= cfg.scratch_elongation:
        return dict(scratch=True)  # long and thin once the blur is taken out: a short scratch
    if c < cfg.min_pore_contrast:
        return None
    if blur > cfg.max_edge_blur_px:
        # the blurred ellipse takes a ragged outline's departure from an ellipse for blur
        # (a radial scatter rho widens the mean edge to sqrt(s^2 + rho^2)): what the
        # outline's own harmonics beyond the ellipse's say of it comes off first. A soft
        # shading of the wall has a smooth outline and keeps its blur
        th, rr = _outline(r, xx, yy, omega, cx, cy, mass, c, blur, deconvolve=False)
        rough = _outline_roughness(th, rr)
        if np.sqrt(max(blur * blur - rough * rough, 0.0)) > cfg.max_edge_blur_px:
            return None
    held = blur_hint
    if held is None and c > 1.0:
        # no blur known and a floor darker than black: the fit traded size for blur; the
        # station's blur, as the scratches' prior has it, is the better guess
        held = BLUR_PRIOR_PX[0]
    if held is not None:
        c, blur, c_sd, _ = _fit_contrast(r, xx, yy, fit_area, cx, cy, cov, mass,
                                         blur_held=float(np.clip(held, 0.5, 3.5)))
    # noise of a sum over n px: the 5x5 box mean's spread x 25 per 25 px (correlated
    # grain); each coefficient sums the pixels with weights of RMS 1/sqrt(2); r^2 = 2 D / c
    u_coef = 5.0 * patch.noise_box5 * np.sqrt(omega.sum() / 2.0)
    th, rr, gain = _outline(r, xx, yy, omega, cx, cy, mass, c, blur, with_gain=True,
                            noise=u_coef)
    r_eq = np.sqrt(max(mass / c, 1.0) / np.pi)
    length, direction, width = feret(rr * np.cos(th), rr * np.sin(th))
    u_density = u_coef * np.sqrt(2.0 * gain) / np.pi
    u_r = u_density / (c * max(r_eq, 1.0))
    u_scale = c_sd / (2.0 * c)  # the outline scales as c^-1/2
    u_len = float(np.sqrt(2.0 * u_r**2 + (length * u_scale) ** 2))
    u_wid = float(np.sqrt(2.0 * u_r**2 + (width * u_scale) ** 2))
    return dict(x=cx, y=cy, length=length, width=width, angle=direction, u_length=u_len, u_width=u_wid,
                significance=float(significance), contrast=c, blur=blur, mean_darkness=mean_darkness)


# ---------------------------------------------------------------- scratches
def _strip(r: np.ndarray, cx: float, cy: float, ang: float, s: np.ndarray, n: np.ndarray,
           bend: np.ndarray | None = None) -> np.ndarray:
    """``r`` sampled on a grid along (``s``) and across (``n``) a line through (cx, cy)
    at ``ang`` (rad), the across offset shifted by ``bend(s)``; NaN outside ``r``."""
    ca, sa = np.cos(ang), np.sin(ang)
    nn = n[:, None] + (bend[None, :] if bend is not None else 0.0)
    mx = (cx + s[None, :] * ca - nn * sa).astype(np.float32)
    my = (cy + s[None, :] * sa + nn * ca).astype(np.float32)
    return cv2.remap(r.astype(np.float32), mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                     borderValue=float("nan"))


def _nanmean_rows(a: np.ndarray) -> np.ndarray:
    """Mean of each row over its finite values (NaN where it has none), quietly."""
    fin = np.isfinite(a)
    cnt = fin.sum(axis=1)
    return np.where(cnt > 0, np.where(fin, a, 0.0).sum(axis=1) / np.maximum(cnt, 1), np.nan)


def _blurred_box(x, centre, width, blur):
    return ndtr((x - centre + width / 2.0) / blur) - ndtr((x - centre - width / 2.0) / blur)


def _scratch_extent(m: np.ndarray, step: float, gap_px: float = 0.0,
                    held: tuple[np.ndarray, tuple[int, int]] | None = None) -> tuple[int, int] | None:
    """The extent of a scratch's darkening ``m`` (integrated across it, sampled every
    ``step`` px along it): the interval [a, b) that a box fits best, i.e. that maximises
    S^2 / n (S the darkening it holds, n its samples; the least-squares box of free
    height), over all intervals at 1 px resolution. A faint scratch's profile dips to
    nothing here and there over several px (noise, grooves crossing its smooth floor):
    runs above 40 % of the plateau, gaps of up to 6 px bridged, still read a 199 px
    scratch as 119 px (dev frames); a box pays for a dip only what the dip lacks, and for
    a groove crossing beyond a gap the whole gap.

    ``held``: another read of the same strip (its profile, sampled as ``m``, and its
    extent there) whose gaps alone may split ``m`` inside that extent: the grooves'
    scaling of a profile (``_measure_scratch``) is a correction, and where a groove runs
    beside a scratch rather than across it, it drives the residual there below zero and
    lifts a junction of grooves on the scratch 2-3x, so it made a gap the raw read does
    not have, and the lesser half of a 1.6 mm scratch was lost (the twin's 2170043)."""
    k = max(int(round(1.0 / step)), 1)
    n = m.size // k
    if n < 2:
        return None
    coarse = m[: n * k].reshape(n, k).sum(axis=1)
    bridge = None
    if held is not None:
        raw, (ra, rb) = held
        rc = raw[: n * k].reshape(n, k).sum(axis=1)
        ca, cb = ra // k, min(-(-rb // k), n)
        raw_gaps = _profile_gaps(rc[ca:cb], gap_px) if cb - ca >= 3 else None
        if raw_gaps is not None:
            # where the raw read is not in a gap of its own (the same rule, over its extent)
            bridge = np.zeros(n, bool)
            bridge[ca:cb] = True
            for ga, gb in raw_gaps:
                bridge[ca + ga:ca + gb] = False
    c = np.concatenate([[0.0], np.cumsum(coarse)])
    i, j = np.triu_indices(n + 1, 1)
    total = c[j] - c[i]
    score = np.where(total > 0, total * total / (j - i), -1.0)
    best = int(np.argmax(score))
    if score[best] <= 0:
        return None
    a, b = int(i[best]), int(j[best])
    # ... but not across a gap: where the darkening stays under a quarter of the box's
    # median over gap_px, the scratch is not there, whatever lies beyond. A box pays for
    # a gap only what it lacks, and a deep groove crossing 10 px past a scratch's end
    # (the twin's 10 % grooves, where the wall model's straight grooves meet their fading)
    # bought the gap and carried the end 28 px on. Of the pieces, the one holding most
    a, b = _largest_piece(coarse, a, b, gap_px, bridge)
    return a * k, b * k


def _profile_gaps(coarse: np.ndarray, gap_px: float) -> list[tuple[int, int]] | None:
    """The gaps of a 1 px profile: runs of at least ``gap_px`` under a quarter of its
    median, smoothed over 3 px (so one noisy pixel does not bridge a gap); None when
    its median is not above zero (no plateau to judge a gap against)."""
    plateau = float(np.median(coarse))
    if plateau <= 0:
        return None
    seg = np.convolve(coarse, np.ones(3) / 3.0, mode="same")
    return [(ga, gb) for ga, gb in _runs(seg < 0.25 * plateau, False) if gb - ga >= gap_px]


def _largest_piece(coarse: np.ndarray, a: int, b: int, gap_px: float,
                   bridge: np.ndarray | None = None) -> tuple[int, int]:
    """[a, b) of a 1 px profile split at runs of at least ``gap_px`` under a quarter
    of its median (smoothed over 3 px, so one noisy pixel does not bridge a gap); the
    piece with the largest sum. ``bridge`` (over the whole profile): where no gap may
    split it (a gap mostly there is none)."""
    if b - a < 3 or gap_px <= 0:
        return a, b
    gaps = _profile_gaps(coarse[a:b], gap_px)
    if gaps is None:
        return a, b
    gaps = [(ga, gb) for ga, gb in gaps if ga > 0 and gb < b - a
            and not (bridge is not None and bridge[a + ga:a + gb].mean() > 0.5)]
    if not gaps:
        return a, b
    bounds = [0] + [v for g in gaps for v in g] + [b - a]
    pieces = [(bounds[2 * q], bounds[2 * q + 1]) for q in range(len(bounds) // 2)]
    best = max(pieces, key=lambda pq: float(np.clip(coarse[a + pq[0]:a + pq[1]], 0.0, None).sum()))
    return a + best[0], a + best[1]


#: a stretch that the grooves' scaling adds at a scratch's end is a shelf, not the
#: scratch, when it is at least ``SHELF_MIN_PX`` long, runs along a modelled groove
#: (``SHELF_MIN_GROOVE_SHARE`` of the scratch's level through the same filter), holds at
#: most ``SHELF_MAX_SHARE`` of the scratch's scaled darkening (medians) and does not
#: overlap it: ``_shelf_beyond``
SHELF_MAX_SHARE = 0.6
SHELF_MIN_GROOVE_SHARE = 0.25
SHELF_MIN_PX = 10.0


def _shelf_beyond(av: np.ndarray, groove_av: np.ndarray, a: int, b: int, core: tuple[int, int],
                  step: float) -> bool:
    """Whether the stretch ``[a, b)`` of a scratch's scaled amplitude ``av`` (sampled every
    ``step`` px), which the grooves' scaling added past the raw read's end, is a groove's
    shelf rather than the scratch: at least ``SHELF_MIN_PX`` long; along a groove, the
    modelled grooves through the scratch's filter (``groove_av``) at least
    ``SHELF_MIN_GROOVE_SHARE`` of the scratch's level there (medians; the level the median
    of ``av`` over the raw read's extent ``core``); and at a level of its own, its median
    at most ``SHELF_MAX_SHARE`` of the scratch's and its upper quartile under the
    scratch's lower quartile.

    A scratch's floor is one furrow of one reflectance, its width varying by ~15 % on a
    scale of 8 px, so where the scaling restores its darkness through a groove it crosses
    the stretch reads at the scratch's level. A groove that the scratch ends on at a
    shallow angle (10-15 deg, as the station's scratches cross the hatch) runs on along
    its line, and the scaling lifts the wall model's misfit of it to a shelf at about half
    the scratch's level, which a box of free height takes in for nothing (station frame
    110048: a 0.85 mm scratch read 1.82 mm, a false scratch and a miss; the groove through
    the filter 0.45 of the scratch's level, the stretch 0.55; its misfit did not rise with
    the modelled groove, so ``_groove_beyond_end`` let it stand). A faint scratch's own end
    may read as low where its centre line, continued straight past its region, leaves it,
    but no groove runs along it there (station frame 91044: 0.08 of its level)."""
    if (b - a) * step < SHELF_MIN_PX or core[1] - core[0] < 2:
        return False
    stretch, inside = av[a:b], av[core[0]:core[1]]
    med = float(np.median(inside))
    return bool(med > 0 and float(np.median(groove_av[a:b])) >= SHELF_MIN_GROOVE_SHARE * med
                and float(np.median(stretch)) <= SHELF_MAX_SHARE * med
                and float(np.percentile(stretch, 75)) < float(np.percentile(inside, 25)))


#: a scratch's centre line is a quintic, not a cubic, where its peaks span this far (px):
#: across much of a frame the lens's distortion bends it as well as its own modes
QUINTIC_BEND_PX = 400.0

#: the camera's blur (Gaussian sigma, px) as a scratch's measurement assumes it before
#: anything in the frame says more: the middle of the station's envelope (0.8-2 px) and a
#: standard deviation that spans it. Combined with what the scratch's own cross profile
#: and ends say (``_scratch_blur``); it decides the blur only when both are vague
BLUR_PRIOR_PX = (1.4, 0.6)


def _ends_blur(s: np.ndarray, a: np.ndarray, s1: float, s2: float) -> tuple[float, float] | None:
    """The blur along a scratch from its two ends: each a blurred step of its amplitude
    along it (a furrow ends in a cut), fitted for its width over +/-7 px; the two
    combined by their variances, less the strip's bilinear sampling (1/6 px^2). Returns
    (blur, its variance), or None when neither end could be fitted. ``a`` must not be
    smoothed along the scratch: a first version fitted the profile after a 1 px
    Gaussian and took only the sampling off, which read a 1.2 px blur as 1.6 px and
    the twin's thin scratches as a third of their width."""
    est = []
    for end, sign in ((s1, 1.0), (s2, -1.0)):
        sel = np.abs(s - end) <= 7.0
        if sel.sum() < 8:
            continue
        x, v = s[sel], a[sel]
        inner = sign * (x - end) > 2.0
        h0 = max(float(np.median(v[inner])) if inner.any() else float(v.max()), 1e-3)
        # with an offset: the wall's level, smoothed over 16 px, sinks a little under a
        # scratch, and the darkening outside its ends reads a few per cent negative
        lo = np.array([0.0, end - 2.0, 0.4, -0.5 * h0])
        hi = np.array([4.0 * h0, end + 2.0, 4.0, 0.5 * h0])
        fit = _gauss_newton(lambda q: q[0] * ndtr(sign * (x - q[1]) / q[2]) + q[3], np.array([h0, end, 1.5, 0.0]), v,
                            lo, hi, iterations=15)
        # samples 0.5 px apart of a bilinear interpolation are correlated (twice the
        # variance), and the scratch's width varies along it on the scale of the fit's
        # window (its plateau is no step's): dev frames' errors were twice the spread
        # the fit states once more (robust sd of the z-scores 1.9-2.0)
        var = 8.0 * fit.cov[2, 2]
        if np.isfinite(var) and var > 0 and 0.45 < fit.x[2] < 3.9:
            est.append((float(fit.x[2]), float(var)))
    if not est:
        return None
    w = np.array([1.0 / v for _, v in est])
    value = float(np.sum(w * np.array([b for b, _ in est])) / w.sum())
    blur = float(np.sqrt(max(value * value - 1.0 / 6.0, 0.25)))
    return blur, float((value / blur) ** 2 / w.sum())


def _bend_function(coef: np.ndarray, lo: float, hi: float):
    """A scratch's centre line across its chord as a function of the position along it:
    the polynomial over [lo, hi], where the cross profiles' peaks fixed it, continued
    along its tangent beyond (a cubic extrapolated 30 px ran off into the wall); and
    its slope."""
    der = np.polyder(coef)

    def at(s):
        s = np.asarray(s, float)
        sc = np.clip(s, lo, hi)
        return np.polyval(coef, sc) + np.polyval(der, sc) * (s - sc)

    def slope(s):
        return np.polyval(der, np.clip(np.asarray(s, float), lo, hi))

    return at, slope


def _scratch_cross_fit(nv: np.ndarray, pv: np.ndarray, b: float, half_w: float, p0=None) -> _Fit:
    """The mean cross profile as a blurred box of blur ``b`` (px, the strip's sampling
    included): contrast, centre, width, offset. The contrast is at most 1: a relative
    darkness beyond it is no light at all (a thin scratch fitted without that bound
    traded its width for contrasts of 1.4-1.5)."""
    c0 = max(float(np.max(pv)), 1e-3)
    w0 = max(float(np.trapezoid(np.clip(pv, 0, None), nv)) / c0, 0.5)
    lo = np.array([0.0, -3.0, 0.2, -0.1])
    hi = np.array([1.0, 3.0, 2 * half_w, 0.1])
    start = np.array([c0, 0.0, w0, 0.0]) if p0 is None else np.asarray(p0, float)
    return _gauss_newton(lambda p: p[0] * _blurred_box(nv, p[1], p[2], b) + p[3], np.clip(start, lo, hi), pv,
                         lo, hi, iterations=20, huber_k=10.0)


def _scratch_blur(nv: np.ndarray, pv: np.ndarray, half_w: float):
    """The camera's blur for a scratch in a frame that gives none (no hole, no
    calibration): what its mean cross profile says (a blurred box with a free blur: its
    shoulders fix the blur when the scratch is wide, its kurtosis when thin, to ~0.1 px
    on a scratch 100 px long) and the prior (``BLUR_PRIOR_PX``), combined by their
    variances; ``_measure_scratch`` adds what its two ends say (``_ends_blur``: blurred
    steps, 0.2-0.4 px each). Returns (blur, its variance). The ends alone (the first
    version) read the twin's 1.2 px blur anywhere from 0.5 to 2 px, and its thin
    scratches' widths 50-70 % off."""
    est = [(BLUR_PRIOR_PX[0], BLUR_PRIOR_PX[1] ** 2)]
    c0 = max(float(np.max(pv)), 1e-3)
    w0 = max(float(np.trapezoid(np.clip(pv, 0, None), nv)) / c0, 0.5)
    lo = np.array([0.0, -3.0, 0.2, 0.45, -0.1])
    hi = np.array([1.0, 3.0, 2 * half_w, 4.0, 0.1])
    free = _gauss_newton(lambda p: p[0] * _blurred_box(nv, p[1], p[2], p[3]) + p[4],
                         np.clip(np.array([c0, 0.0, w0, 1.5, 0.0]), lo, hi), pv, lo, hi, iterations=20, huber_k=10.0)
    bx, var = float(free.x[3]), float(free.cov[3, 3])
    if np.isfinite(var) and var > 0 and lo[3] + 0.05 < bx < hi[3] - 0.05:
        b = float(np.sqrt(max(bx * bx - 1.0 / 6.0, 0.25)))
        # the fit's variance x 5 and a 0.05 px floor: the centre line's wander and the width's
        # variation along the scratch shape the mean profile too (dev frames, 170 scratches
        # of the twin and the bench: errors 1.7-2.4 times the fit's standard deviation, and
        # wide scratches' blur read 0.05 px high)
        est.append((b, 5.0 * var * (bx / b) ** 2 + 0.05**2))
    w = np.array([1.0 / v for _, v in est])
    value = float(np.sum(w * np.array([b for b, _ in est])) / w.sum())
    return value, float(1.0 / w.sum())


#: how firmly (the slope's t, on 1 px samples) a scratch's amplitude beyond its raw end
#: must rise with the groove there to be read as the groove's, not the scratch's
GROOVE_BEYOND_END_T = 3.0


def _groove_beyond_end(raw: np.ndarray, groove: np.ndarray, a: int, b: int, step: float) -> bool:
    """Whether the stretch ``[a, b)`` past a scratch's end on its raw amplitude ``raw``
    (the residual matched-filtered across, no scaling for the grooves) is the wall
    model's misfit of a groove there (``groove``: the modelled grooves through the same
    filter) rather than the scratch running on. The scratch's floor is smooth: where it
    runs through a groove the residual *dips* by what the model took for the groove,
    whatever the groove's depth; where it is not, the residual is the model's misfit of
    the groove, which on a deep groove the model underreads *rises* with it. So a
    stretch whose amplitude rises with the groove (the least-squares slope over 1 px
    samples, its t at least ``GROOVE_BEYOND_END_T``) is the groove's. A stretch under
    4 px, or over which the groove hardly varies, says nothing (False)."""
    k = max(int(round(1.0 / step)), 1)
    if b - a < 4 * k:
        return False
    y, x = raw[a:b:k], groove[a:b:k]
    if y.size < 4 or float(np.ptp(x)) <= 0:
        return False
    X = np.column_stack([np.ones_like(x), x])
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    r = y - X @ coef
    dof = y.size - 2
    if dof <= 0:
        return False
    cov = float(r @ r) / dof * np.linalg.pinv(X.T @ X)
    se = float(np.sqrt(max(cov[1, 1], 0.0)))
    return bool(coef[1] > 0 and (se == 0.0 or coef[1] / se >= GROOVE_BEYOND_END_T))


#: a stretch of a scratch's centre-line peaks at one end that is the groove it ends on:
#: at least ``HATCH_TAIL_MIN_PX`` long, within ``HATCH_TAIL_DEG`` of a groove family,
#: the rest (at least ``HATCH_TAIL_MIN_BODY_PX``) off the hatch, and the two straight
#: lines fitting the peaks ``HATCH_TAIL_MAX_SSE_SHARE`` or less of one line's squares
#: (``_hatch_tail``)
HATCH_TAIL_MIN_PX = 20.0
HATCH_TAIL_MIN_BODY_PX = 40.0
HATCH_TAIL_DEG = 3.0
HATCH_TAIL_MAX_SSE_SHARE = 0.25
#: ... and the tail's peaks (median) at most this share of the body's
HATCH_TAIL_MAX_AMPLITUDE_SHARE = 0.6
#: ... and a cubic through all the peaks no more than this many times better (its
#: weighted squares) than the two lines: a smooth bend is the scratch's own
HATCH_TAIL_MAX_CUBIC_GAIN = 4.0


def _hatch_tail(s: np.ndarray, c: np.ndarray, w: np.ndarray, ang: float, angles_deg,
                alignment_deg: float) -> tuple[np.ndarray, float, int] | None:
    """Which of a scratch's centre-line peaks (``s`` along its axis ``ang``, rad; ``c``
    across; weights ``w``) are a groove's straight stretch at one of its ends: (that mask,
    where along the axis the peaks leave the scratch's line for the groove's, the end: 0
    low s, 1 high s), or None.

    A scratch that ends on a deep groove at a shallow angle joins the groove's residue in
    one region, and the peaks run on along the groove; at 15-20 deg from the scratch the
    robust line's Tukey weights do not drop them, they drag it, and the cubic follows the
    groove (the twin's frame 2131037: a 1.33 mm scratch 17 deg off the groove it ends on
    read 2.36 mm). The peaks then lie on two straight lines that meet at the kink: the
    tail along a groove family (``angles_deg``, within ``HATCH_TAIL_DEG``) and the body
    off the hatch (``alignment_deg`` or more from each family). A scratch bends slowly
    (the renderer's modes: 1.2 % of its length) and never onto the hatch at a kink; one
    along the hatch is never cut here."""
    if s.size < 12 or not len(angles_deg):
        return None
    o = np.argsort(s)
    ss, cc, ww = s[o], c[o], np.maximum(w[o], 1e-12)

    def line_fit(sel: np.ndarray) -> tuple[float, float, float]:
        """Weighted least squares c = a + m s: (sum of squares, a, m)."""
        x, y, q = ss[sel], cc[sel], ww[sel]
        sw = q.sum()
        mx, my = (q * x).sum() / sw, (q * y).sum() / sw
        vx = (q * (x - mx) ** 2).sum()
        slope = (q * (x - mx) * (y - my)).sum() / vx if vx > 0 else 0.0
        r = y - my - slope * (x - mx)
        return float((q * r * r).sum()), float(my - slope * mx), float(slope)

    whole = line_fit(np.ones(ss.size, bool))[0]
    if whole <= 0:
        return None
    # the best split of the peaks into two straight lines; the tail then the part along
    # the hatch (at least HATCH_TAIL_MIN_PX), the body the other (HATCH_TAIL_MIN_BODY_PX)
    best = None
    for b in np.arange(ss[0] + HATCH_TAIL_MIN_PX, ss[-1] - HATCH_TAIL_MIN_PX + 1e-9, 2.0):
        low = ss < b
        if low.sum() < 4 or (~low).sum() < 4:
            continue
        fl, fh = line_fit(low), line_fit(~low)
        if best is None or fl[0] + fh[0] < best[0]:
            best = (fl[0] + fh[0], float(b), fl[2], fh[2])
    if best is None or best[0] > HATCH_TAIL_MAX_SSE_SHARE * whole:
        return None
    _, b, m_low, m_high = best
    deg = [float(np.rad2deg(ang + np.arctan(m)) % 180.0) for m in (m_low, m_high)]
    span = (b - ss[0], ss[-1] - b)
    for side in (0, 1):  # 0: the tail at the low end of s, 1: at the high end
        if span[side] >= HATCH_TAIL_MIN_PX and span[1 - side] >= HATCH_TAIL_MIN_BODY_PX and \
                any(_circ_diff_deg(deg[side], g) <= HATCH_TAIL_DEG for g in angles_deg) and \
                all(_circ_diff_deg(deg[1 - side], g) >= alignment_deg for g in angles_deg):
            break
    else:
        return None
    tail = ss < b if side == 0 else ss >= b
    # ... and fainter: the groove's stretch is what the wall model misses of it, the
    # scratch's darkness is whole along its length (its width varies by ~15 %). A scratch
    # along the hatch whose region took in a piece off it (a crossing's residue) split
    # there, its own long stretch the "tail" at 0.70-1.13 of the piece's peaks (along
    # the hatch 542000: six scratches cut to a third of their length); 2131037's groove
    # 0.53 of its scratch's
    if float(np.median(ww[tail])) > HATCH_TAIL_MAX_AMPLITUDE_SHARE * float(np.median(ww[~tail])):
        return None
    # ... and a kink, not the scratch's own bend: a scratch bends smoothly (the renderer's
    # two modes, 1.2 % of its length each, turn its ends by up to ~6 deg), which a cubic
    # follows to the noise, and one 10 deg off the hatch bent its last 48 px within 3 deg
    # of it and was cut to 1.33 of its 1.81 mm (station frame 88091: the two lines' squares
    # 8.5x the cubic's). Where the cubic fits HATCH_TAIL_MAX_CUBIC_GAIN times better than
    # the two lines, no tail (2131037: 0.23; the twin's 2134066, where a thin scratch
    # merges into a wide groove band: 1.95)
    cubic = np.polyfit(ss, cc, 3, w=np.sqrt(ww))
    r3 = cc - np.polyval(cubic, ss)
    if best[0] > HATCH_TAIL_MAX_CUBIC_GAIN * float((ww * r3 * r3).sum()):
        return None
    out = np.zeros(s.size, bool)
    out[o] = tail
    return out, float(b), side


def _measure_scratch(patch: _Patch, region: np.ndarray, blur_hint: float | None = None, angles_deg=(),
                     alignment_deg: float = 7.5):
    """A scratch: its centre line (a polynomial bend), its extent (``_scratch_extent``)
    and each end at half its local height (``_fit_end``) on its amplitude along it (the
    strip matched-filtered across by its own mean cross profile), its mean width (that
    profile fitted as a blurred box), with standard uncertainties (px). ``angles_deg``:
    the frame's groove families, and ``alignment_deg`` how near one a direction is along
    it (``DefectConfig.groove_alignment_deg``): a groove's stretch the peaks run on along
    at an end is cut off (``_hatch_tail``); none given, none is."""
    r = patch.residual
    h, w = r.shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    wts = np.where(region, np.clip(r, 0.0, None), 0.0)
    if wts.sum() <= 0:
        return None
    xr, yr, wr = xx[region], yy[region], wts[region]
    cx, cy, ang, _ = _weighted_pca(xr, yr, wr)
    # the main line: a deep groove's residue the scratch ends on joins its region as a
    # branch, and a 40 px branch at 60 deg dragged the strip's width, its centre line
    # and its end along it (the twin's frames: a 127 px scratch read 191 px). What lies
    # within a band round the axis (the scratch's half width and blur, and its bend: a
    # few per cent of its length) is the scratch; its axis again from that
    main = np.ones(xr.size, bool)
    for _ in range(2):
        along = (xr - cx) * np.cos(ang) + (yr - cy) * np.sin(ang)
        across = -(xr - cx) * np.sin(ang) + (yr - cy) * np.cos(ang)
        keep = np.abs(across) <= 8.0 + 0.03 * float(np.ptp(along[main]))
        if keep.sum() < 8 or wr[keep].sum() <= 0:
            break
        main = keep
        cx, cy, ang, _ = _weighted_pca(xr[main], yr[main], wr[main])
    ca, sa = np.cos(ang), np.sin(ang)
    along = (xr[main] - cx) * ca + (yr[main] - cy) * sa
    across = -(xr[main] - cx) * sa + (yr[main] - cy) * ca
    half_w = max(float(np.percentile(np.abs(across), 98)) + 6.0, 8.0)
    step = 0.5
    # beyond the region's ends by 30 px: a faint scratch's region, grown at full resolution,
    # may stop short of its end; and 5 px more each side, the flanks of the matched filter
    s = np.arange(along.min() - 30.0, along.max() + 30.0 + step, step)
    n_all = np.arange(-half_w - 5.0, half_w + 5.0 + step / 2, step)
    strip_all = _strip(r, cx, cy, ang, s, n_all)
    inside_w = np.abs(n_all) <= half_w + 1e-9
    n, strip = n_all[inside_w], strip_all[inside_w]
    # the centre line: column by column, the peak of the cross profile (smoothed over 1 px
    # each way, refined by a parabola), and a polynomial through the peaks with Tukey
    # weights. The darkening's centroid across was pulled by groove residue and noise
    # beside a faint scratch, and the polynomial with it (dev frames: 13 px widths)
    sm = cv2.GaussianBlur(np.nan_to_num(strip).astype(np.float32), (0, 0), 2.0, 2.0)
    sm[~np.isfinite(strip)] = -np.inf
    k = np.argmax(sm, axis=0)
    cols = np.arange(s.size)
    top = sm[k, cols]
    km, kp = np.clip(k - 1, 0, n.size - 1), np.clip(k + 1, 0, n.size - 1)
    y0_, y1_, y2_ = sm[km, cols], top, sm[kp, cols]
    with np.errstate(all="ignore"):
        den = y0_ - 2 * y1_ + y2_
        off = np.where(np.isfinite(den) & (den < 0), 0.5 * (y0_ - y2_) / den, 0.0)
    centre_n = n[k] + np.clip(off, -0.5, 0.5) * step
    col_mass = np.clip(top, 0.0, None)
    # the peaks are fitted over the region's length only: beyond its ends they are the
    # wall's (noise, or the groove a scratch ends on), and the line continues straight
    good = (np.isfinite(top) & (top > 3.0 * patch.noise / 2.0) & (s >= along.min() - 4.0)
            & (s <= along.max() + 4.0))
    if good.sum() < 4:
        return None
    # ... and only where they keep to a straight line, within the bend a scratch has (a few
    # per cent of its length): a groove's residue a scratch ends on leaves it at a shallow
    # angle, and the cubic followed it (bench frames: a 171 px scratch, a groove 25 deg off
    # its end, read 213 px). The line robustly (Tukey weights), then the peaks near it
    tail = _hatch_tail(s[good], centre_n[good], col_mass[good], ang, angles_deg, alignment_deg)
    if tail is not None:
        idx = np.flatnonzero(good)
        good[idx[tail[0]]] = False
    wts = np.sqrt(col_mass[good])
    sg, cg = s[good], centre_n[good]
    for _ in range(5):
        line = np.polyfit(sg, cg, 1, w=wts)
        res = cg - np.polyval(line, sg)
        u = res / (4.685 * max(_mad_sigma(res), 0.5))
        wts = np.sqrt(col_mass[good]) * np.where(np.abs(u) < 1, (1 - u * u) ** 2, 0.0)
        if (wts > 0).sum() <= 3:
            break
    near = np.abs(centre_n - np.polyval(line, s)) <= 3.0 + 0.03 * float(np.ptp(sg))
    if (good & near).sum() >= 4:
        good &= near
    # a cubic: a dragged chip's path bends in up to two modes over its length (the
    # renderer's: sin(pi u) and sin(2 pi u), 1.2 % of the length each), which a quadratic
    # leaves as a wander of ~1-2 px on a 150 px scratch, smearing its cross profile
    deg = 3 if good.sum() >= 40 else (2 if good.sum() >= 12 else 1)
    if deg == 3 and float(np.ptp(s[good])) >= QUINTIC_BEND_PX:
        # a quintic over a long stretch: the lens bends a straight furrow across the frame
        # as r^3 and r^5 do, and with a long scratch's own modes a cubic over 950 px stood
        # 2-4.5 px off its last 40 px, where the matched filter then read nothing (a whole-
        # surface part's 12.2 mm scratch, a frame's piece of it 45 px short)
        deg = 5
    wts = np.sqrt(col_mass[good])
    for _ in range(4):
        coef = np.polyfit(s[good], centre_n[good], deg, w=wts)
        res = centre_n[good] - np.polyval(coef, s[good])
        u = res / (4.685 * max(_mad_sigma(res), 0.3))
        wts = np.sqrt(col_mass[good]) * np.where(np.abs(u) < 1, (1 - u * u) ** 2, 0.0)
        if (wts > 0).sum() <= deg + 2:
            break
    bend_at, slope_at = _bend_function(coef, float(s[good].min()), float(s[good].max()))
    bend = bend_at(s)
    strip_all = _strip(r, cx, cy, ang, s, n_all, bend)
    strip = strip_all[inside_w]
    prof_all = _nanmean_rows(strip[:, good])
    if not np.isfinite(prof_all).any():
        return None
    # integrate across over the scratch's core and its blur (where the mean profile is dark)
    core_half = max(float(np.sum(prof_all > 0.5 * np.nanmax(prof_all))) * step / 2.0 + 5.0, 4.0)
    core_all = np.abs(n_all) <= core_half
    core = core_all[inside_w]
    # the amplitude along the scratch: each column matched-filtered by the mean cross
    # profile (its least-squares multiple), less the mean of 5 px flanks each side. Across
    # the core's 10-15 px the box integral took in as much groove residue and grain as
    # scratch on a thin one, and a deep groove crossing the strip darkens its whole width
    # (the twin's grooves, 10 % deep: a 1.6 px scratch ran on 45 px past its end, a 127 px
    # one on 64 px); the filter weighs each pixel by what the scratch puts there, and
    # darkening as wide as the flanks cancels. A straight furrow's square end blurred by
    # a Gaussian is separable, so the amplitude steps at the end as the darkening does
    flank = (np.abs(n_all) > core_half) & (np.abs(n_all) <= core_half + 5.0)
    used = core_all | flank
    valid = np.isfinite(strip_all[used]).all(axis=0)
    if valid.sum() < 8:
        return None
    filt = np.where(core_all, np.nan_to_num(np.clip(_nanmean_rows(strip_all[:, good]), 0.0, None)), 0.0)
    if filt.sum() <= 0:
        return None
    filt_norm = float(np.sum(filt * filt))
    if flank.any():
        filt = filt - np.where(flank, filt.sum() / flank.sum(), 0.0)
    filt = filt[used]
    sv = s[valid]
    used_strip = strip_all[used][:, valid]
    box_rows = core_all[used]
    grooves = np.nan_to_num(_strip(patch.grooves, cx, cy, ang, s, n_all[used], bend)[:, valid])

    def profiles(factor):
        st = used_strip if factor is None else used_strip * factor
        return np.sum(st[box_rows], axis=0) * step, (filt @ st) / filt_norm

    mv, av = profiles(None)
    gap_px = 8.0
    ext = _scratch_extent(av, step, gap_px)
    if ext is None:
        return None
    s1, s2 = float(sv[ext[0]]), float(sv[ext[1] - 1])
    if s2 - s1 < 3.0:
        return None
    # the mean profile across, over the scratch's length clear of its ends
    inner = (s >= s1 + 2.0) & (s <= s2 - 2.0)
    prof = _nanmean_rows(strip[:, inner])
    ok = np.isfinite(prof)
    if ok.sum() < 5:
        return None
    nv, pv = n[ok], prof[ok]
    # across a thin scratch, its width and contrast trade off under the blur (their product
    # is what the profile fixes); the blur comes from the frame's holes (``blur_hint``)
    # when it has any, else from the scratch itself: its cross profile and the prior here,
    # its ends below (``_scratch_blur``, ``_ends_blur``)
    if blur_hint is not None:
        blur_cam, var_blur = float(np.clip(blur_hint, 0.5, 3.5)), 0.0
    else:
        blur_cam, var_blur = _scratch_blur(nv, pv, half_w)

    def cross_fit(blur_cam):
        # the strip's bilinear sampling, at phases that vary along the scratch, adds the
        # variance of a tent (1/6 px^2) to the averaged cross profile
        b = float(np.sqrt(float(np.clip(blur_cam, 0.5, 3.5)) ** 2 + 1.0 / 6.0))
        return b, _scratch_cross_fit(nv, pv, b, half_w)

    b, cross = cross_fit(blur_cam)
    c = float(cross.x[0])
    # the furrow's floor is smooth: the honing grooves the wall model subtracts are not in
    # it, so where a groove G crosses the scratch the residual reads cover x (c - G) rather
    # than cover x c (dev frames: a faint 1.6 px scratch broke into pieces at deep
    # grooves). Each pixel scaled by c / (c - G), which is 1 off the scratch: the first
    # version added G x width along the centre line, also past the ends, where a deep
    # groove then carried the end on (the twin's frames)
    c_eff = float(np.clip(max(c, float(np.nanmax(prof_all))), 0.05, 1.0))
    factor = c_eff / np.maximum(c_eff - grooves, c_eff / 2.5)
    ext_raw, av_raw = ext, av
    groove_ends = [False, False]  # an end read where a groove's stretch begins
    groove_av = (filt @ grooves) / filt_norm  # the modelled grooves through the same filter
    mv, av = profiles(factor)
    ext = _scratch_extent(av, step, gap_px, held=(av_raw, ext_raw))
    if ext is not None:
        # ... but an end that the scaling carried on into a groove the scratch ends on is
        # the raw darkness's: there the scaling lifts the wall model's misfit of the groove
        # (``_groove_beyond_end``; a whole-surface part's 0.89 mm scratch ending on a deep
        # groove 30 deg off it read 1.06 mm, its place 0.10 mm off), or lifts it to a shelf
        # below the scratch's own level (``_shelf_beyond``)
        lo, hi = ext
        trim = int(np.ceil(2.0 * b / step))  # the raw end's own blurred step
        if _groove_beyond_end(av_raw, groove_av, ext[0], ext_raw[0] - trim, step) \
                or _shelf_beyond(av, groove_av, ext[0], ext_raw[0], ext_raw, step):
            lo = ext_raw[0]
            av[:lo] = av_raw[:lo]
            groove_ends[0] = True
        if _groove_beyond_end(av_raw, groove_av, ext_raw[1] + trim, ext[1], step) \
                or _shelf_beyond(av, groove_av, ext_raw[1], ext[1], ext_raw, step):
            hi = ext_raw[1]
            av[hi:] = av_raw[hi:]
            groove_ends[1] = True
        ext = (lo, hi)
        s1, s2 = float(sv[ext[0]]), float(sv[ext[1] - 1])
    if tail is not None:
        # the scratch ends where it meets the groove its peaks ran on along (``_hatch_tail``):
        # beyond, the darkness is the groove's, which the straight line read for ~15 px as it
        # left it (the twin's 2131037 read 10 % long and 0.07 mm off)
        meet, side = tail[1], tail[2]
        beyond = sv < meet if side == 0 else sv > meet
        av = np.where(beyond, np.minimum(av, 0.0), av)
        groove_ends[side] = True
        if side == 0:
            s1 = max(s1, meet)
        else:
            s2 = min(s2, meet)
        if s2 - s1 < 3.0:
            return None
    if blur_hint is None:
        ends = _ends_blur(sv, av, s1, s2)
        if ends is not None:
            wb = 1.0 / var_blur + 1.0 / ends[1]
            blur_cam = (blur_cam / var_blur + ends[0] / ends[1]) / wb
            var_blur = 1.0 / wb
            b, cross = cross_fit(blur_cam)
    c, n0, width, _ = (float(v) for v in cross.x)
    var_w = float(cross.cov[2, 2]) if np.isfinite(cross.cov[2, 2]) else width**2
    if var_blur > 0:
        # the blur's own uncertainty, carried into the width by the fit's sensitivity to it
        db = 0.1
        bb = float(np.sqrt((float(np.clip(blur_cam, 0.5, 3.5)) + db) ** 2 + 1.0 / 6.0))
        dw = (float(_scratch_cross_fit(nv, pv, bb, half_w, cross.x).x[2]) - width) / db
        var_w += dw * dw * var_blur
    blur_x = b
    blur = float(np.clip(blur_x, 0.7, 2.8))
    ms = gaussian_filter1d(av, 1.0 / step)
    # a square end's step in ms: the camera's blur and the strip's sampling (blur_x), and
    # the 1 px smoothing
    step_blur = float(np.hypot(blur_x, 1.0))
    s1, u_s1 = _fit_end(sv, ms, s1, blur, rising=True, step_blur=step_blur)
    s2, u_s2 = _fit_end(sv, ms, s2, blur, rising=False, step_blur=step_blur)
    # ... each end read at half its local height, which walks out along a shelf past a
    # square end: where the scratch ends on a deep groove crossing it, the model's misfit
    # of the groove beyond holds a third of the scratch's level, and read on it the half
    # height fell onto the shelf, and again, 10-15 px on (the twin's 2133057: a 1.22 mm
    # scratch read 1.37 mm, 0.07 mm off; the raw read's end right). An end that went 10 px
    # or more past the raw read's over a shelf (``_shelf_beyond``) is read at half the
    # scratch's own level instead, from the raw read's end
    if tail is None:
        own = float(np.median(av[ext_raw[0]:ext_raw[1]])) if ext_raw[1] > ext_raw[0] else 0.0
        lo_raw, hi_raw = float(sv[ext_raw[0]]), float(sv[ext_raw[1] - 1])
        k1 = int(np.searchsorted(sv, s1))
        if own > 0 and _shelf_beyond(av, groove_av, k1, ext_raw[0], ext_raw, step):
            s1, u_s1 = _fit_end(sv, ms, lo_raw, blur, rising=True, height=own)
        k2 = int(np.searchsorted(sv, s2, side="right"))
        if own > 0 and _shelf_beyond(av, groove_av, ext_raw[1], k2, ext_raw, step):
            s2, u_s2 = _fit_end(sv, ms, hi_raw, blur, rising=False, height=own)
    if s2 - s1 < 3.0:
        return None
    ss = np.linspace(s1, s2, 200)
    length = float(np.trapezoid(np.sqrt(1.0 + slope_at(ss) ** 2), ss))
    # the width's spread from the fit's covariance: its product with the contrast is what
    # the profile fixes best, the two apart only as well as the blur is known
    u_width = float(np.sqrt(max(var_w, 0.0)))
    mid = (s1 + s2) / 2.0
    nm = float(bend_at(mid)) + n0
    x = cx + mid * ca - nm * sa
    y = cy + mid * sa + nm * ca
    area = float(np.sum(core)) * step * max(s2 - s1, 1.0)
    mass = float(np.sum(mv[(sv >= s1) & (sv <= s2)]) * step)
    significance = mass / (5.0 * patch.noise_box5 * np.sqrt(area))
    # the chord's direction (the centre line's mean slope over the scratch; its slope at
    # the middle, the first version's, is off the chord by up to 5-10 deg on a scratch bent
    # in an S, and a 137 deg scratch read 144 deg and was taken for the 150 deg hatch)
    direction = float(np.rad2deg(ang + np.arctan(float(bend_at(s2) - bend_at(s1)) / (s2 - s1))) % 180.0)
    # the patch cuts the scratch when its strip runs out of the patch (not out of the
    # samples asked for) within reach of an end
    reach = 3.0 * blur + 4.0
    cut = bool((sv[0] > s[0] + 1e-6 and s1 - sv[0] < reach) or (sv[-1] < s[-1] - 1e-6 and sv[-1] - s2 < reach))
    sl = np.linspace(s1, s2, max(int((s2 - s1) / 5.0), 2) + 1)
    nl = bend_at(sl) + n0
    line = (cx + sl * ca - nl * sa, cy + sl * sa + nl * ca)
    return dict(x=float(x), y=float(y), length=length, width=width, angle=direction,
                u_length=float(np.hypot(u_s1, u_s2)), u_width=u_width, significance=float(significance),
                contrast=c, blur=blur_x, mean_darkness=float(np.max(pv)), cut=cut, line=line,
                groove_ends=(bool(groove_ends[0]), bool(groove_ends[1])),
                half_band=float(width / 2.0 + 2.5 * blur + 2.0))


# ---------------------------------------------------------------- burrs and chips
def _runs(mask: np.ndarray, wrap: bool) -> list[tuple[int, int]]:
    """(start, stop) index ranges of the True runs of a 1-D mask; with ``wrap`` a run
    may cross the end (stop > len)."""
    n = mask.size
    if not mask.any():
        return []
    if mask.all():
        return [(0, n)]
    idx = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(np.int8), [0]])))
    runs = [(int(a), int(b)) for a, b in zip(idx[::2], idx[1::2])]
    if wrap and len(runs) > 1 and runs[0][0] == 0 and runs[-1][1] == n:
        first = runs.pop(0)
        last = runs.pop()
        runs.append((last[0], n + first[1]))
    return runs


@dataclass
class _RimProfile:
    theta: np.ndarray  # ray directions (rad, image sense), 0.5 px of arc apart at the rim
    rr: np.ndarray  # radii sampled along each ray (px)
    share: np.ndarray  # (len(rr), len(theta)): the share of "hole", (W - I) / (W - H)
    valid: np.ndarray  # rays wholly inside the frame and clear of other holes' zones
    edge: np.ndarray  # per ray: where the share first falls below ``rim_crossing``, going out
    edge_find: np.ndarray  # the same on the share averaged along the rim (finding defects)
    #: per ray: where the share averaged along the rim first falls below ``RIM_FLOOR_CROSSING``,
    #: going out: the outer end of whatever is darker than the wall there (a chip whose
    #: floor is lit stays below ``rim_crossing`` and does not move ``edge``)
    edge_out: np.ndarray | None = None


def _rim_profile(img: np.ndarray, hole, zone_others: np.ndarray, reach_px: float, wall_level: np.ndarray,
                 angles_deg, blur_px: float, crossing: float, smooth_px: float, groove_sides: bool):
    """The rim along rays from the hole's centre: the share of "hole" (W - I) / (W - H)
    over [R - reach, R + reach], and each ray's edge, where that share first falls
    below ``crossing`` going out (``edge``; ``edge_find`` on the share averaged along
    the rim over ``smooth_px`` of arc first).

    W is the frame's wall level (``wall_level``, full res: it follows the blotches,
    carried over the hole's zone from the wall round it), recalibrated per angle on a
    ring just outside the band; H the hole's own level read per angle inside it. The
    edge is where the hole's dark disc ends, whatever lies inside it (a burr's bright
    metal) or beyond it (a chip's dark notch); a groove or a blotch on the wall moves it
    only when it touches the rim, where an integral of the share across the whole band
    took in every groove within reach (dev frames: 1-4 px on clean rims crossed by deep
    grooves, which the grooves' model, fitted on a ring further out, could not remove
    where they fade along their length)."""
    cx, cy, rad = hole.x_px, hole.y_px, hole.diameter_px / 2.0
    hh, ww = img.shape
    out_px = reach_px + 10.0
    box_px = out_px + 12.0
    x0, x1 = max(int(np.floor(cx - rad - box_px)), 0), min(int(np.ceil(cx + rad + box_px)) + 1, ww)
    y0, y1 = max(int(np.floor(cy - rad - box_px)), 0), min(int(np.ceil(cy + rad + box_px)) + 1, hh)
    p = img[y0:y1, x0:x1].astype(np.float32)
    level = np.ascontiguousarray(wall_level[y0:y1, x0:x1], dtype=np.float32)
    others = zone_others[y0:y1, x0:x1].astype(np.float32)
    # the cross-hatch, modelled on a ring beyond the band and read back along its lines
    # (as the photometric hole fit does); the hole cuts the grooves before the camera
    # blurs them, so they are put back outside the rim only
    yy, xx = np.mgrid[y0:y1, x0:x1].astype(np.float32)
    rho = np.hypot(xx - cx, yy - cy)
    fit_ring = (rho > rad + reach_px + 1.0) & (rho < rad + out_px + 12.0) & (others == 0)
    if fit_ring.sum() > 100:
        d = 1.0 - p / np.maximum(level, 1.0)
        d -= _plane(d, xx - x0, yy - y0, fit_ring)
        grooves = _groove_profiles(d, xx, yy, fit_ring, angles_deg, sides_about=(cx, cy) if groove_sides else None)
        p = p + level * grooves * ndtr((rho - rad) / max(blur_px, 0.5)).astype(np.float32)
    step = 0.5
    n_th = int(np.ceil(2 * np.pi * rad / step))
    theta = np.linspace(0.0, 2 * np.pi, n_th, endpoint=False)
    rr = np.arange(rad - reach_px - 6.0, rad + reach_px + 9.0 + step / 2, step)
    mx = (cx - x0 + rr[:, None] * np.cos(theta)[None, :]).astype(np.float32)
    my = (cy - y0 + rr[:, None] * np.sin(theta)[None, :]).astype(np.float32)
    nan = float("nan")
    polar = cv2.remap(p, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=nan)
    wall_polar = cv2.remap(level, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=nan)
    other_polar = cv2.remap(others, mx, my, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
    inner = rr < rad - reach_px
    band = (rr >= rad - reach_px) & (rr <= rad + reach_px)
    ring = rr > rad + reach_px + 1.0
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a column all outside the frame: NaN, dropped below
        hole_lv = np.nanmedian(polar[inner], axis=0)
        ratio = np.nanmedian(polar[ring] / wall_polar[ring], axis=0)
    valid = (np.isfinite(polar[band]).all(axis=0) & np.isfinite(hole_lv) & np.isfinite(ratio)
             & (other_polar[band | ring].max(axis=0) == 0))
    if valid.sum() < 16:
        return None

    def smooth(v: np.ndarray, px: float) -> np.ndarray:
        filled = np.interp(np.arange(n_th), np.flatnonzero(valid), v[valid], period=n_th)
        return gaussian_filter1d(filled, px / step, mode="wrap")

    # the hole's far side varies slowly round it (vignetting) and has no texture: its
    # level smoothed over ~10 px of arc; the wall's recalibration over 4 px of arc
    hole_s = smooth(hole_lv, 10.0)
    wall_b = wall_polar[band] * smooth(ratio, 4.0)[None, :]
    share = (wall_b - polar[band]) / np.maximum(wall_b - hole_s[None, :], 1.0)
    share[:, ~valid] = 0.0
    rb = rr[band]
    share = _lift_wall(share, rb, valid, rad + 2.5 * blur_px + 1.0, smooth)

    def first_crossing(sh: np.ndarray, crossing: float = crossing) -> np.ndarray:
        # the first fall below ``crossing``, going out, that holds over ``RIM_HOLD_PX``
        # (past the band's end counts as below: the wall; a ray already below it at the
        # band's start, and held: the edge is there)
        below = sh < crossing
        for j in range(1, int(round(RIM_HOLD_PX / step)) + 1):
            below[:-j] &= sh[j:] < crossing
        k = np.argmax(below, axis=0)
        k = np.where(below.any(axis=0), k, rb.size - 1)
        km = np.maximum(k - 1, 0)
        cols = np.arange(n_th)
        s0, s1 = sh[km, cols], sh[k, cols]
        t = np.where(k > 0, (s0 - crossing) / np.maximum(s0 - s1, 1e-6), 0.0)
        e = rb[km] + np.clip(t, 0.0, 1.0) * step
        e = np.where(k > 0, e, rb[0])
        e[~valid] = np.nan
        return e

    edge = first_crossing(share)
    # for finding defects, the crossing of the share averaged along the rim first: a first
    # crossing is a threshold's, and on a dim, noisy frame one noisy pixel moves a ray's
    # edge by pixels (inwards mostly, where the blurred step is brightest), which the
    # edge's smoothing afterwards cannot undo (a normalised average over the valid rays)
    edge_find, sh = edge, share
    if smooth_px > 0:
        sig = smooth_px / (2 * np.pi * rad / n_th)
        mode = "wrap" if valid.all() else "constant"
        w = gaussian_filter1d(valid.astype(np.float64), sig, mode=mode)
        sh = gaussian_filter1d(np.where(valid[None, :], share, 0.0), sig, axis=1, mode=mode)
        sh = sh / np.maximum(w, 1e-6)[None, :]
        edge_find = first_crossing(sh)
    edge_out = first_crossing(sh, RIM_FLOOR_CROSSING)
    edge_out[~(sh < RIM_FLOOR_CROSSING).any(axis=0)] = np.nan  # never left it within the band: not read
    return _RimProfile(theta, rb, share, valid, edge, edge_find, edge_out)


def _lift_wall(share: np.ndarray, rb: np.ndarray, valid: np.ndarray, beyond: float, smooth) -> np.ndarray:
    """The share with the wall's level raised, ray by ray, where the wall just beyond
    the rim (radii from ``beyond`` to the band's end, past the blurred step) reads
    brighter than the level it was calibrated to: its median share there ``e`` < 0,
    averaged along the rim (``smooth``, 4 px of arc) and taken where it exceeds twice its
    own spread round the rim. With the level W' = W - e (W - H) the share is (s - e) /
    (1 - e): the blurred step 1 - (1 - e) Phi, the edge's crossing moved in by the
    mis-read wall, becomes 1 - Phi again, and the hole's side (s = 1) is unchanged.

    Why: the wall's level is calibrated on a ring beyond the band and the grooves put back
    from a model fitted there; where a groove that is deep on that ring fades beside the
    rim, or a dark spot lies on the ring, the wall at the rim is brighter than its level
    (a share of -1.2 over 40 deg of arc), and the edge's crossing moved in by 1.1 px over
    21 px: a false 0.21 mm "burr" at significance 157 on a clean frame (wide bench seed
    86000, frame 25). Only brighter: a wall darker than its level is what a chip is, and
    nothing on the wall beyond a rim is brighter than the wall."""
    outer = rb >= beyond
    if outer.sum() < 3 or valid.sum() < 16:
        return share
    e = np.median(share[outer], axis=0)  # every column finite: unread rays are 0
    e_s = smooth(e, 4.0)
    spread = _mad_sigma(e_s[valid])
    lift = np.minimum(e_s + 2.0 * spread, 0.0)
    lift[~valid] = 0.0
    if not (lift < 0).any():
        return share
    return (share - lift[None, :]) / (1.0 - lift[None, :])


def _rim_integral(prof: _RimProfile, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Per ray, the equivalent edge over [lower, upper]: lower + the share of hole
    integrated over it. Blur moves light along a ray, not in or out of the interval,
    so this is the area-true edge however thin the feature (rays' own bands)."""
    return lower + _band_sum(prof.rr, prof.share, lower, upper)


def _band_sum(rr: np.ndarray, values: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Per ray (column of ``values``, sampled at radii ``rr``), the integral of the values
    over [lower, upper] (px), the samples taken as cells of the radii's step."""
    step = rr[1] - rr[0]
    cum = np.vstack([np.zeros(values.shape[1]), np.cumsum(values, axis=0) * step])
    pos = np.concatenate([[rr[0] - step / 2], rr + step / 2])  # cumulative sums' abscissae
    cols = np.arange(values.shape[1])

    def at(r):
        f = np.clip((r - pos[0]) / step, 0.0, pos.size - 1.000001)
        i = f.astype(np.int64)
        w = f - i
        return cum[i, cols] * (1 - w) + cum[np.minimum(i + 1, pos.size - 1), cols] * w

    return at(upper) - at(lower)


def _robust_harmonics(theta: np.ndarray, edge: np.ndarray, valid: np.ndarray, order: int) -> np.ndarray:
    """The rim's low harmonics (centre offset, ovality) fitted with Tukey weights, so a
    defect on part of the rim does not move them.

    The weights' scale comes from the profile's own small-scale noise (differences over
    4 px of arc), not from the residuals of a first least-squares fit: defects on a
    quarter of the rim (two long burrs of a bench frame) pulled that fit, inflated its
    residuals' spread and with it the scale, and were then fitted away (dev frames).
    The fit starts from the median radius, so the defects begin as outliers."""
    cols = [np.ones_like(theta)]
    for k in range(1, order + 1):
        cols += [np.cos(k * theta), np.sin(k * theta)]
    a = np.column_stack(cols)
    y = np.nan_to_num(edge)
    lag = max(int(round(4.0 / (2 * np.pi * max(float(np.nanmean(edge)), 1.0) / theta.size))), 1)
    both = valid & np.roll(valid, -lag)
    local = _mad_sigma((np.roll(y, -lag) - y)[both]) / np.sqrt(2.0)
    # a clean rim wanders by ~0.1-0.3 px where grooves cross it; a measured centre may be
    # off by 1-2 px (a first harmonic of that size; two large burrs pull the hole's fit):
    # the weights' reach shrinks from 3.7 px to the noise's over the first passes, so
    # the rim's clean rays are kept while the harmonics settle (dev frames: two burrs
    # on a quarter of a rim left a false "chip" between them with a fixed 1.6 px reach)
    scale = max(local, 0.1)
    coef = np.zeros(a.shape[1])
    coef[0] = float(np.median(y[valid]))
    w = valid.astype(np.float64)
    reach = (0.8, 0.6, 0.45, 0.35)
    for it in range(10):
        res = y - a @ coef
        c = 4.685 * max(scale, reach[it] if it < len(reach) else 0.0)
        u = res / c
        w = np.where(valid & (np.abs(u) < 1), (1 - u**2) ** 2, 0.0)
        if w.sum() < a.shape[1] * 3:
            break
        sw = np.sqrt(w)
        coef = np.linalg.lstsq(a * sw[:, None], y * sw, rcond=None)[0]
    return a @ coef


def camera_blur_from_edge(edge_sigma_px: float) -> float:
    """The camera's blur (Gaussian sigma, px) from a hole's measured rim: the rays' edge
    profile width (``HoleMeasurement.edge_sigma_px``) less the measurer's 1 px smoothing
    and the 1/6 px^2 of bilinear sampling (``station.vision.measure``), never below
    0.5 px; dev frames: within ~0.05 px of the rendered blur.

    Public because the blur is the camera's, not the frame's: the coverage scan reads it
    at the holes' edges during the bore scan and gives it to every surface frame
    (``detect_defects(blur_px=...)``), most of which show no hole to read it from."""
    return float(np.sqrt(max(edge_sigma_px**2 - SMOOTH_SIGMA_PX**2 - 1.0 / 6.0, 0.25)))


def _hole_blur(hole) -> float:
    """The camera's blur at a hole's rim (px): :func:`camera_blur_from_edge` of its
    ``edge_sigma_px``."""
    return camera_blur_from_edge(hole.edge_sigma_px)


def _marks_mask(shape: tuple[int, int], found, blur: float) -> np.ndarray:
    """The frame's pores and scratches found, each as its measured ellipse (length by
    width along its direction) grown by its blurred skirt (3 blur + 2 px): whole, where
    their claimed regions stop at a hole's zone (``_groove_run_on`` must not read a pore
    beside a rim as a groove's darkness running on)."""
    mask = np.zeros(shape, np.uint8)
    pad = 3.0 * blur + 2.0
    for d in found:
        if d.kind not in ("pore", "scratch"):
            continue
        axes = (int(np.ceil(d.length_px / 2.0 + pad)), int(np.ceil(d.width_px / 2.0 + pad)))
        cv2.ellipse(mask, (int(round(d.x_px)), int(round(d.y_px))), axes, float(d.angle_deg), 0.0, 360.0, 1, -1)
    return mask.astype(bool)


def _rim_noise(dev: np.ndarray, k: float, rounds: int = 4) -> float:
    """The noise of a rim's edge about its circle (px): the robust spread (MAD) of the
    deviations, read again without those that stand out at ``k`` times it, until it
    settles. The MAD alone is robust to a few defects, not to a rim that is half defect:
    two burrs and two chips over 42 % of a 0.75 mm hole's rim read a noise of 0.62 px
    (clean rims there: 0.05-0.17), and the chips, 2.5 and 3.5 px high, stayed under the
    5-noise bar (station bench seed 93005); without the burrs it reads 0.17 px. On a
    rim without defects nothing stands out at k noise, and the first reading stands."""
    noise = max(_mad_sigma(dev), 0.02)
    for _ in range(rounds):
        inside = np.abs(dev) < k * noise
        if inside.sum() < 10 or inside.all():
            break
        new = max(_mad_sigma(dev[inside]), 0.02)
        if abs(new - noise) <= 1e-3 * noise:
            break
        noise = new
    return noise


def _rim_defects(img: np.ndarray, hole, index: int, zone_others: np.ndarray, wall_level: np.ndarray, angles_deg,
                 cfg: DefectConfig, mm_per_px: float, marks: np.ndarray | None = None) -> list[Defect]:
    """Burrs and chips on one hole's rim: where the rim's edge stands out of its own
    low harmonics, inwards (burr) or outwards (chip). ``marks``: the frame's pores and
    scratches found (``_marks_mask``), which a chip's run-on test does not read."""
    blur = _hole_blur(hole) if getattr(hole, "edge_sigma_px", None) else 1.3
    reach = cfg.rim_reach_mm / mm_per_px + 2.5 * blur + 2.0
    prof = _rim_profile(img, hole, zone_others, reach, wall_level, angles_deg, blur, cfg.rim_crossing,
                        cfg.rim_find_smooth_px, cfg.rim_groove_sides)
    if prof is None:
        return []
    theta, valid = prof.theta, prof.valid
    rad = hole.diameter_px / 2.0
    n = theta.size
    # the rays run on across theta = 0 when both ends are read: an arc left out elsewhere
    # (another hole's zone, a pore claimed beside the rim) does not cut the rim there, and
    # a defect across that point is one run (a burr at 0 deg on a rim with a pore's arc
    # left out was reported twice, as its two halves' runs)
    whole = bool(valid[0] and valid[-1])
    # the rim's baseline is a circle (the first harmonic: the measured centre's offset):
    # a second harmonic (ovality) bent round the arcs the defects take out of the fit
    # and read the clean rim between two burrs as a 3 px "chip" (dev: a quarter of a rim
    # under two burrs); a compensating hole's ovality on the bore is well under 1 px
    base = _robust_harmonics(theta, prof.edge, valid, 1)
    dev = np.where(valid, prof.edge - base, 0.0)
    step_arc = 2 * np.pi * rad / n  # px of arc per ray
    # smoothed over ~1 px of arc: the rays are 0.5 px apart and the blur correlates them
    dev_s = gaussian_filter1d(dev, 1.0 / step_arc, mode="wrap" if whole else "nearest")
    noise = _rim_noise(dev_s[valid], cfg.rim_k)
    thr = max(cfg.rim_k * noise, cfg.rim_min_height_px)
    # the rays' edges on the share averaged along the rim, where a defect is looked for
    dev_f = np.where(valid, prof.edge_find - _robust_harmonics(theta, prof.edge_find, valid, 1), 0.0)
    dev_f = gaussian_filter1d(dev_f, 1.0 / step_arc, mode="wrap" if whole else "nearest")
    thr_f = max(cfg.rim_k * _rim_noise(dev_f[valid], cfg.rim_k), cfg.rim_min_height_px)
    # the area-true deviation, each ray integrated over its own edge and the baseline
    # plus the blur's reach: thin features (a burr lower than the blur) keep their area.
    # The ends and the significance are read on it; a chip's depth on the same integral
    # with the bands reaching out as far as whatever is darker than the wall (``area``):
    # a chip's lit floor stays below the edge's crossing, and its rays' bands ended
    # inside it (6.5 px read 3.2). The ends on the wider bands came out 1-3 px long on
    # short defects (dev frames).
    margin = 3.0 * blur + 1.0
    edge0 = np.nan_to_num(prof.edge, nan=0.0)
    clean = valid & (np.abs(dev_s) < 2.0 * noise)
    mode = "wrap" if whole else "nearest"

    def integral(lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
        d = np.where(valid, _rim_integral(prof, lower, upper) - base, 0.0)
        # what the integral reads on the rim's clean rays (its small bias from the rim's
        # curvature and the band's texture), taken off
        return d - float(np.median(d[clean])) if clean.sum() > 10 else d

    lower, upper = np.minimum(edge0, base) - margin, np.maximum(edge0, base) + margin
    dev_int = integral(lower, upper)
    dev_int_s = gaussian_filter1d(dev_int, 1.0 / step_arc, mode=mode)
    # out to 1.5 blur + 1 px past the floor's crossing (0.2, already ~0.8-1.5 blur past a
    # notch's end: 99.5 % of the blurred step; each px further only added noise, and a
    # shallow chip lost 0.3 px), the deepest within the blur's spill along the rim (its
    # light reaches the neighbours' rays); the extra reach read against the clean rays'
    # own share at each radius (the wall's ~0 reads -0.05 to -0.15 round some holes, lit
    # above the ring that calibrates it). For chips only: reaching inwards as well (a
    # deep narrow burr's spill) moved burrs' heights by -0.3 to +0.3 px at random, and the
    # outward reach, where a groove at the rim carries the floor's crossing out, lifted a
    # dim rim's dent over the significance bar as a false 2 px burr (wide bench)
    spill = 2 * int(np.ceil(margin / step_arc)) + 1
    edge_out = np.maximum(edge0, np.nan_to_num(prof.edge_out, nan=0.0)) if prof.edge_out is not None else edge0
    upper_w = np.maximum(maximum_filter1d(np.where(valid, np.maximum(edge_out, base), base), spill, mode=mode)
                         + 1.5 * blur + 1.0, upper)
    area = dev_int
    if clean.sum() > 10:
        excess = prof.share - np.median(prof.share[:, clean], axis=1)[:, None]
        area = dev_int + np.where(valid, _band_sum(prof.rr, excess, upper, upper_w), 0.0)
    out: list[Defect] = []
    for sign, kind in ((-1.0, "burr"), (1.0, "chip")):
        sd = sign * dev_s
        sf = sign * dev_f
        # teeth of one ragged defect join over dips that stay above a third of the
        # threshold: a clean rim between two defects comes back to within the noise
        for a, b in _merge_runs(_runs((sf > thr_f) & valid, whole), sf, whole, 0.35 * thr_f):
            idx = np.arange(a, b) % n
            h_ref = float(np.median(sd[idx]))
            # walk out to half the run's height, sub-sample by linear interpolation
            lo, hi = a, b - 1
            while sd[(lo - 1) % n] > 0.5 * h_ref and valid[(lo - 1) % n] and b - lo < n:
                lo -= 1
            while sd[(hi + 1) % n] > 0.5 * h_ref and valid[(hi + 1) % n] and hi + 1 - a < n:
                hi += 1
            v_lo_in, v_lo_out = sd[lo % n], sd[(lo - 1) % n]
            v_hi_in, v_hi_out = sd[hi % n], sd[(hi + 1) % n]
            f_lo = (v_lo_in - 0.5 * h_ref) / max(v_lo_in - v_lo_out, 1e-9)
            f_hi = (v_hi_in - 0.5 * h_ref) / max(v_hi_in - v_hi_out, 1e-9)
            start, stop = lo - min(f_lo, 1.0), hi + min(f_hi, 1.0)
            pad = int(np.ceil((3.0 * blur + 3.0) / step_arc))
            win = np.arange(int(np.floor(start)) - pad, int(np.ceil(stop)) + pad + 1)
            ok = valid[win % n]
            if ok.sum() < 6:
                continue
            s_arc = win[ok] * step_arc
            # the ends on the area-true profile: the edge's crossing sits off the middle of
            # the blurred step (``rim_crossing``), which shortens chips and lengthens burrs
            # by ~1.3 blur
            s1, u1 = _fit_end(s_arc, sign * dev_int_s[win[ok] % n], start * step_arc, blur, rising=True)
            s2, u2 = _fit_end(s_arc, sign * dev_int_s[win[ok] % n], stop * step_arc, blur, rising=False)
            length = s2 - s1
            if not length >= cfg.rim_min_length_px:
                continue
            # the mean height: the area-true deviation integrated over the defect and the
            # blur's spill along the rim
            inside = (s_arc >= s1 - 2.5 * blur) & (s_arc <= s2 + 2.5 * blur)
            prof_h = area if kind == "chip" else dev_int
            height = float(np.sum(sign * prof_h[win[ok] % n][inside]) * step_arc) / length
            floor = _chip_floor(prof, win[ok] % n, s_arc, s1, s2, base, edge_out, blur) if kind == "chip" else 1.0
            # the area counts a chip's floor at the hole's level; it may be lit
            height /= floor
            if height < cfg.rim_min_height_px:
                continue  # the area-true height decides; the crossing only found it
            # ... and it must stand out of the rim either side of it: where the wall's model
            # is off along an arc (a groove or blotch it misreads), the whole arc's edge moves
            # by 0.3-0.7 px, and noise on it crossed the 1 px bar as short false "burrs" (wide
            # bench seed 82000: 2 of 3 false defects per 100 clean frames; the same recall
            # above the limit there, on wide seed 85000 and station seed 60000)
            local = _flank_level(sign * prof_h, valid, whole, s1, s2, blur, step_arc)
            if height - local * float(inside.sum()) * step_arc / length / floor < cfg.rim_min_height_px:
                continue
            if kind == "chip" and _groove_run_on(img, wall_level, zone_others if marks is None else zone_others | marks,
                                                 hole, ((s1 + s2) / 2.0) / rad, length, height, angles_deg,
                                                 blur) > cfg.chip_groove_share:
                continue  # a deep groove running into the rim
            if kind == "chip" and _groove_along_rim(img, wall_level, zone_others if marks is None else zone_others | marks,
                                                    hole, s1 / rad, s2 / rad, height, angles_deg,
                                                    blur) > cfg.chip_groove_along_share:
                continue  # a deep groove grazing the rim
            partial = not ok.all()
            significance = height * np.sqrt(length) / noise
            if significance < cfg.min_significance:
                continue
            if kind == "burr":
                # a burr's height as reported: its rays' edges' mean depth between its ends.
                # The area-true height above (what finds it) counts the burr's metal at the
                # wall's level, but it is 0.9-1.15 of it, a share of -0.4 to 0.25 of the
                # wall-to-hole step at 40 % hole contrast, and the height scales with it; the
                # edge's crossing (0.75) moves with the burr's level by 0.25 blur at most,
                # and the baseline, fitted to the crossings, holds the crossing's own offset.
                # Dev frames 7200-7349 / fresh seed 95000: within tolerance 97.3 / 94.2 % ->
                # 99.1 / 100 %, median abs. error 0.46 / 0.49 -> 0.22 / 0.26 px, better at
                # every height, burrs lower than 1.5 blur included
                along = (s_arc >= s1) & (s_arc <= s2)
                edge_height = float(np.mean(sd[win[ok] % n][along])) if along.any() else 0.0
                if edge_height > 0.0:
                    height = edge_height
            th = 2 * np.pi * ((((s1 + s2) / 2.0) / step_arc) % n) / n
            rc = rad - height / 2.0 if kind == "burr" else rad + height / 2.0
            u_len = float(np.hypot(u1, u2))
            # the noise over the defect, and its level: a chip's floor read or taken as the
            # hole's errs by ~10 %; a burr's level moves its edges' crossing by up to 0.25
            # blur (uniform: 0.15 blur). With the model term (0.6 px) that holds 97-98 % of
            # burrs' heights within 2u on the dev and fresh frames (10 % of the height, the
            # area-true height's term, held 98-100 % at a median u 30-45 % larger)
            level = 0.15 * blur if kind == "burr" else 0.1 * height
            u_h = float(np.hypot(noise * np.sqrt(2.5 * blur / max(length, 1.0)), level))
            out.append(Defect(kind, float(hole.x_px + rc * np.cos(th)), float(hole.y_px + rc * np.sin(th)),
                              float(length), float(height), _confidence(significance, cfg.min_significance),
                              float(np.rad2deg(th) % 360.0), u_len, u_h, float(significance), partial, index))
    return out


def _flank_level(values: np.ndarray, valid: np.ndarray, whole: bool, s1: float, s2: float, blur: float,
                 step_arc: float) -> float:
    """The level of ``values`` (per ray, signed as the defect) on the rim either side of
    [s1, s2] (px of arc), past the blur's spill: the lower of the two flanks' medians,
    0 when it is below 0 or a flank is not read."""
    n = values.size
    gap = 2.5 * blur
    width = max(8.0, s2 - s1)
    levels = []
    for a, b in ((s1 - gap - width, s1 - gap), (s2 + gap, s2 + gap + width)):
        k = np.arange(int(np.floor(a / step_arc)), int(np.ceil(b / step_arc)) + 1)
        if not whole:
            k = k[(k >= 0) & (k < n)]
        k = k % n
        k = k[valid[k]]
        if k.size < 4:
            return 0.0
        levels.append(float(np.median(values[k])))
    return max(min(levels), 0.0)


def _darkness_reader(img: np.ndarray, wall_level: np.ndarray, others: np.ndarray):
    """A function of points (..., 2) giving the wall's darkness 1 - I / W there (W the
    frame's level ``wall_level``, bilinear), NaN off the frame and in ``others``."""
    hh, ww = img.shape
    level = np.asarray(wall_level, np.float32)

    def darkness(pts: np.ndarray) -> np.ndarray:
        x = pts[..., 0].astype(np.float32)
        y = pts[..., 1].astype(np.float32)
        v = cv2.remap(img, x, y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).astype(np.float32)
        w = cv2.remap(level, x, y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        ix, iy = np.rint(x).astype(int), np.rint(y).astype(int)
        inside = (ix >= 0) & (iy >= 0) & (ix < ww) & (iy < hh)
        inside[inside] = ~others[iy[inside], ix[inside]]
        return np.where(inside, 1.0 - v / np.maximum(w, 1.0), np.nan)

    return darkness


def _hole_darkness(darkness, centre: np.ndarray, rad: float, theta: float) -> float | None:
    """The hole's own darkness towards angle ``theta`` (rad): the median over 11 points
    across 10 px at 0.6 of its radius; None where fewer than 3 are read or it is under
    0.05 (no hole to compare a mark with)."""
    radial = np.array([np.cos(theta), np.sin(theta)])
    inner = centre + 0.6 * rad * radial + np.linspace(-5.0, 5.0, 11)[:, None] * np.array([-radial[1], radial[0]])
    d = darkness(inner[None])
    if np.isfinite(d).sum() < 3:
        return None
    v = float(np.nanmedian(d))
    return v if v > 0.05 else None


def _groove_along_rim(img: np.ndarray, wall_level: np.ndarray, others: np.ndarray, hole, theta1: float,
                      theta2: float, height: float, angles_deg, blur: float) -> float:
    """How dark the wall stays beyond both ends of a chip found between angles
    ``theta1`` and ``theta2`` (rad) of ``hole``'s rim, ``height`` px deep, along lines
    of the hatch's directions through the notch and just outside it, as a share of the
    hole's darkness (both 1 - I / W, as ``_groove_run_on``): a deep groove that grazes
    the rim (runs nearly along its tangent) darkens the wall along an arc just outside
    it and moves the edge out there as a notch does, but leaves the rim at under 0.2 of
    the radial direction, where ``_groove_run_on`` does not look; its darkness runs on
    along its line past both the notch's ends, where a chip's wall comes back.

    Lines 1 px of arc apart across the notch, at 0.5, 0.75 and 1 of its depth out from
    the rim and 1.5 blur beyond its depth (where the edge is read, the groove's skirt
    and the hole's blurred step together reach the edge's crossing: a groove that makes
    a shallow notch has its middle outside it), are followed both ways along each
    direction from where each leaves the notch (its ends' angles or its depth), 3 blur
    + 2 px on, over 24 px; points nearer the hole's centre than its radius plus that
    clearance (the rim's blurred step, the hole beyond it), off the frame or in
    ``others`` are not read, nor a line with fewer than 8 points left. Each line's
    median darkness, each way's upper quartile over a depth's lines; the lower of the
    two ways, the greatest over the depths and directions. A direction that either way
    does not read (one that runs into the hole, the radial test's) counts 0, as does a
    hole under 0.05 dark."""
    centre = np.array([hole.x_px, hole.y_px])
    rad = hole.diameter_px / 2.0
    mid = 0.5 * (theta1 + theta2)
    half = 0.5 * (theta2 - theta1)
    darkness = _darkness_reader(img, wall_level, others)
    hole_dark = _hole_darkness(darkness, centre, rad, mid)
    if hole_dark is None:
        return 0.0
    depth = max(height, 1.0)
    th = np.linspace(theta1, theta2, max(3, int(np.ceil(2.0 * half * rad)) + 1))
    ray = np.stack([np.cos(th), np.sin(th)], axis=1)
    clear = 3.0 * blur + 2.0
    walk = np.arange(0.0, 2.0 * rad + 2.0 * depth + 2.0 + 1.5 * blur, 0.5)  # long enough to cross the notch
    read = np.arange(0.0, 24.0, 1.0)
    best = 0.0
    for out_px in (0.5 * depth, 0.75 * depth, depth, depth + 1.5 * blur):
        q = centre + (rad + out_px) * ray  # (lines, 2)
        for a in angles_deg:
            u = np.array([np.cos(np.deg2rad(a)), np.sin(np.deg2rad(a))])
            ways = []
            for sgn in (1.0, -1.0):
                d = q[:, None, :] + sgn * walk[None, :, None] * u - centre
                r = np.hypot(d[..., 0], d[..., 1])
                dth = (np.arctan2(d[..., 1], d[..., 0]) - mid + np.pi) % (2.0 * np.pi) - np.pi
                outside = (np.abs(dth) > half) | (r > rad + max(depth, out_px)) | (r < rad - 1.0)
                left = walk[np.argmax(outside, axis=1)]  # where each line leaves the notch
                pts = q[:, None, :] + sgn * (left[:, None] + clear + read[None, :])[..., None] * u
                dd = pts - centre
                v = np.where(np.hypot(dd[..., 0], dd[..., 1]) >= rad + clear, darkness(pts), np.nan)
                ok = np.isfinite(v).sum(axis=1) >= 8
                if not ok.any():
                    break
                ways.append(float(np.percentile(np.nanmedian(v[ok], axis=1), 75.0)))
            if len(ways) == 2:
                best = max(best, min(ways))
    return best / hole_dark


def _groove_run_on(img: np.ndarray, wall_level: np.ndarray, others: np.ndarray, hole, theta: float, length: float,
                   height: float, angles_deg, blur: float) -> float:
    """How dark the wall stays beyond a chip found at angle ``theta`` (rad) of ``hole``'s
    rim (``length`` px of arc, ``height`` px deep), along the hatch's directions, as a
    share of the hole's own darkness (both 1 - I / W, W the frame's level ``wall_level``).

    For each groove direction that leaves the rim outwards (at least 0.2 of it radial),
    lines in that direction from the notch's mouth on the rim (1 px apart, across its
    length and 1 px beyond each end) are read over 24 px, starting where each leaves the
    notch (through its depth or its side) and then 3 blur + 2 px further radially (clear
    of the blurred step), at least 6 px along; each line's median darkness, and the upper
    quartile of the lines' (the darkest direction's).  A chip's notch ends and the wall
    beyond is the wall (a groove's depth, ~0.05 of the hole's darkness at the median); a
    deep groove that runs into the rim carries its darkness on over the notch it makes,
    which is as wide as the groove (0.48-0.77). The darkest line alone (until session 40)
    read a deep groove that merely crosses a true chip's arc and runs on from it: on a 30
    %-contrast hole its darkness is the hole's, and 2 of 37 chips above the limit were
    lost (wide envelope, 22 deg hatch, seed 78000: darkest line 0.65 and 0.88, upper
    quartile 0.23 and 0.19).
    Points off the frame or in another hole's zone (``others``) are not read, nor a line
    with fewer than 8 points left.  0 when no direction leaves the rim outwards."""
    radial = np.array([np.cos(theta), np.sin(theta)])
    tang = np.array([-radial[1], radial[0]])
    centre = np.array([hole.x_px, hole.y_px])
    rad = hole.diameter_px / 2.0
    darkness = _darkness_reader(img, wall_level, others)
    hole_dark = _hole_darkness(darkness, centre, rad, theta)
    if hole_dark is None:
        return 0.0
    # lines through the notch's mouth on the rim, 1 px apart across its length and 1 px
    # beyond each end, in each groove direction, each read from where it leaves the
    # notch (its depth, or its side): read from the notch's outer end along the radius
    # (until session 50), the lines missed a deep groove that meets the rim obliquely,
    # or two that meet at it in a V, whose darkness the notch's depth carries out along
    # the radius or the bisector, away from the grooves' own lines (wide bench: 0.08-0.18
    # mm "chips", run-on shares 0.11-0.24)
    half = length / 2.0 + 1.0
    offsets = np.arange(-half, half + 1e-9, 1.0)
    rim = centre + rad * radial
    best = 0.0
    for a in angles_deg:
        u = np.array([np.cos(np.deg2rad(a)), np.sin(np.deg2rad(a))])
        if u @ radial < 0:
            u = -u
        ur, ut = float(u @ radial), float(u @ tang)
        if ur < 0.2:
            continue
        leave = np.full(offsets.size, max(height, 0.0) / ur)
        if abs(ut) > 1e-6:
            leave = np.minimum(leave, (half - np.sign(ut) * offsets) / abs(ut))
        t0 = max(6.0, (3.0 * blur + 2.0) / ur)
        t = leave[:, None] + t0 + np.arange(0.0, 24.0, 1.0)[None, :]
        d = darkness(rim + offsets[:, None, None] * tang + t[:, :, None] * u)
        read = np.isfinite(d).sum(axis=1) >= 8
        if read.any():
            best = max(best, float(np.percentile(np.nanmedian(d[read], axis=1), 75.0)))
    return best / hole_dark


def _chip_floor(prof: _RimProfile, rays: np.ndarray, s_arc: np.ndarray, s1: float, s2: float, base: np.ndarray,
                edge_out: np.ndarray, blur: float) -> float:
    """A chip's floor as a share of the wall-to-hole step (1: as dark as the hole), by
    which its area-true height is divided. Its broken face slopes into the hole in
    shadow, but not always at the hole's level: a floor lit to 0.7 of the step read a
    6.5 px notch as 3.2 px (dev frames). Read just beyond the rim's own blurred step (1.5
    blur to 1.5 blur + 1.5 px out) on the rays where the notch is deep enough to hold a
    plateau there (its outer end, ``edge_out``, 3 blur + 1.5 px out) and whose share of
    the notch along the rim, under the blur, is at least 0.9 (a 6 px chip under 1.9 px of
    blur covers 0.85 of its middle ray: its floor read 0.68 for 0.95), divided by that
    share; the median over them. 1 where fewer than 3 rays hold one: a shallow or short
    notch's floor and size trade off under the blur, and only their product is read.

    Not for burrs: a burr's torn metal is 0.9-1.15 of the wall's level, which at a hole
    of 40 % contrast is a share of -0.4 to 0.25, but a burr is ragged (its height varies
    by 30 % over 1.5 px along the rim), its rays' share falls off across any window
    inside its rim, and the same reading over-corrected deep burrs by 30-40 % (dev
    frames). A burr's height is read from its rays' edges instead (``_rim_defects``)."""
    along = float(np.sqrt(blur**2 + 1.0 / 6.0))  # the camera's blur and the rays' sampling
    cover = ndtr((s_arc - s1) / along) - ndtr((s_arc - s2) / along)
    vals = []
    for i, c in zip(rays[cover >= 0.9], cover[cover >= 0.9]):
        if not prof.valid[i] or not edge_out[i] - base[i] >= 3.0 * blur + 1.5:
            continue
        sel = (prof.rr >= base[i] + 1.5 * blur) & (prof.rr <= base[i] + 1.5 * blur + 1.5)
        if sel.any():
            vals.append(float(np.mean(prof.share[sel, i])) / c)
    if len(vals) < 3:
        return 1.0
    return float(np.clip(np.median(vals), 0.3, 1.3))


def _fit_end(s: np.ndarray, data: np.ndarray, guess: float, blur: float, rising: bool,
             step_blur: float | None = None, height: float | None = None) -> tuple[float, float]:
    """Where a profile steps up (``rising``) or down near ``guess``: the crossing of half
    its *local* height, the height read 1.2 blur to 1.2 blur + 1 px inside the end
    (where a blurred step has reached 88-97 %), iterated from ``guess``. A ragged defect
    is often low at its ends; one height for the whole defect (a fitted box, or a step
    fitted over a window reaching into its middle) put such ends 1-2 px too far in. On
    the dev frames' 217 rim defects, lengths off by more than 10 % and 2 px: 24 with the
    height read 2-4 blur inside, 13 with 1.2 blur + 1 px. Returns (position, standard
    deviation from the noise at the crossing).

    ``step_blur``: the blur of a square end's step in ``data`` (Gaussian sigma, px), if it
    is one. The height read so near the end is the blurred step's 88-97 %, not its
    plateau, so its half sat outside the end: each end of a square-ended scratch (its
    profile smoothed over 1 px, a step blur of 1.7 px) read 0.2-0.3 px out, every
    scratch 0.55 px long on a clean wall. Given the step's blur, the height is divided by
    what the step reaches where it was read.

    ``height``: the profile's height at the end if known (a square-ended scratch's own
    level): its half is the crossing, not a local height's."""
    order = np.argsort(s)
    s, data = s[order], data[order]
    inward = 1.0 if rising else -1.0
    end = guess
    half = 0.5
    for _ in range(4):
        near = (inward * (s - end) >= 1.2 * blur) & (inward * (s - end) <= 1.2 * blur + 1.0)
        if not near.any():
            break
        if height is not None:
            level = 0.5 * height
        else:
            level = 0.5 * float(np.median(data[near]))
            if step_blur is not None:
                level /= float(np.median(ndtr(inward * (s[near] - end) / step_blur)))
        if level <= 0:
            break
        half = level
        # the crossing nearest the current end, by linear interpolation, that steps the
        # way this end does: up into the defect at its start, down out of it at its end
        # (either way, a ragged chip's end was read on its other side and its length came
        # out negative: wide bench seed 78008, a 0.086 x 0.072 mm chip lost)
        above = data >= half
        cross = np.flatnonzero(above[1:] & ~above[:-1] if rising else above[:-1] & ~above[1:])
        if cross.size == 0:
            break
        i = cross[np.argmin(np.abs(s[cross] - end))]
        t = (half - data[i]) / (data[i + 1] - data[i]) if data[i + 1] != data[i] else 0.5
        new = float(s[i] + t * (s[i + 1] - s[i]))
        if abs(new - end) > 3.0 * blur + 3.0:
            break  # ran off: keep the walk's end
        end = new
    # the crossing moves by noise / slope; a blurred step of height 2 half has slope
    # 2 half / (sqrt(2 pi) blur) at its middle
    resid = _mad_sigma(np.diff(data)) / np.sqrt(2.0)
    slope = 2.0 * half / (np.sqrt(2 * np.pi) * blur)
    return end, float(resid / slope)


def _merge_runs(runs: list[tuple[int, int]], sd: np.ndarray, wrap: bool, floor: float = 0.0) -> list[tuple[int, int]]:
    """Join runs of one sign whose gap stays above ``floor`` throughout: a ragged burr's
    height dips below the threshold between its teeth without the rim coming back, two
    defects side by side are apart where it does (dev frames: two chips 15 px apart
    read as one 39 px chip with a floor of zero)."""
    if len(runs) < 2:
        return runs
    n = sd.size
    runs = sorted(runs)
    out = [runs[0]]
    for a, b in runs[1:]:
        pa, pb = out[-1]
        gap = np.arange(pb, a) % n
        if gap.size == 0 or (sd[gap] > floor).all():
            out[-1] = (pa, b)
        else:
            out.append((a, b))
    if wrap and len(out) > 1:
        pa, pb = out[-1]
        a, b = out[0]
        gap = np.arange(pb, a + n) % n
        if pb - n < a and (gap.size == 0 or (sd[gap] > floor).all()):
            out[0] = (pa, b + n)
            out.pop()
    return out


# ---------------------------------------------------------------- the whole frame
def _measure_holes_for_rims(img: np.ndarray, mm_per_px: float, cfg: DefectConfig) -> list:
    """The frame's holes, as ``measure_holes`` measures them, and those it drops because
    their rim is no clean disc: a large burr or chip makes the photometric fit run away
    (``MeasureConfig.reject_unfitted_whole``), and such a hole, unmeasured, would be taken
    for a 0.7 mm pore (dev frames: a hole with two burrs of 0.2-0.3 mm). Those are
    measured by their rays alone (robust circle, Tukey weights: the defects are its
    outliers), which is all the rim analysis needs."""
    from station.vision.detect import detect_candidates, for_scale
    from station.vision.measure import MeasureConfig, measure_candidate, measure_holes

    # the rims need no grain-aware step: the weighted fit places them well within a px
    holes = list(measure_holes(img, mm_per_px, cfg=MeasureConfig(gls_steps=0)))
    rays_only = MeasureConfig(photometric=None, min_inlier_fraction=cfg.rim_hole_min_inlier_fraction,
                              min_confidence=cfg.rim_hole_min_confidence)
    rays_only = replace(rays_only, detect=for_scale(rays_only.detect, mm_per_px))
    for cand in detect_candidates(img, rays_only.detect):
        if 2.0 * cand.radius_px * mm_per_px < cfg.rim_hole_coarse_share * cfg.min_hole_diameter_mm:
            continue  # too small to be a hole, even as a coarse blob that rim defects cut into
        if any(np.hypot(cand.x_px - h.x_px, cand.y_px - h.y_px) < h.diameter_px / 2 for h in holes):
            continue
        m = measure_candidate(img, cand, rays_only)
        if m is not None and m.diameter_px * mm_per_px >= cfg.min_hole_diameter_mm:
            holes.append(m)
    return holes


def detect_defects(image: np.ndarray, mm_per_px: float, *, holes=None, blur_px: float | None = None,
                   cfg: DefectConfig = DefectConfig()) -> list[Defect]:
    """Pores, scratches, burrs and chips of one grey (or BGR) frame of 8 or 16 bits.

    ``mm_per_px``: the scale at the wall (sizes in mm, and which dark discs are holes).
    ``holes``: the frame's holes (``HoleMeasurement``) if already measured; None
    measures them (``measure_holes``). Holes smaller than ``cfg.min_hole_diameter_mm``
    are not holes but dark marks, and are judged as such.
    ``blur_px``: the camera's blur (Gaussian sigma, px) if known (a calibration's MTF, or
    what the coverage scan read at the holes' edges in the bore scan,
    :func:`camera_blur_from_edge`); otherwise it is read from the frame's holes' edges,
    else from each scratch itself (its mean cross profile, its ends and a prior,
    ``_scratch_blur``) and each pore's own fit: a thin scratch's width is
    fixed only as well as the blur is known (its cross profile is the blur's, widened by
    w^2/12), and a small pore's size trades off against its blur (a 0.085 x 0.076 mm
    pore read 0.050 mm wide with the blur free, 0.090 x 0.072 mm with 1.2 px given:
    ``station bench surface``). (A pore's fitted edge blur was tried as a third
    source and dropped: its ragged outline reads as extra blur, up to 3 px on dev frames.)
    Given, it stands for the blur everywhere but at the rims, which each read their own
    hole's (``_rim_defects``).
    Sorted by y then x.
    """
    if not (mm_per_px and mm_per_px > 0):
        raise ValueError("mm_per_px must be positive")
    img = to_8bit(to_grey(image))
    if holes is None:
        holes = _measure_holes_for_rims(img, mm_per_px, cfg)
    holes = [h for h in holes if h.diameter_px * mm_per_px >= cfg.min_hole_diameter_mm]
    # the wall model leaves out each hole and the band its rim defects may occupy
    reach_px = cfg.rim_reach_mm / mm_per_px + 6.0
    wall = model_wall(img, holes, reach_px, cfg, largest_mark_px=cfg.min_hole_diameter_mm / mm_per_px)
    zone = _hole_zone(img.shape, holes, reach_px)
    hh, ww = img.shape
    level_full = cv2.resize(wall.level, (ww // 2 * 2, hh // 2 * 2), interpolation=cv2.INTER_LINEAR)
    if level_full.shape != img.shape:  # an odd size: the last row or column repeats
        level_full = cv2.copyMakeBorder(level_full, 0, hh - level_full.shape[0], 0, ww - level_full.shape[1],
                                        cv2.BORDER_REPLICATE)
    blur_hint = blur_px
    hole_blurs = [_hole_blur(h) for h in holes if getattr(h, "edge_sigma_px", None)]
    if blur_hint is None and hole_blurs:
        blur_hint = float(np.median(hole_blurs))
    max_width_px = cfg.max_scratch_width_mm / mm_per_px
    examined: list[_Examined] = []
    # what the defects measured so far cover (their regions, a scratch's line): each
    # patch's wall model leaves it out as well as its own candidate (a 0.43 mm pore 14 px
    # below a patch pulled its grooves' fit, and the wall above it stood as a false 0.31 mm
    # pore: bench seed 70078). Not every candidate's pixels: most are the grooves' residue,
    # and a deep groove left out of its own profile's fit read its crossing with another
    # as a 0.31 mm pore (wide seed 1078051)
    claimed = np.zeros(img.shape, bool)
    # the regions alone, which the rims' analysis leaves out (a scratch's cover reaching a
    # rim's groove ring changed its chips: bench seed 80053)
    claimed_regions = np.zeros(img.shape, bool)
    pore_regions = np.zeros(img.shape, np.int32)  # the pores' regions alone, each its own label
    pore_sizes = [0]  # each label's px (label 0: none)
    candidates = _candidates(wall, cfg)
    # (a group; None, or for a member examined on its own what its group's defects claimed)
    queue = [(group, None) for group in _group_collinear(candidates)]
    while queue:
        group, own_group = queue.pop(0)
        bx0 = min(candidates[i][2][0] for i in group)
        by0 = min(candidates[i][2][1] for i in group)
        bx1 = max(candidates[i][2][2] for i in group)
        by1 = max(candidates[i][2][3] for i in group)
        size = max(bx1 - bx0, by1 - by0) * 2
        margin = int(np.clip(0.6 * size, 14, 40))  # room for the wall model round the mark
        box = (max(2 * bx0 - margin, 0), max(2 * by0 - margin, 0), min(2 * bx1 + margin, ww), min(2 * by1 + margin, hh))
        seed = np.zeros((box[3] - box[1], box[2] - box[0]), bool)
        for i in group:
            seed |= _seed_in_box(candidates[i][0], candidates[i][1], box)
        taken = claimed[box[1]:box[3], box[0]:box[2]]
        if own_group is not None:  # its own group's claim grew over it, not a measurement of it
            taken = taken & ~own_group[box[1]:box[3], box[0]:box[2]]
        if taken[seed].mean() > 0.5:
            continue  # already measured as part of another candidate's defect
        # two scratches crossing are one candidate (an X, a V): each furrow is examined on
        # its own, its region confined to its line, the other's pixels left out of the wall
        # model (one candidate's measurement read the X's bisector and neither scratch).
        # The furrows are kept only when they are scratches: a pore with deep grooves'
        # residue attached holds bands too, and its pieces were read as pores; such a
        # seed is examined whole
        results = []
        furrows = [(fx + box[0], fy + box[1], fa, bend) for fx, fy, fa, bend in _furrows(seed)]
        if furrows:
            results = [_examine(img, box, seed & _band(seed.shape, box[:2], line, cfg.furrow_half_band_px), zone,
                                wall.angles_deg, level_full, cfg, blur_hint, max_width_px, excl=seed, confine=line,
                                others=claimed)
                       for line in furrows]
            if not any(ex.defect is not None for ex in results) or \
                    any(ex.defect is not None and ex.defect.kind != "scratch" for ex in results):
                results = []
        if not results:
            results = [_examine(img, box, seed, zone, wall.angles_deg, level_full, cfg, blur_hint, max_width_px,
                                others=claimed)]
            line = _one_furrow(seed) if results[0].defect is None else None
            if line is not None:
                # one furrow whose region, grown unconfined, was no defect: a deep groove's
                # residue that crosses a scratch joins its region, which is then no line and
                # was measured as a pore and dropped (the twin's frames: a 1.66 mm scratch,
                # plain to see, not reported, seed 2086604). Examined again confined to the
                # seed's own line, kept only as a scratch
                line = (line[0] + box[0], line[1] + box[1], line[2], line[3])
                again = _examine(img, box, seed & _band(seed.shape, box[:2], line, cfg.furrow_half_band_px), zone,
                                 wall.angles_deg, level_full, cfg, blur_hint, max_width_px, excl=seed,
                                 confine=line, others=claimed)
                if again.defect is not None and again.defect.kind == "scratch":
                    results = [again]
        for ex in results:
            if ex.defect is None:
                continue
            rb = ex.box or box
            if ex.cover is not None and claimed[rb[1]:rb[3], rb[0]:rb[2]][ex.cover].mean() > 0.5:
                continue  # grown along its line into a scratch already measured (groove residue beside it)
            if ex.defect.kind == "pore" and _measured_again(pore_regions[rb[1]:rb[3], rb[0]:rb[2]], ex.region,
                                                            pore_sizes):
                # a pore measured again: a groove's stretch beside it seeded a region that grew
                # over it (wide bench, 40 deg hatch, seed 89055: a 0.30 mm pore on a deep
                # groove reported a second time as a 0.47 mm one, its centre 7 px off)
                continue
            claimed[rb[1]:rb[3], rb[0]:rb[2]] |= ex.region if ex.cover is None else ex.region | ex.cover
            claimed_regions[rb[1]:rb[3], rb[0]:rb[2]] |= ex.region
            if ex.defect.kind == "pore":
                mine = pore_regions[rb[1]:rb[3], rb[0]:rb[2]]
                fresh = ex.region & (mine == 0)
                mine[fresh] = len(pore_sizes)
                pore_sizes.append(int(np.count_nonzero(fresh)))
            examined.append(ex)
        if len(group) > 1 and not any(ex.defect is not None for ex in results):
            # a group is the guess that its members are pieces of one scratch; when the
            # group is no defect and one member stands out of it (its peak at least
            # ``GROUP_DOMINANT_SHARE`` times every other's), that member is judged on its
            # own, as any candidate is: a groove's stretch on a bent scratch's line, grouped
            # with it, grew its region into no line and no pore, and a 1.63 mm scratch,
            # plain to see, was lost (the twin's 2180009: peaks 32.6 and 6.5). Not members
            # alike: pieces of groove residue in line, each examined alone, gave a 0.54 mm
            # "scratch" where the group was rightly nothing (peaks 7.1 and 6.3, test frame
            # 93401)
            peaks = sorted((candidates[i][3], i) for i in group)
            if peaks[-1][0] >= GROUP_DOMINANT_SHARE * peaks[-2][0]:
                queue.append(([peaks[-1][1]], None))
        elif len(group) > 1:
            # a member apart from the group's defects (a scratch its line and width, a
            # pore its region: no more than a pixel or two of its seed on them) is another
            # mark, examined on its own: a 0.45 mm pore 50 px beyond a scratch's end, on its
            # line, was grouped with it as a piece of it, grown into its region and never
            # measured (wide bench, 35 deg hatch, seed 85007). Not one that touches them: a
            # pore's seed reaches past its measured region into its skirt, and a member
            # half outside was measured twice (wide seed 79046)
            covered = np.zeros(img.shape, bool)
            group_claim = np.zeros(img.shape, bool)
            for ex in results:
                if ex.defect is not None:
                    rb = ex.box or box
                    covered[rb[1]:rb[3], rb[0]:rb[2]] |= ex.region if ex.cover is None else ex.cover
                    group_claim[rb[1]:rb[3], rb[0]:rb[2]] |= ex.region if ex.cover is None else ex.region | ex.cover
            inside = covered[box[1]:box[3], box[0]:box[2]]
            for i in group:
                own = _seed_in_box(candidates[i][0], candidates[i][1], box)
                if own.any() and inside[own].mean() < 0.05:
                    queue.append(([i], group_claim))
    examined = _drop_scratch_pieces(examined)
    examined = _track_scratches(img, level_full, examined, cfg, wall.angles_deg, wall.residual)
    examined = _join_scratch_pieces(img, level_full, examined, cfg)
    found: list[Defect] = [ex.defect if ex.line is None else replace(ex.defect, line_px=_line_points(ex.line))
                           for ex in examined if ex.defect is not None]
    others = [_hole_zone(img.shape, [h for j, h in enumerate(holes) if j != i], reach_px) for i in range(len(holes))]
    blur_rim = blur_hint if blur_hint is not None else BLUR_PRIOR_PX[0]
    marks = _marks_mask(img.shape, found, blur_rim) if holes else None
    grown, labels = None, None
    if holes and claimed_regions.any():
        # a mark that reaches a rim's band, with its blurred skirt (2.5 blur + 1 px): a
        # scratch that ends at a rim darkens the wall beside its region too, read as a
        # 0.07 mm "chip" next to it (wide bench seed 82083). Only those: a pore 30 px out
        # whose skirt reached the ring that calibrates the wall cut a true chip between it
        # and the rim in two (hatch 22 deg, seed 89000)
        skirt = int(np.ceil(2.5 * blur_rim + 1.0))
        grown = cv2.dilate(claimed_regions.astype(np.uint8),
                           cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * skirt + 1, 2 * skirt + 1)))
        labels = cv2.connectedComponents(grown)[1]
    for i, hole in enumerate(holes):
        own = _hole_zone(img.shape, [hole], reach_px)
        marks_i = claimed_regions
        if labels is not None:
            near = np.unique(labels[own & (grown > 0)])
            near = near[near > 0]
            if near.size:
                marks_i = claimed_regions | np.isin(labels, near)
        found += _rim_defects(img, hole, i, others[i] | (marks_i & ~own),
                              level_full, wall.angles_deg, cfg, mm_per_px, marks=marks)
    out = []
    model = {k: (a, b) for k, a, b in cfg.model_u_px}
    for d in found:
        k = cfg.uncertainty_factor
        m_len, m_wid = model.get(d.kind, (0.0, 0.0))
        if d.kind == "scratch":
            m_len = float(np.hypot(m_len, cfg.scratch_length_u_share * d.length_px))
        u_len = float(np.hypot(k * d.length_u_px, m_len))
        u_wid = float(np.hypot(k * d.width_u_px, m_wid))
        out.append(Defect(**{**asdict(d), "length_u_px": u_len, "width_u_px": u_wid,
                             "length_mm": d.length_px * mm_per_px, "width_mm": d.width_px * mm_per_px,
                             "size_mm": d.length_px * mm_per_px, "size_u_mm": u_len * mm_per_px,
                             "width_u_mm": u_wid * mm_per_px}))
    return sorted(out, key=lambda d: (d.y_px, d.x_px))


@dataclass
class _Examined:
    """One candidate examined at full resolution: the defect it is, if any, and the
    region it covers (claimed, so that another candidate's seed in it is not measured
    twice)."""

    defect: Defect | None
    region: np.ndarray
    box: tuple[int, int, int, int] | None = None  # the region's box (None: the candidate's)
    #: a scratch's cover over the same box: its centre line, half its width plus the blur's
    #: reach either side (claimed too; None: the region alone)
    cover: np.ndarray | None = None
    #: a scratch's centre line (frame px, (n, 2), end to end) and its blur (px)
    line: np.ndarray | None = None
    blur: float | None = None
    #: which of a scratch's line's ends (its first point, its last) the measurement read
    #: where a groove's stretch begins (``_groove_beyond_end``, ``_shelf_beyond``): not
    #: followed on (``_track_scratches``)
    groove_ends: tuple[bool, bool] = (False, False)


def _measured_again(labels: np.ndarray, region: np.ndarray, sizes: list[int]) -> bool:
    """Whether a pore's ``region`` is a pore already measured (``labels``: the measured
    pores' regions, each its own label, 0 elsewhere, over the region's box; ``sizes``:
    each label's whole region, px, by label): it covers at least half of one of them."""
    under = labels[region]
    return any(np.count_nonzero(under == lab) >= 0.5 * sizes[lab] for lab in np.unique(under[under > 0]))


def _cover_share(a: "_Examined", b: "_Examined") -> float:
    """The share of ``a``'s cover that lies in ``b``'s (frame px)."""
    (ax0, ay0, ax1, ay1), (bx0, by0, bx1, by1) = a.box, b.box
    x0, y0, x1, y1 = max(ax0, bx0), max(ay0, by0), min(ax1, bx1), min(ay1, by1)
    total = int(a.cover.sum())
    if x1 <= x0 or y1 <= y0 or total == 0:
        return 0.0
    inter = a.cover[y0 - ay0:y1 - ay0, x0 - ax0:x1 - ax0] & b.cover[y0 - by0:y1 - by0, x0 - bx0:x1 - bx0]
    return float(inter.sum()) / total


def _drop_scratch_pieces(examined: list["_Examined"]) -> list["_Examined"]:
    """Scratches of which most of the cover (over half) lies in a longer scratch's: a
    piece of it, measured from its own candidate before the whole one was (claiming
    stops only the pieces that come after). Along the hatch the wall model's grooves
    take a scratch in by pieces, and each was reported (session 45: 5 duplicates in 60
    fresh frames of two such scratches)."""
    scratches = [ex for ex in examined if ex.defect is not None and ex.defect.kind == "scratch"
                 and ex.cover is not None and ex.box is not None]
    drop = set()
    for a in scratches:
        for b in scratches:
            if b is not a and id(b) not in drop and b.defect.length_px > a.defect.length_px \
                    and _cover_share(a, b) > 0.5:
                drop.add(id(a))
                break
    return [ex for ex in examined if id(ex) not in drop]


def _end_tangent(line: np.ndarray, k: int, back_px: float = 20.0) -> np.ndarray:
    """The unit direction out of a centre line's end ``k`` (0 or -1), from the point
    ``back_px`` along it inside the end."""
    pts = line if k == -1 else line[::-1]
    acc = _to_end(pts)
    i = int(np.argmin(np.abs(acc - min(back_px, acc[0]))))
    v = pts[-1] - pts[i]
    n = float(np.hypot(*v))
    return v / n if n > 0 else np.zeros(2)


def _furrow_contrast(img: np.ndarray, level: np.ndarray, pts: np.ndarray, tangents: np.ndarray,
                     core: float) -> np.ndarray:
    """At each point of a path (frame px, with its unit tangents), the raw relative
    darkness ``1 - img / level`` (the grooves kept) over the core ``|n| <= core`` less
    that of flanks 2-6 px beyond it; NaN where the frame does not hold it."""
    off = np.arange(-(core + 6.0), core + 6.0 + 0.25, 0.5)
    in_core, in_flank = np.abs(off) <= core, np.abs(off) >= core + 2.0
    nx, ny = -tangents[:, 1], tangents[:, 0]
    mx = pts[None, :, 0] + off[:, None] * nx[None, :]
    my = pts[None, :, 1] + off[:, None] * ny[None, :]
    hh, ww = img.shape
    bx0, by0 = int(max(np.floor(mx.min()) - 1, 0)), int(max(np.floor(my.min()) - 1, 0))
    bx1, by1 = int(min(np.ceil(mx.max()) + 2, ww)), int(min(np.ceil(my.max()) + 2, hh))
    if bx1 - bx0 < 2 or by1 - by0 < 2:
        return np.full(pts.shape[0], np.nan)
    dark = (1.0 - img[by0:by1, bx0:bx1].astype(np.float32) / np.maximum(level[by0:by1, bx0:bx1], 1.0))
    st = cv2.remap(dark.astype(np.float32), (mx - bx0).astype(np.float32), (my - by0).astype(np.float32),
                   cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=float("nan"))
    with warnings.catch_warnings():  # a point the frame does not hold: NaN, no warning
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmean(st[in_core], axis=0) - np.nanmean(st[in_flank], axis=0)


def _gap_path(pa: np.ndarray, ta: np.ndarray, pb: np.ndarray, tb: np.ndarray, step: float = 1.0):
    """The smooth path (a cubic Hermite curve) from end ``pa`` leaving along ``ta`` to end
    ``pb`` arriving against ``tb`` (both unit, outwards from their pieces): its points
    every ~``step`` px and their unit tangents."""
    g = float(np.hypot(*(pb - pa)))
    n = max(int(np.ceil(g / step)), 1) + 1
    t = np.linspace(0.0, 1.0, n)[:, None]
    m0, m1 = ta * g, -tb * g
    h00, h10, h01, h11 = 2 * t**3 - 3 * t**2 + 1, t**3 - 2 * t**2 + t, -2 * t**3 + 3 * t**2, t**3 - t**2
    pts = h00 * pa + h10 * m0 + h01 * pb + h11 * m1
    d = (6 * t**2 - 6 * t) * pa + (3 * t**2 - 4 * t + 1) * m0 + (-6 * t**2 + 6 * t) * pb + (3 * t**2 - 2 * t) * m1
    d /= np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)[:, None]
    return pts, d


def _scratch_gap(img: np.ndarray, level: np.ndarray, a: "_Examined", b: "_Examined",
                 cfg: DefectConfig) -> tuple[float, int, int, np.ndarray] | None:
    """Whether two scratches of one frame are one furrow with a stretch between them that
    was not measured, and how well: (the gap, a's end, b's end, the gap's path), or None.

    Along the hatch the wall model's grooves take a scratch's darkness in (their means
    along the groove lines are the scratch's own), so a bent scratch whose middle runs
    near a groove direction is found as two pieces, its middle lost (a fresh whole-surface
    part: a 16.6 mm scratch reported as 7.9 and 7.4 mm, ~0.9 mm lost between). Two
    pieces are joined when an end of each faces the other (the gap no longer than
    ``scratch_join_gap_px``, each end's direction within ``scratch_join_turn_deg`` of
    the gap's and of the other's), their widths agree, and the raw darkness along a
    smooth path between the ends (the grooves not removed), core less flanks, is at
    least ``scratch_join_dark_share`` of what it is along the pieces' own last 40 px
    over nearly all of the gap: a groove's residue does not carry it, the furrow does."""
    da, db = a.defect, b.defect
    if max(da.width_px, db.width_px) > 2.5 * max(min(da.width_px, db.width_px), 1.0) + 2.0:
        return None
    best = None
    for ka in (0, -1):
        for kb in (0, -1):
            pa, pb = a.line[ka], b.line[kb]
            g = float(np.hypot(*(pb - pa)))
            if best is None or g < best[0]:
                best = (g, ka, kb)
    g, ka, kb = best
    if g > cfg.scratch_join_gap_px:
        return None
    far = float(np.hypot(*(a.line[-1 - ka] - b.line[-1 - kb])))
    if far < max(da.length_px, db.length_px) + 0.5 * g:
        return None  # side by side, not end to end
    pa, pb = a.line[ka], b.line[kb]
    ta, tb = _end_tangent(a.line, ka), _end_tangent(b.line, kb)
    cos_max = np.cos(np.deg2rad(cfg.scratch_join_turn_deg))
    if float(ta @ -tb) < cos_max:
        return None
    blur = float(np.clip(np.nanmean([a.blur or BLUR_PRIOR_PX[0], b.blur or BLUR_PRIOR_PX[0]]), 0.7, 2.8))
    core = max(0.5 * max(da.width_px, db.width_px) + blur, 1.5)
    if g > 2.0 and float((pb - pa) @ ta) < 0.0:
        # overlapping ends: two measurements of one stretch, when each end lies on the
        # other's centre line
        if max(float(np.min(np.hypot(*(a.line - pb).T))), float(np.min(np.hypot(*(b.line - pa).T)))) > core + 4.0:
            return None
        return -g, ka, kb, np.vstack([pa, pb])
    # end to end: each end off the other's continued line by no more than the core and
    # the turn allowed over the gap (a centre line's last px bend as its fit likes: two
    # pieces 9 px apart met with a 3 px jog, the gap 25 deg off their lines)
    slack = np.tan(np.deg2rad(cfg.scratch_join_turn_deg))
    for p0, t0, p1 in ((pa, ta, pb), (pb, tb, pa)):
        w = p1 - p0
        along = float(w @ t0)
        if abs(float(t0[0] * w[1] - t0[1] * w[0])) > core + 2.0 + slack * max(along, 0.0):
            return None
    path, tang = _gap_path(pa, ta, pb, tb)
    if g > 2.0:
        own = [_own_contrast(img, level, ex.line, k, core, blur) for ex, k in ((a, ka), (b, kb))]
        ref = float(np.nanmin(own)) if np.isfinite(own).any() else float("nan")
        if not (ref > 0):
            return None
        c = _furrow_contrast(img, level, path, tang, core)
        c = gaussian_filter1d(np.nan_to_num(c, nan=-1.0), 1.5)
        if float(np.median(c)) < cfg.scratch_join_dark_share * ref or \
                float(np.mean(c >= 0.5 * cfg.scratch_join_dark_share * ref)) < 0.9:
            return None
    return g, ka, kb, path


def _own_contrast(img: np.ndarray, level: np.ndarray, line: np.ndarray, k: int, core: float, blur: float) -> float:
    """The raw furrow contrast (``_furrow_contrast``) along a centre line's last 40 px
    inside its end ``k`` (clear of the end's blur): the median."""
    pts = line if k == -1 else line[::-1]
    to_end = _to_end(pts)
    near = pts[(to_end <= 40.0) & (to_end >= 2.0 * blur)]
    if len(near) < 2:
        near = pts[-2:]
    span = float(np.hypot(*(near[-1] - near[0])))
    if span <= 0:
        return float("nan")
    dense = near[0] + np.linspace(0.0, 1.0, max(int(span), 2))[:, None] * (near[-1] - near[0])
    tv = (near[-1] - near[0]) / span
    c = _furrow_contrast(img, level, dense, np.tile(tv, (len(dense), 1)), core)
    return float(np.median(c[np.isfinite(c)])) if np.isfinite(c).any() else float("nan")


def _track_on(img: np.ndarray, level: np.ndarray, line: np.ndarray, k: int, width: float, blur: float,
              cfg: DefectConfig) -> np.ndarray | None:
    """A furrow that runs on past a scratch's measured end ``k``: the path that follows
    its ridge (frame px, from the end outwards; its last point where the darkness has
    fallen to half), or None when the end is a cut.

    The measurement reads the darkness with the wall model's grooves removed, and where a
    bent scratch turns along a groove direction those grooves take its darkness in: a
    16.6 mm scratch bent in an S was measured to where it met the hatch, 3 mm short of
    the frame's border (a fresh whole-surface part). The raw darkness (``1 - img /
    level``, the grooves kept), core less flanks, shows the furrow on. From the end the
    path steps ``2 px`` along its direction, moves at most ``track_turn_px`` across per
    step towards the darkest line of a short cross profile (a scratch turns slowly: the
    twin's modes bend a 16 mm scratch by under 3 deg per 50 px), and stops where the
    raw contrast stays below half the scratch's own there for ``track_gap_px`` (a deep
    groove crossing it dips it for a groove's width or two). A run on is taken only when
    the first ``track_min_px`` past the end keep ``track_run_share`` of that contrast (a
    cut's darkness steps down within the blur) and the whole stretch ``track_hold_share``
    (a deep groove that a faint scratch ends on is darker than the wall, but not as dark
    as the scratch: wide bench frame 82039, a 1.73 mm scratch run on 0.35 mm)."""
    core = max(0.5 * width + blur, 1.5)
    ref = _own_contrast(img, level, line, k, core, blur)
    if not (ref > 0):
        return None
    pts = line if k == -1 else line[::-1]
    t = _end_tangent(line, k, 30.0)
    if not np.any(t):
        return None
    hh, ww = img.shape
    step = 2.0
    p = pts[-1].astype(float)
    path = [p.copy()]
    contrast = []
    n = np.array([-t[1], t[0]])
    offs = np.arange(-3.0, 3.0 + 0.25, 0.5)
    below = 0
    for _ in range(int(cfg.track_max_px / step)):
        q = p + step * t
        if not (2.0 <= q[0] <= ww - 3.0 and 2.0 <= q[1] <= hh - 3.0):
            break
        # the cross profile's darkest line within 3 px, each candidate read over 6 px along
        cand = q[None, :] + offs[:, None] * n[None, :]
        seg = cand[:, None, :] + np.array([-3.0, -1.5, 0.0, 1.5, 3.0])[None, :, None] * t[None, None, :]
        c = _furrow_contrast(img, level, seg.reshape(-1, 2), np.tile(t, (seg.shape[0] * seg.shape[1], 1)), core)
        c = c.reshape(seg.shape[0], seg.shape[1])
        if not np.isfinite(c).any():
            break
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            c = np.nanmean(c, axis=1)
        j = int(np.nanargmax(c))
        shift = float(np.clip(offs[j], -cfg.track_turn_px, cfg.track_turn_px))
        q = q + shift * n
        here = float(c[int(np.argmin(np.abs(offs - shift)))])
        contrast.append(here)
        path.append(q.copy())
        # the direction: the path's last 30 px (the piece's end before the path has them)
        back = np.vstack([pts[-16:], np.array(path)])[-16:]
        v = back[-1] - back[0]
        if np.hypot(*v) > 0:
            t_new = v / np.hypot(*v)
            if float(t_new @ t) > 0.0:
                t = t_new
                n = np.array([-t[1], t[0]])
        p = q
        below = below + 1 if here < 0.5 * ref else 0
        if below * step > cfg.track_gap_px:
            break
    # the stretch judged ends 3 steps below half, as it did when a dip that long stopped it
    cs = np.array(contrast[:len(contrast) - max(below - 3, 0)])
    first = max(int(cfg.track_min_px / step), 1)
    if cs.size < first or float(np.median(cs[:first])) < cfg.track_run_share * ref \
            or float(np.median(cs)) < cfg.track_hold_share * ref:
        return None
    # the end: where the contrast (smoothed) last falls through half of the scratch's own
    sm = gaussian_filter1d(cs, 1.0)
    keep = np.flatnonzero(sm >= 0.5 * ref)
    if keep.size == 0:
        return None
    last = int(keep[-1])
    out = np.array(path[:last + 2])
    if last + 1 < cs.size and sm[last] != sm[last + 1]:
        f = (sm[last] - 0.5 * ref) / (sm[last] - sm[last + 1])
        out[-1] = path[last + 1] + float(np.clip(f, 0.0, 1.0)) * (path[last + 2] - path[last + 1]) \
            if last + 2 < len(path) else path[last + 1]
    if float(np.hypot(*np.diff(out, axis=0).T).sum()) < cfg.track_min_px:
        return None
    return out


def _at_frame_border(p: np.ndarray, shape: tuple[int, int]) -> bool:
    """Whether a followed path's end (x, y) stopped at the frame's border (within 4-5 px)."""
    hh, ww = shape
    return bool(p[0] <= 4.0 or p[1] <= 4.0 or p[0] >= ww - 5.0 or p[1] >= hh - 5.0)


def _run_on_fades(img: np.ndarray, level: np.ndarray, on: np.ndarray, width: float, blur: float,
                  cfg: DefectConfig) -> bool:
    """Whether a scratch's run on (``_track_on``'s path, from its end outwards) is a
    groove it meets rather than the scratch: its far end, read inside the frame over the
    path's last 60 px, does not step down as a scratch's end does (no wider than
    ``cfg.square_end_other_max_width_px`` and by ``cfg.square_end_min_height`` of the
    darkness inside it: ``_end_steps``) but fades, as a groove does along its length or
    as a straight path leaves a groove that diverges from it.

    - A scratch's end that meets a deep groove running on 10 deg from it was followed
      along the groove to where that faded (the twin's frames, seed 2087087: a 1.57 mm
      scratch reported 4.16 mm long).
    - Straight on along a deep groove 12 deg off the scratch, to where the groove had
      left the path (seed 2088050: a 1.65 mm scratch read 2.01 mm, its place 0.18 mm
      off): the far end fades over 10 px.

    A scratch that bends along the hatch, which the wall model's grooves took in, keeps
    its stretch: that ends where the scratch does, in a cut, or at the frame's border
    (unread)."""
    seg = np.hypot(*np.diff(on, axis=0).T)
    if on.shape[0] < 2 or float(seg.sum()) < cfg.track_min_px:
        return False
    to_end = np.concatenate([[0.0], np.cumsum(seg[::-1])])[::-1]
    far = on[to_end <= 60.0]
    if far.shape[0] < 2:
        return False
    if _at_frame_border(on[-1], img.shape):
        return False
    steps = _end_steps(img, level, 0, 0, dict(line=(far[:, 0], far[:, 1]), width=width, blur=blur), ends=(-1,))
    if not steps:
        return False
    w, h = steps[0]
    max_width = max(cfg.square_end_other_max_width_px, cfg.square_end_max_width_px, 2.5 * blur)
    return not (w <= max_width and h >= cfg.square_end_min_height)


#: a run on's body, beyond its first ``RUN_ON_SETTLE_PX`` (where the path turns onto
#: what it follows), that is at least ``RUN_ON_BODY_PX`` long, within ``RUN_ON_HATCH_DEG``
#: of a groove family and ``RUN_ON_STRAIGHT_PX`` (RMS) of a straight line:
#: ``_turns_onto_hatch``
RUN_ON_SETTLE_PX = 60.0
RUN_ON_BODY_PX = 120.0
RUN_ON_HATCH_DEG = 2.5
RUN_ON_STRAIGHT_PX = 1.5


def _turns_onto_hatch(line: np.ndarray, k: int, on: np.ndarray, angles_deg, cfg: DefectConfig) -> bool:
    """Whether a scratch's run on (``_track_on``'s path from its end ``k`` outwards) is a
    groove the scratch ends on: the scratch's end runs off the hatch (at least
    ``cfg.groove_alignment_deg`` from a family), and past its first ``RUN_ON_SETTLE_PX``
    the path is a straight line along that family (``RUN_ON_BODY_PX`` long at least,
    within ``RUN_ON_HATCH_DEG`` of it, ``RUN_ON_STRAIGHT_PX`` RMS of a line).

    A groove is straight and keeps the hatch's direction over the frame; a scratch bends
    slowly and its direction passes the hatch's rather than turning onto it and staying
    (the twin's modes: 1.2 % of its length, under 1 deg per 50 px on a 16 mm scratch). A
    scratch that meets a deep groove at a shallow angle was followed along the groove to
    the frame's border, where ``_run_on_fades`` does not read (station frame 110048: a
    0.85 mm scratch 12 deg off the hatch, its end turning 8 deg onto a groove at 30 deg
    within 60 px, reported 8.3 mm long)."""
    t = _end_tangent(line, k, 30.0)
    if not np.any(t) or on.shape[0] < 3:
        return False
    to_end = _to_end(on)
    body = on[to_end[0] - to_end >= RUN_ON_SETTLE_PX]
    if body.shape[0] < 3 or to_end[0] - RUN_ON_SETTLE_PX < RUN_ON_BODY_PX:
        return False
    # the body's axis, and its RMS distance from it (the covariance's lesser eigenvalue)
    _, _, axis, cov = _weighted_pca(body[:, 0], body[:, 1], np.ones(body.shape[0]))
    if float(np.sqrt(max(np.linalg.eigvalsh(cov)[0], 0.0))) > RUN_ON_STRAIGHT_PX:
        return False
    body_deg = float(np.rad2deg(axis) % 180.0)
    end_deg = float(np.rad2deg(np.arctan2(t[1], t[0])) % 180.0)
    return any(_circ_diff_deg(body_deg, g) <= RUN_ON_HATCH_DEG
               and _circ_diff_deg(end_deg, g) >= cfg.groove_alignment_deg for g in angles_deg)


def _run_on_grooves_only(residual: np.ndarray, line: np.ndarray, on: np.ndarray, angles_deg,
                         cfg: DefectConfig) -> bool:
    """Whether a run on ``on`` (frame px, from the scratch's end outwards) is the grooves'
    darkness alone: its chord lies off the hatch (``cfg.groove_alignment_deg`` or more
    from each family), where the wall model's grooves (their means along their own
    lines) cannot take a furrow in, and the model's residual (``residual``, half
    resolution, 1 px-smoothed) along it holds less than ``cfg.track_residual_share`` of
    the residual along the scratch's own line (medians). Along the hatch the residual
    says nothing: there the grooves' means take a furrow in, which is what the run on is
    for (``_track_on``). Points in the holes' zones (residual 0) are not read; fewer than
    5 read on either part: no judgement."""
    chord = on[-1] - on[0]
    if float(np.hypot(*chord)) < 4.0 or not len(angles_deg):
        return False
    deg = float(np.rad2deg(np.arctan2(chord[1], chord[0])) % 180.0)
    if _near_hatch(deg, angles_deg, cfg) is not None:
        return False

    def along(pts: np.ndarray) -> np.ndarray:
        q = (np.asarray(pts, float) - 0.5) / 2.0  # half resolution: pixel i covers 2i and 2i + 1
        v = map_coordinates(residual, [q[:, 1], q[:, 0]], order=1, mode="constant", cval=0.0)
        return v[v != 0.0]

    body, run = along(_dense(line)), along(_dense(on)[1:])
    if body.size < 5 or run.size < 5:
        return False
    own = float(np.median(body))
    return bool(own > 0.0 and float(np.median(run)) < cfg.track_residual_share * own)


def _track_scratches(img: np.ndarray, level: np.ndarray, examined: list["_Examined"],
                     cfg: DefectConfig, angles_deg=(), residual: np.ndarray | None = None) -> list["_Examined"]:
    """Each scratch's ends followed where the furrow runs on (``_track_on``): its centre
    line, length, place and direction take the stretch in, and it is ``partial`` when
    the stretch reaches the frame's border. A stretch that fades at its far end is a
    groove the scratch meets, not taken (``_run_on_fades``), nor one that turns onto the
    hatch and runs straight along it (``_turns_onto_hatch``), nor one off the hatch that
    the wall model's residual (``residual``, half resolution; smoothed over 1 px here, on
    the first run on to judge) does not carry (``_run_on_grooves_only``); and an end that the
    measurement read where a groove's stretch begins (``_groove_beyond_end``,
    ``_shelf_beyond``) is not followed at all: the raw darkness beyond it is the groove's
    (the twin's 2088002: its end read right, a run on of 21 px straight on through the
    groove's band to a 6.8 px step that passes as a cut put it 0.11 mm off)."""
    out = []
    smooth: list[np.ndarray] = []  # the residual smoothed, once, when a run on needs it

    def grooves_only(line: np.ndarray, on: np.ndarray) -> bool:
        if residual is None:
            return False
        if not smooth:
            smooth.append(cv2.GaussianBlur(residual, (0, 0), 1.0))
        return _run_on_grooves_only(smooth[0], line, on, angles_deg, cfg)

    for ex in examined:
        d = ex.defect
        if d is None or d.kind != "scratch" or ex.line is None or len(ex.line) < 2:
            out.append(ex)
            continue
        blur = float(np.clip(ex.blur or BLUR_PRIOR_PX[0], 0.7, 2.8))
        line = ex.line
        partial = d.partial
        grown = False
        for k in (0, -1):
            if ex.groove_ends[0 if k == 0 else 1]:
                continue  # beyond it the raw darkness is the groove's (``_measure_scratch``)
            on = _track_on(img, level, line, k, d.width_px, blur, cfg)
            if on is None or _run_on_fades(img, level, on, d.width_px, blur, cfg) \
                    or _turns_onto_hatch(line, k, on, angles_deg, cfg) \
                    or grooves_only(line, on):
                continue
            grown = True
            line = np.vstack([on[::-1], line[1:]]) if k == 0 else np.vstack([line[:-1], on])
            if _at_frame_border(on[-1], img.shape):
                partial = True
        if not grown:
            out.append(ex)
            continue
        along, x, y, angle = _line_place(line)
        length = d.length_px + along - _line_place(ex.line)[0]
        nd = Defect(**{**asdict(d), "x_px": x, "y_px": y, "length_px": length, "angle_deg": angle,
                       "partial": bool(partial)})
        out.append(_Examined(nd, ex.region, ex.box, ex.cover, line, ex.blur, ex.groove_ends))
    # a piece whose centre line the other's followed stretch now runs along is the same
    # furrow twice: the shorter goes
    items = [ex for ex in out if ex.defect is not None and ex.defect.kind == "scratch" and ex.line is not None]
    drop = set()
    for a in items:
        for b in items:
            if a is b or id(b) in drop or b.defect.length_px < a.defect.length_px or \
                    (b.defect.length_px == a.defect.length_px and id(a) < id(b)):
                continue
            tol = 0.5 * max(a.defect.width_px, b.defect.width_px) + 3.0
            dense = _dense(a.line)
            near = np.min(np.hypot(dense[:, None, 0] - b.line[None, :, 0], dense[:, None, 1] - b.line[None, :, 1]),
                          axis=1) if len(dense) * len(b.line) <= 4_000_000 else np.full(len(dense), np.inf)
            if float(np.mean(near <= tol + _spacing(b.line))) >= 0.8:
                drop.add(id(a))
                break
    return [ex for ex in out if id(ex) not in drop]


def _line_place(line: np.ndarray) -> tuple[float, float, float, float]:
    """A centre line's length along it, its middle (x, y: halfway along) and its chord's
    direction (deg, 0-180): (length, x, y, angle)."""
    acc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(line, axis=0).T))])
    half = 0.5 * acc[-1]
    chord = line[-1] - line[0]
    return (float(acc[-1]), float(np.interp(half, acc, line[:, 0])), float(np.interp(half, acc, line[:, 1])),
            float(np.degrees(np.arctan2(chord[1], chord[0])) % 180.0))


def _to_end(pts: np.ndarray) -> np.ndarray:
    """Each polyline point's distance along it to its last point (px)."""
    seg = np.hypot(*np.diff(pts, axis=0).T)
    return np.concatenate([[0.0], np.cumsum(seg[::-1])])[::-1]


def _line_points(line: np.ndarray, step: float = 10.0) -> tuple[tuple[float, float], ...]:
    """A centre line as points every ~``step`` px, its two ends kept."""
    pts = _dense(line, step) if len(line) > 1 else line
    return tuple((round(float(x), 2), round(float(y), 2)) for x, y in pts)


def _spacing(line: np.ndarray) -> float:
    """Half the largest step between a polyline's points (px)."""
    return 0.5 * float(np.max(np.hypot(*np.diff(line, axis=0).T))) if len(line) > 1 else 0.0


def _dense(line: np.ndarray, step: float = 2.0) -> np.ndarray:
    """A polyline's points every ~``step`` px along it."""
    seg = np.hypot(*np.diff(line, axis=0).T)
    acc = np.concatenate([[0.0], np.cumsum(seg)])
    at = np.linspace(0.0, acc[-1], max(int(acc[-1] / step), 1) + 1)
    return np.column_stack([np.interp(at, acc, line[:, 0]), np.interp(at, acc, line[:, 1])])


def _join_scratch_pieces(img: np.ndarray, level: np.ndarray, examined: list["_Examined"],
                         cfg: DefectConfig) -> list["_Examined"]:
    """Scratches of one frame that are pieces of one furrow (``_scratch_gap``) as one:
    its centre line the pieces' and the gap's path, its length theirs along it, its
    place that line's middle, its width the pieces' length-weighted mean."""
    while True:
        items = [ex for ex in examined if ex.defect is not None and ex.defect.kind == "scratch"
                 and ex.line is not None and len(ex.line) >= 2]
        best = None
        for i, a in enumerate(items):
            for b in items[i + 1:]:
                r = _scratch_gap(img, level, a, b, cfg)
                if r is not None and (best is None or r[0] < best[0]):
                    best = (r[0], a, b, r)
        if best is None:
            return examined
        _, a, b, (g, ka, kb, path) = best
        la = a.line if ka == -1 else a.line[::-1]
        lb = b.line if kb == 0 else b.line[::-1]
        if g < 0:
            # overlapping: b's line from where it passes a's end on
            ta = _end_tangent(a.line, ka)
            lb = lb[(lb - la[-1]) @ ta > 0.0]
            line = np.vstack([la, lb])
        else:
            line = np.vstack([la, path[1:-1], lb])
        da, db = a.defect, b.defect
        length, x, y, angle = _line_place(line)
        wa, wb = da.length_px, db.length_px
        width = (da.width_px * wa + db.width_px * wb) / (wa + wb)
        width_u = (da.width_u_px * wa + db.width_u_px * wb) / (wa + wb)
        sig = float(np.hypot(da.significance, db.significance))
        d = Defect("scratch", x, y, length, width, _confidence(sig, cfg.min_significance), angle,
                   float(np.hypot(da.length_u_px, db.length_u_px) / np.sqrt(2.0)), width_u, sig,
                   bool(da.partial or db.partial))
        x0, y0 = min(a.box[0], b.box[0]), min(a.box[1], b.box[1])
        x1, y1 = max(a.box[2], b.box[2]), max(a.box[3], b.box[3])
        region = np.zeros((y1 - y0, x1 - x0), bool)
        cover = np.zeros_like(region)
        for ex in (a, b):
            bx0, by0, bx1, by1 = ex.box
            region[by0 - y0:by1 - y0, bx0 - x0:bx1 - x0] |= ex.region
            if ex.cover is not None:
                cover[by0 - y0:by1 - y0, bx0 - x0:bx1 - x0] |= ex.cover
        joined = _Examined(d, region, (x0, y0, x1, y1), cover, line, float(np.mean([a.blur or 0, b.blur or 0])))
        examined = [ex for ex in examined if ex is not a and ex is not b] + [joined]


def _examine(img: np.ndarray, box, seed: np.ndarray, zone: np.ndarray, angles_deg, wall_level: np.ndarray,
             cfg: DefectConfig, blur_hint: float | None, max_width_px: float, excl: np.ndarray | None = None,
             confine: tuple[float, float, float, float] | None = None, others: np.ndarray | None = None) -> _Examined:
    """One candidate at full resolution: the local wall model, its region, its kind,
    its measurement and the tests it must pass.

    A scratch whose end the patch cuts (its strip runs out of the patch within reach
    of the end) is examined again in a patch grown along it: the patch is the box of
    the candidates that were found, and a long scratch near a groove direction breaks
    into pieces that are not joined (the twin's frames: a 161 px scratch 10 deg off the
    hatch measured as three overlapping scratches of 73, 99 and 129 px). So is a piece of
    a scratch along a groove direction that ends square at one end and runs on at the
    other (``_square_end``): the wall model's grooves along its line took the rest of it
    in, and the line is left out of them the second time. What a scratch covers, its
    centre line and blur, is claimed with its region, so that its other pieces are not
    measured again.

    ``excl``: what the first wall model leaves out besides the seed (a crossing furrow);
    ``confine``: a line the region keeps to (one furrow of several, ``_furrows``);
    ``others``: what the defects measured so far cover over the frame, which the wall
    model leaves out in every patch."""
    hh, ww = img.shape

    def beside(b) -> np.ndarray:
        return others[b[1]:b[3], b[0]:b[2]] if others is not None else False

    excl = (seed if excl is None else (seed | excl)) | beside(box)
    ex = None
    box0 = tuple(box)
    for attempt in range(3):
        again, m, kind = _examine_once(img, box, seed, excl, zone, angles_deg, wall_level, cfg, blur_hint,
                                       max_width_px, confine, line_out=attempt > 0)
        if ex is not None and again.defect is None and not (box0[0] == 0 or box0[1] == 0 or box0[2] == ww
                                                             or box0[3] == hh):
            # the grown patch lost it (bench frames: short scratches of 0.14-0.17 mm, taken for
            # a mark there): the cut one stands; but at the frame's border, where the first
            # patch had half a wall model round it, the grown patch's verdict (twin frames:
            # the hatch's residue at the border, 7 deg off a groove, stood as a 0.32 mm scratch)
            break
        ex = again
        if kind != "scratch" or m is None or not (m.get("cut") or m.get("runs_on")) or attempt == 2:
            break
        # the ends (frame px), each moved out by as much again as the scratch is long
        (xa, ya), (xb, yb) = ((m["line"][0][i] + box[0], m["line"][1][i] + box[1]) for i in (0, -1))
        reach = max(60.0, m["length"])
        ux, uy = (xb - xa) / max(np.hypot(xb - xa, yb - ya), 1e-6), (yb - ya) / max(np.hypot(xb - xa, yb - ya), 1e-6)
        pa, pb = (xa - reach * ux, ya - reach * uy), (xb + reach * ux, yb + reach * uy)
        pad = 20
        new = (int(max(min(box[0], min(pa[0], pb[0]) - pad), 0)), int(max(min(box[1], min(pa[1], pb[1]) - pad), 0)),
               int(min(max(box[2], max(pa[0], pb[0]) + pad), ww)), int(min(max(box[3], max(pa[1], pb[1]) + pad), hh)))
        # no larger than the frame's quarter each way: a bound on the time, far beyond a scratch
        if (new == tuple(box) and not m.get("runs_on")) or (new[2] - new[0]) * (new[3] - new[1]) > ww * hh / 4:
            break
        shape = (new[3] - new[1], new[2] - new[0])
        grown_seed = np.zeros(shape, bool)
        grown_seed[box[1] - new[1]:box[3] - new[1], box[0] - new[0]:box[2] - new[0]] = seed | ex.region
        # the wall model leaves out the scratch's line over the reach it may continue
        line_mask = np.zeros(shape, np.uint8)
        cv2.line(line_mask, (int(round(pa[0] - new[0])), int(round(pa[1] - new[1]))),
                 (int(round(pb[0] - new[0])), int(round(pb[1] - new[1]))), 1, int(2 * m["half_band"] + 1))
        seed, excl, box = grown_seed, grown_seed | line_mask.astype(bool) | beside(new), new
    return ex


def _examine_once(img: np.ndarray, box, seed: np.ndarray, excl: np.ndarray, zone: np.ndarray, angles_deg,
                  wall_level: np.ndarray, cfg: DefectConfig, blur_hint: float | None, max_width_px: float,
                  confine: tuple[float, float, float, float] | None = None, line_out: bool = False):
    """``_examine`` in one patch: (the examined candidate, its measurement, its kind).
    ``excl``: what the local wall model leaves out (the seed, or more); ``confine``: the
    line the region keeps to (``_examine``); ``line_out``: ``excl`` holds the mark's line
    (an examination again along it)."""
    patch = _local_patch(img, box, excl, zone, angles_deg, wall_level)
    x0, y0, x1, y1 = box
    empty = np.zeros((y1 - y0, x1 - x0), bool)
    if patch is None:
        return _Examined(None, empty, tuple(box)), None, None
    rs = cv2.GaussianBlur(patch.residual, (0, 0), 1.0)
    use = ~patch.excluded
    noise_s = max(_mad_sigma(rs[use]), NOISE_FLOOR)
    peak = float(rs[seed].max()) if seed.any() else 0.0
    # grown down to the noise, or to a share of the peak for a dark mark: a pore must not
    # run out along a groove's faint residue that touches it
    grow = (rs > max(cfg.grow_k * noise_s, cfg.grow_share * peak)) & ~zone[y0:y1, x0:x1]
    if confine is not None:
        grow &= _band(grow.shape, (x0, y0), confine, cfg.furrow_half_band_px)
    n_lab, labels = cv2.connectedComponents(grow.astype(np.uint8), connectivity=8)
    hit = np.unique(labels[seed & grow])
    hit = hit[hit > 0]
    if hit.size:
        region = np.isin(labels, hit)
    else:
        # a faint scratch found by the line response may leave no pixel above the growth
        # threshold at full resolution: the seed's darker half is its region
        region = seed & (rs > 0) & ~zone[y0:y1, x0:x1]
        if region.sum() < 8:
            return _Examined(None, empty, tuple(box)), None, None
    def at_border_of(reg: np.ndarray) -> bool:
        touches = reg[0, :].any() or reg[-1, :].any() or reg[:, 0].any() or reg[:, -1].any()
        return bool(touches and (x0 == 0 or y0 == 0 or x1 == img.shape[1] or y1 == img.shape[0]))

    yy, xx = np.nonzero(region)
    wts = np.clip(rs[region], 1e-6, None)
    mx_, my_, ang, ext_l, ext_w = _extents(xx, yy, wts)
    ca, sa = np.cos(ang), np.sin(ang)
    elongated = ext_l >= cfg.scratch_elongation * ext_w and ext_l >= 12.0
    if elongated and _along_hatch(float(np.rad2deg(ang) % 180.0), ext_l, angles_deg, cfg):
        # along the hatch: most such marks are the grooves' residue, and measuring each as a
        # scratch cost the twin's frames 1.26x their time; the ends' test on the region's
        # own axis first (loosely: a piece that runs on may be a longer scratch's)
        along = (xx - mx_) * ca + (yy - my_) * sa
        ends = np.array([along.min(), along.max()])
        blur0 = float(blur_hint) if blur_hint is not None else BLUR_PRIOR_PX[0]
        pre = dict(line=(mx_ + ends * ca, my_ + ends * sa), blur=blur0, width=max(ext_w - 2.0 * blur0, 1.0))
        if not any(_square_end(img, wall_level, x0, y0, pre, cfg, angles_deg, zone)):
            # a piece of groove the wall model left, or a pore with such a piece attached
            return _core_pore(patch, rs, seed, region, zone[y0:y1, x0:x1], peak, box, at_border_of(region),
                              angles_deg, cfg, max_width_px, blur_hint)

    def as_pore(reg: np.ndarray, allow_scratch: bool = True):
        # a pore is one cavity: of a region in parts, the part round the peak when it
        # passes as a pore alone (``_peak_part``); else the whole region, as it stood
        part, beside = _peak_part(reg, rs, seed)
        if beside is not None:
            mp = _measure_pore(patch, part, cfg, blur_hint=blur_hint, beside=beside)
            if mp is not None and not mp.get("scratch") and \
                    _accept(mp, "pore", box, at_border_of(part), angles_deg, cfg, max_width_px) is not None:
                return part, mp
        return reg, _measure_pore(patch, reg, cfg, allow_scratch=allow_scratch, blur_hint=blur_hint)

    if elongated:
        m = _measure_scratch(patch, region, blur_hint, angles_deg, cfg.groove_alignment_deg)
    else:
        region, m = as_pore(region)
    if m is not None and m.get("scratch"):
        elongated = True
        m = _measure_scratch(patch, region, blur_hint, angles_deg, cfg.groove_alignment_deg)
    kind = "scratch" if elongated else "pore"
    if kind == "scratch" and m is not None and m["length"] < cfg.scratch_elongation * m["width"]:
        region, m = as_pore(region, allow_scratch=False)  # short, broad
        kind = "pore"
    at_border = at_border_of(region)
    if kind == "scratch" and m is not None:
        m["along_share"] = _along_share(rs, region, m["angle"], angles_deg)
        m["along_hatch"] = _along_hatch(m["angle"], m["length"], angles_deg, cfg)
        if _near_hatch(m["angle"], angles_deg, cfg) is not None:
            # near the hatch: along it, a scratch if it ends in cuts (``_accept``); one cut end
            # and the other running on is a piece of a longer scratch (the wall model's
            # grooves along its line took the rest in), measured again along it (``_examine``),
            # as is a piece of one that crosses the lines (``_along_hatch``)
            m["square_end"], m["runs_on"] = _square_end(img, wall_level, x0, y0, m, cfg, angles_deg, zone)
            if line_out and not m["square_end"]:
                # measured again with its line left out of the grooves (``_examine``): its ends
                # read on the residual too, where a groove it ran into is modelled from beside
                # its line rather than read as the mark running on (dev frames within 7.5 deg
                # of the hatch: 2 more of 114 scratches; none of the clean frames' pieces)
                # the holes' zone is not read there (NaN: an end it meets is not read, as one
                # the frame cuts is not): the residual is 0 in it, and a groove's stretch that
                # runs into a rim read as cut there (wide clean frame 1096029: a 0.63 mm
                # "scratch" between a crossing and a hole)
                res_img = np.where(patch.zone, np.nan, 1.0 - patch.residual).astype(np.float32)
                m["square_end"] = _square_end(res_img, np.ones_like(res_img), 0, 0, m, cfg, angles_deg)[0]
    defect = _accept(m, kind, box, at_border, angles_deg, cfg, max_width_px)
    if defect is None:
        core = _core_pore(patch, rs, seed, region, zone[y0:y1, x0:x1], peak, box, at_border, angles_deg, cfg,
                          max_width_px, blur_hint)
        if core[0].defect is not None:
            return core
        # else as it stood: a cut scratch that failed is examined again in a grown patch
    cover = None
    if defect is not None and kind == "scratch":
        # what the scratch covers: its centre line, its half width and blur either side
        lines = np.zeros(region.shape, np.uint8)
        pts = np.round(np.column_stack(m["line"])).astype(np.int32)
        cv2.polylines(lines, [pts], False, 1, int(2 * m["half_band"] + 1))
        cover = lines.astype(bool)
        line = np.column_stack(m["line"]) + np.array([x0, y0], float)
        return _Examined(defect, region, tuple(box), cover, line, float(m["blur"]),
                         m.get("groove_ends", (False, False))), m, kind
    return _Examined(defect, region, tuple(box), cover), m, kind


def _round_peak(mask: np.ndarray, rs: np.ndarray, seed: np.ndarray) -> tuple[np.ndarray, int]:
    """The connected part (8-connected) of ``mask`` round the seed's darkest pixel in it
    (the seed must meet the mask), and how many parts the mask has."""
    n_lab, labels = cv2.connectedComponents(mask.astype(np.uint8), connectivity=8)
    at = np.unravel_index(int(np.argmax(np.where(seed & mask, rs, -np.inf))), rs.shape)
    return labels == labels[at], n_lab - 1


def _extents(xx: np.ndarray, yy: np.ndarray, wts: np.ndarray) -> tuple[float, float, float, float, float]:
    """Pixels' weighted centre, principal direction (rad) and their extents along it and
    across it (px, end pixels included): (mx, my, angle, along, across)."""
    mx, my, ang, _ = _weighted_pca(xx.astype(float), yy.astype(float), wts)
    ca, sa = np.cos(ang), np.sin(ang)
    return mx, my, ang, float(np.ptp(xx * ca + yy * sa)) + 1.0, float(np.ptp(-xx * sa + yy * ca)) + 1.0


def _peak_part(region: np.ndarray, rs: np.ndarray, seed: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """Of a region in several parts, the part round the seed's darkest pixel, and the
    rest (None: one part): a pore is one cavity. A deep groove's stretch in line with a
    pore is a candidate grouped with it (``_group_collinear``, which joins a faint
    scratch's pieces), and the pore was measured with the stretch beside it (a 30 px pore
    20 px from a stretch's end read 42 px, its place 8 px off; the surface bench's seed
    24203 lost a 0.31 mm pore so, read with the stretch as one broad faint mark)."""
    if not (seed & region).any():
        return region, None
    part, parts = _round_peak(region, rs, seed)
    if parts <= 1:
        return region, None
    return part, region & ~part


def _core_pore(patch: _Patch, rs: np.ndarray, seed: np.ndarray, region: np.ndarray, zone: np.ndarray,
               peak: float, box, at_border: bool, angles_deg, cfg: DefectConfig, max_width_px: float,
               blur_hint: float | None):
    """A candidate whose region was no defect (``_examine_once``), looked at again for a
    pore in it: the region's part darker than ``cfg.core_share`` of its peak, round the
    peak. A deep groove's stretch that the frame's wall model does not hold (a groove
    that fades out along its line) joins a pore beside it in one region, and the pore
    was measured with it as one broad, faint mark or a piece of groove, and lost (the
    surface bench's seed 24203: a 0.31 mm pore of contrast ~0.6 at a groove's end, in a
    region three times its size). Only a compact core smaller than the region, measured
    as a pore and passing a pore's tests, stands, and only a dark one away from the
    frame's border (``cfg.core_min_peak``); else the candidate is nothing, as before.
    Returns what ``_examine_once`` does."""
    none = _Examined(None, region, tuple(box)), None, None
    if peak < cfg.core_min_peak or at_border or not seed.any():
        return none
    dark = (rs > cfg.core_share * peak) & region & ~zone
    if not (seed & dark).any():
        return none
    core, _ = _round_peak(dark, rs, seed)
    n = int(core.sum())
    if n < 8 or n > cfg.core_max_share * int(region.sum()):
        return none  # no core, or the region is its core: measured as it stood
    yy, xx = np.nonzero(core)
    *_, ext_l, ext_w = _extents(xx, yy, np.clip(rs[core], 1e-6, None))
    if ext_l >= cfg.scratch_elongation * ext_w:
        return none  # a line: the furrows' and the scratches' business, not a pore's
    m = _measure_pore(patch, core, cfg, allow_scratch=False, blur_hint=blur_hint)
    defect = _accept(m, "pore", box, at_border, angles_deg, cfg, max_width_px)
    if defect is None:
        return none
    return _Examined(defect, core, tuple(box)), m, "pore"


def _end_steps(img: np.ndarray, level: np.ndarray, x0: int, y0: int, m: dict,
               ends: tuple[int, ...] = (0, -1), other_deg: float | None = None,
               unread: np.ndarray | None = None) -> list[tuple[float, float]]:
    """How a mark measured as a line (``m``: its centre line, width and blur; patch offset
    ``x0``, ``y0``) steps down at each of its ``ends`` read (0: the first, -1: the last):
    (the step's width, px; its height as a share of the darkness inside). The raw
    relative darkness ``1 - img / level`` (the grooves kept) is read along the centre
    line's chord from up to 30 px inside the end to 30 px beyond it, the mean across the
    mark's core less that of its 4 px flanks (the other family's grooves cross both
    alike), and fitted as a blurred step (height, place, width, offset). An end the frame
    cuts is not read (no entry); a mark no darker inside than beyond reads (inf, 0).

    The step is fitted over its last ``_END_FIT_INSIDE_PX`` inside; the darkness inside
    it is measured against is the median over all of the inside read.

    ``other_deg``: the direction of the groove family that crosses a mark lying along the
    other (``_crossing_family``). Its grooves cross the core and the flanks at places
    along the line that differ by the flanks' offset over the tangent of the crossing
    angle (5-10 px at a 44 deg crossing), so core less flanks read a crossing groove as a
    peak beside a dip: at a deep groove's stretch that ended where a groove of the other
    family crossed it, a step 0.5-1.1 px wide of 0.9-1.1 of the darkness inside, sharper
    than the frame's blur allows an edge (wide clean frames 1097042, 1097051 at a 22 deg
    hatch: 1.14 and 0.84 mm "scratches"). That family's darkness is read along its own
    lines beside the mark (beyond the core, up to ``_CROSSING_READ_PX`` along them) and
    taken from every sample first, each sample by the line through it; ``unread`` (bool,
    the frame's shape, offset as ``img``): where those lines are not read (the holes'
    zone: a hole 20 px along them would read as the family's darkness)."""
    lx, ly = (np.asarray(v, float) for v in m["line"])
    if lx.size < 2:
        return []
    px, py = lx + x0, ly + y0
    length = float(np.hypot(px[-1] - px[0], py[-1] - py[0]))
    if length < 4.0:
        return []
    blur = float(np.clip(m["blur"], 0.7, 2.8))
    core = max(m["width"] / 2.0 + blur, 1.5)
    off = np.arange(-(core + 6.0), core + 6.0 + 0.25, 0.5)
    in_core, in_flank = np.abs(off) <= core, np.abs(off) >= core + 2.0
    inner = min(30.0, length / 2.0)
    t = np.arange(-inner, 30.0 + 0.25, 0.5)  # along the line, outwards from the end
    darkness = None  # the crossing family's lines' reader, made once when needed
    hh, ww = img.shape
    steps = []  # (width, share of the darkness) of each end read
    # along the chord: the centre line's last few px bend as its polynomial likes, and a
    # groove's piece read on past its end along them left the groove within 30 px (a
    # "square end": the twin's frames, 9 false scratches in 50 with this test's first form)
    cux, cuy = (px[-1] - px[0]) / length, (py[-1] - py[0]) / length
    for k, ux, uy in ((0, -cux, -cuy), (-1, cux, cuy)):
        if k not in ends:
            continue
        mx = px[k] + t[None, :] * ux - off[:, None] * uy
        my = py[k] + t[None, :] * uy + off[:, None] * ux
        bx0, by0 = int(max(np.floor(mx.min()) - 1, 0)), int(max(np.floor(my.min()) - 1, 0))
        bx1, by1 = int(min(np.ceil(mx.max()) + 2, ww)), int(min(np.ceil(my.max()) + 2, hh))
        if bx1 - bx0 < 2 or by1 - by0 < 2:
            continue
        dark = (1.0 - img[by0:by1, bx0:bx1].astype(np.float32)
                / np.maximum(level[by0:by1, bx0:bx1], 1.0)).astype(np.float32)
        st = cv2.remap(dark, (mx - bx0).astype(np.float32), (my - by0).astype(np.float32), cv2.INTER_LINEAR,
                       borderMode=cv2.BORDER_CONSTANT, borderValue=float("nan"))
        s_b = np.zeros(0)
        if other_deg is not None:
            b = np.array([np.cos(np.deg2rad(other_deg)), np.sin(np.deg2rad(other_deg))])
            bn = float(b[0] * -uy + b[1] * ux)  # across the mark per px along the other family
            slope = float(b[0] * ux + b[1] * uy) / bn  # along the mark per px across it
            s_b = np.arange(-_CROSSING_READ_PX, _CROSSING_READ_PX + 0.5, 1.0)
            s_b = s_b[np.abs(s_b * bn) >= core + 2.0]  # beside the mark, off its core
        if s_b.size:
            t_b = np.arange(t[0] - (core + 7.0) * abs(slope), t[-1] + (core + 7.0) * abs(slope) + 0.5, 0.5)
            if darkness is None:
                darkness = _darkness_reader(img, level, np.zeros(img.shape, bool) if unread is None else unread)
            sb = darkness(np.stack([px[k] + t_b[None, :] * ux + s_b[:, None] * b[0],
                                    py[k] + t_b[None, :] * uy + s_b[:, None] * b[1]], axis=-1))
            have = np.isfinite(sb).sum(axis=0)
            if (have >= 4).sum() >= 8:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", RuntimeWarning)  # a line with nothing read
                    prof = np.where(have >= 4, np.nanmedian(sb, axis=0), np.nan)
                ok_b = np.isfinite(prof)
                # each sample less the other family's darkness on its line, where the line
                # meets the mark's centre line (the constant the lines pick up beside the
                # mark cancels in core less flanks)
                st = st - np.interp(t[None, :] - off[:, None] * slope, t_b[ok_b], prof[ok_b],
                                    left=np.nan, right=np.nan)
        ok = np.isfinite(st).all(axis=0)
        if ok.sum() < 20 or t[ok].max() < 12.0:
            continue  # the frame cuts this end
        a = st[in_core][:, ok].mean(axis=0) - st[in_flank][:, ok].mean(axis=0)
        tt = t[ok]
        inside, beyond = tt < -3.0 * blur, tt > 3.0 * blur
        if inside.sum() < 4:
            continue
        h_in = float(np.median(a[inside]))
        if h_in <= 0.0:
            steps.append((np.inf, 0.0))  # no darker inside than beyond: no end of a dark mark
            continue
        h_out = float(np.median(a[beyond])) if beyond.sum() >= 4 else 0.0
        # the step fitted over its last ``_END_FIT_INSIDE_PX`` inside (the darkness inside,
        # the share's reference, over all 30): a scratch's darkness varies along it (it
        # tapers, or bends off the chord), and over 30 px a plain step read a tapering
        # scratch's cut end as well as a step as wide as the taper, at the same cost to
        # 0.2 % (a station frame's 1.46 mm scratch 0.3 deg off the hatch, 542006: 0.7 or
        # 12 px as the data moved by a few thousandths)
        near = tt >= -_END_FIT_INSIDE_PX
        tn = tt[near]
        fit = _gauss_newton(lambda q: q[0] * ndtr(-(tn - q[1]) / q[2]) + q[3],
                            np.array([max(h_in - h_out, 0.01), 0.0, 2.0, h_out]), a[near],
                            np.array([-1.0, -12.0, 0.4, -1.0]), np.array([2.0, 12.0, 30.0, 1.0]), iterations=25)
        steps.append((float(fit.x[2]), float(fit.x[0]) / h_in))
    return steps


#: how far along the crossing family's lines their darkness is read either side of a
#: mark's centre line (px; ``_end_steps``)
_CROSSING_READ_PX = 24.0
#: how far inside a mark's end its step is fitted (px; ``_end_steps``)
_END_FIT_INSIDE_PX = 15.0


def _crossing_family(line: tuple, angles_deg, cfg: DefectConfig) -> float | None:
    """The groove family that crosses a mark lying along the other (``line``: its centre
    line's x and y), at ``cfg.crossing_min_deg`` or more; None for a mark along neither
    family (both cross it) or where the families are too near to part."""
    lx, ly = (np.asarray(v, float) for v in line)
    if lx.size < 2 or len(angles_deg) < 2:
        return None
    mark = float(np.rad2deg(np.arctan2(ly[-1] - ly[0], lx[-1] - lx[0])) % 180.0)
    if _near_hatch(mark, angles_deg, cfg) is None:
        return None
    far = max(angles_deg, key=lambda g: _circ_diff_deg(mark, g))
    return float(far) if _circ_diff_deg(mark, far) >= cfg.crossing_min_deg else None


def _square_end(img: np.ndarray, level: np.ndarray, x0: int, y0: int, m: dict,
                cfg: DefectConfig, angles_deg=(), unread: np.ndarray | None = None) -> tuple[bool, bool]:
    """Whether a scratch measured along a groove direction (``m``, patch offset ``x0``,
    ``y0``) ends in a cut at both ends, as a furrow does, rather than fading as a groove
    does, each end read on the raw darkness (the grooves kept: the wall model's grooves
    along such a line may have taken the mark in) by ``_end_steps``. Returns (square,
    runs on): whether both ends are read, both step by at least
    ``cfg.square_end_min_height`` of the darkness inside, one of them square (no wider
    than ``cfg.square_end_max_width_px``, or 2.5 of the mark's blur) and the other no
    wider than ``cfg.square_end_other_max_width_px``; and whether one end is square while
    another runs on at more than ``cfg.square_end_max_run_on`` of the darkness (a piece
    of a longer mark). ``angles_deg``: the hatch's directions (the family crossing the
    mark is taken out of its ends' read, ``unread`` not read: ``_end_steps``)."""
    steps = _end_steps(img, level, x0, y0, m, other_deg=_crossing_family(m["line"], angles_deg, cfg),
                       unread=unread)
    max_width = max(cfg.square_end_max_width_px, 2.5 * float(np.clip(m["blur"], 0.7, 2.8)))
    square = [w <= max_width and h >= cfg.square_end_min_height for w, h in steps]
    ends = [w <= max(cfg.square_end_other_max_width_px, max_width) and h >= cfg.square_end_min_height
            for w, h in steps]
    runs_on = [h < 1.0 - cfg.square_end_max_run_on for _, h in steps]
    # both ends: one the frame cuts leaves a groove's piece at the border as square as a
    # scratch's (a fresh twin frame, 2080043); the scan's overlap sees such a scratch whole
    return len(steps) == 2 and any(square) and all(ends), any(square) and any(runs_on)


def _along_share(rs: np.ndarray, region: np.ndarray, angle_deg: float, angles_deg, sigma_px: float = 2.0,
                 grow_px: int = 3) -> float:
    """The share of the oriented gradient energy over ``region`` (grown by ``grow_px``, to
    take in the mark's flanks) whose local line direction is that of the scratch
    (``angle_deg``): nearer it than any groove direction (``angles_deg``) and within 10
    deg.  The local direction is the structure tensor's (the residual's gradient products
    over a Gaussian of ``sigma_px``), its weight the tensor's anisotropy (the flanks of a
    line carry it; flat noise little).  One straight furrow: ~0.9; deep grooves that
    cross, whose residue is a V or an X along the hatch: ~0.1-0.25."""
    gx = cv2.Sobel(rs, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(rs, cv2.CV_32F, 0, 1, ksize=3)
    jxx = cv2.GaussianBlur(gx * gx, (0, 0), sigma_px)
    jyy = cv2.GaussianBlur(gy * gy, (0, 0), sigma_px)
    jxy = cv2.GaussianBlur(gx * gy, (0, 0), sigma_px)
    area = cv2.dilate(region.astype(np.uint8), np.ones((2 * grow_px + 1,) * 2, np.uint8)).astype(bool)
    dxy, dd = 2.0 * jxy[area], (jxx - jyy)[area]
    weight = np.sqrt(dd * dd + dxy * dxy)
    total = float(weight.sum())
    if total <= 0.0:
        return 0.0
    line = (0.5 * np.degrees(np.arctan2(dxy, dd)) + 90.0) % 180.0  # the gradient's normal

    to_groove = (np.min([_circ_diff_deg(line, float(g)) for g in angles_deg], axis=0) if len(angles_deg)
                 else np.full(line.shape, 180.0))
    along = _circ_diff_deg(line, float(angle_deg)) < np.minimum(to_groove, 10.0)
    return float(weight[along].sum()) / total


def _accept(m: dict | None, kind: str, box, at_border: bool, angles_deg, cfg: DefectConfig,
            max_width_px: float) -> Defect | None:
    """The tests a measured mark must pass to be a defect, and the defect."""
    if m is None:
        return None
    # a mark cut by the frame's border has half the wall model round it (the grooves'
    # means and the level end there): twice the significance (dev and bench frames:
    # small "pores" in the frame's corners at 8.8-10.5)
    if m["significance"] < cfg.min_significance * (2.0 if at_border else 1.0):
        return None
    if m["mean_darkness"] < cfg.min_mean_darkness:
        return None
    if kind == "pore" and m["length"] >= cfg.broad_pore_px and m["mean_darkness"] < cfg.min_broad_pore_darkness:
        return None  # broad and faint: the cross-hatch's residue, not a cavity
    if kind == "pore" and m["mean_darkness"] > cfg.max_pore_darkness_over_floor * m["contrast"]:
        return None  # darker on the whole than its own fitted floor: no cavity's blurred step
    if kind == "scratch" and (m["contrast"] < cfg.min_scratch_contrast or m["blur"] > cfg.max_edge_blur_px
                              or m["width"] > max_width_px or m["length"] < cfg.scratch_elongation * m["width"]
                              or (m.get("along_hatch", False)
                                  and (not m.get("square_end", False)
                                       or m["contrast"] < cfg.aligned_min_scratch_contrast))
                              or m.get("along_share", 1.0) < cfg.min_scratch_along_share
                              or m["contrast"] * np.sqrt(max(m.get("along_share", 1.0), 0.0))
                              < cfg.min_scratch_line_contrast):
        return None  # the cross-hatch residue: broad, faint, soft, short, along a groove, not one line or faint, ragged
    conf = _confidence(m["significance"], cfg.min_significance)
    return Defect(kind, m["x"] + box[0], m["y"] + box[1], m["length"], m["width"], conf, m["angle"], m["u_length"],
                  m["u_width"], m["significance"], at_border)
