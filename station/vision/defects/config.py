"""The defect detector's settings (``DefectConfig``), its result (``Defect``) and the
constants shared by its stages.

Part of ``station.vision.defects`` (its docstring tells the method).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass


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
#: a rim's ray recalibrates the wall's level from its own ring beyond the band only when
#: at least this many of the ring's samples (0.5 px apart, 8 px in all) are clear of
#: the other zones' skirts; else from the rays either side (``rims._rim_profile``)
RIM_RING_MIN_SAMPLES = 4
#: a ray's share falls below a crossing going out (``_rim_profile``) only where it stays
#: below it over the next this many px: the rim's blurred step, and the burr's metal or
#: the wall beyond it, hold for many px, where the noise inside a dim hole dips for a
#: pixel or two (bilinear samples 0.5 px apart share their pixels). On the wide bench's
#: dim, noisy holes (5-20 e-/DN, 30 % contrast) the share inside reads 1 +/- 0.1 a
#: sample, and a dip below 0.75 at one sample 14-18 px inside the rim, the share back
#: at 0.86-1 beyond it, was that ray's "edge": 0.03-0.07 mm "burrs" 3-12 px high on
#: clean frames 1097086, 1099092 and 1100029 (session 56)
RIM_HOLD_PX = 2.0
#: a group of candidates (``group_collinear``) that is no defect has its strongest member
#: examined alone when its peak is at least this many times every other member's
GROUP_DOMINANT_SHARE = 2.0


@dataclass(frozen=True)
class DefectConfig:
    #: a dark disc at least this large is a hole, not a pore (:data:`MIN_HOLE_DIAMETER_MM`)
    min_hole_diameter_mm: float = MIN_HOLE_DIAMETER_MM
    #: a dark disc of a hole's size at none of the part's holes (``detect_defects``'s
    #: ``hole_places``) is a dark mark: the wall's level and its grooves' means are modelled
    #: past this many times its diameter, as past the largest pore. At 1.2x (the grooves'
    #: means then 1.8x) the means along the lines through a 1.3 mm pore took most of its
    #: middle's darkness, the level followed it there, its floor read from -0.08 to 0.55,
    #: and 0.65-1.3 mm pores were lost 9 times in 24 (synthetic frames, session 91); at
    #: 2x none of 24 at 1.0-1.3 mm, sizes within 2 %
    stray_disc_reach: float = 2.0
    #: ... a disc the holes' coarse stage finds counts from this share of the least
    #: hole's diameter (it reads a disc 0.85-0.93 of its size): the wall's model of frames
    #: whose marks are all of a pore's size stays as it is
    stray_disc_min_share: float = 0.85
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
    #: ... and what its circle holds must be dark: the share of the disc inside its rim's
    #: blur (radius R - 2 blur - 1 px) darker than midway between the ring beyond the rim
    #: and the disc's own darkest tenth. A 0.47 x 0.31 mm pore, by its rays a 0.56 mm
    #: circle that it half fills (0.46), was taken for a hole, its outline for two
    #: chips, and the pore was lost (wide bench frame 4920063). A hole's burrs take its
    #: disc at its rim: the three holes measured so in 600 fresh wide and station frames
    #: read 0.96-0.99; two of the twin's largest burrs (0.3 x 0.08 mm) on its least hole
    #: (0.6 mm) take about a tenth of it
    rim_hole_min_dark_share: float = 0.75
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
    #: a pore over which the frame's level lies this far (a share of it, on average)
    #: under the level taken round it is measured again under the latter
    #: (``examine._examine_once``, ``wall.level_dip``)
    pore_relevel_dip: float = 0.03
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
    #: a furrow of a candidate that holds several (two scratches crossing: ``split_furrows``)
    #: is examined within this many px of its line: half the widest scratch (0.06 mm)
    #: and the blur's reach beyond its edge
    furrow_half_band_px: float = 8.0
    #: a frame without a given blur or a hole's edge is examined again under the blur its
    #: scratches read themselves, combined (``shared_blur``), when that is known to this
    #: standard deviation (px; a 1.7 mm scratch reads it to ~0.2 px, a 0.7 mm one of
    #: higher contrast to ~0.07)
    frame_blur_max_sd_px: float = 0.25
    #: at most this many candidates per frame are examined (the most significant):
    #: a bound on the time of a pathological frame, far above a real wall's count
    max_candidates: int = 40
    #: a pore or scratch must be this significant at full resolution: its integrated
    #: darkening over its area against the patch's own noise integrated the same way
    #: (dev frames: the faintest true scratch above the limits 11.7; the cross-hatch's
    #: residue reaches 20 and more, and is told apart by the tests below, not by this)
    min_significance: float = 8.0
    #: a scratch not along the hatch is as significant as the larger of its box integral
    #: and its darkening weighed by its own cross profile (``_line_significance``), the
    #: latter counted up to this multiple of the former: true scratches read 0.74-3.6x the
    #: box (median 1.23; session 72's 9,100 frames), groove residue that a line's weights
    #: pick out of a band lighter on the whole 4-50x or against a negative box
    line_significance_max_over_box: float = 3.0
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
    #: ... but not for the dark discs of a hole's size at none of the part's holes (x_px,
    #: y_px, diameter_px; ``detect_defects`` sets them from its ``hole_places``): a mark
    #: centred in one and at least ``stray_disc_min_share`` of its diameter long is that
    #: disc. Such a pore reads a floor under its mean darkness where its outline is no
    #: ellipse and the fit's blur runs to 3 px (a 1.43 mm pore at a frame's border: 0.40
    #: against 0.49, lost; whole-surface bench seed 96000, ``--large-pores``). Not by size
    #: alone: the grooves' residue the test stops reaches 0.61 mm (wide frame 96090)
    floor_test_exempt: tuple = ()
    #: a pore's rim is a sharp edge blurred by the camera alone: a fitted edge blur beyond
    #: this (px) is a soft shading of the wall, not a cavity (the renderer's and the
    #: endoscope's envelope is 0.8-2 px; dev frames' texture blobs fit 3-3.5 px)
    max_edge_blur_px: float = 2.8
    #: ... and where the camera's blur is known (the frame's holes' edges, ``--blur-px``, a
    #: calibration), at least that blur plus this (px): the bar is the camera's blur and
    #: what a ragged outline or the fit's noise adds to it, and an endoscope focused less
    #: sharply than the station's 0.8-2 px must not lose its pores. 2.8 stands up to a
    #: camera blur of 2.0 (the envelope's edge, unchanged there); at 2.84 px a 0.33 x 0.23
    #: mm pore fitted its edge at 2.9-3.2 px and was lost (seed 981010, blur drawn 2-3 px)
    edge_blur_over_camera_px: float = 0.8
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
    #: ... and a mark further off a family than this (deg) keeps to none of its lines,
    #: however short and wide: the width allowance (``on_groove_line``: two pieces side by
    #: side read as one mark as wide as their offset, its axis turned by it) let a short
    #: wide scratch 30.6 deg off pass as keeping to a line, and a groove on that line
    #: through its middle ran on (station 4710086: a 0.216 x 0.043 mm scratch, plain to
    #: see, lost). Session 85, every scratch measurement that keeps to a line on six sets
    #: (station 4710000, wide 4700000, grooves broken 30 % 650000 and its clean 1650000,
    #: wide clean walls broken 40 % 4750000, scratches within 25 deg of the hatch 4760000):
    #: the 207 groove pieces read 19.3 deg off at most (two over 15, both on the wide broken
    #: walls); true scratches 8-28 deg off keep to a line by the chord alone, and three at
    #: 22.0, 25.9 and 30.6 deg were lost to a groove's run-on (the 22.0: wide 4620093 at a 65
    #: deg hatch, 0.32 x 0.046 mm). Set between the pieces' 19.3 and the scratches' 22.0:
    #: a thin margin either side
    groove_line_max_off_deg: float = 20.5
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
    #: ... or, when both ends are square (a cut at each, no wider than the first bar), each
    #: a step of at least this share: what lies on beyond a cut is another mark, a groove
    #: along the line or one of the other family crossing at the end (session 66: a 0.80 x
    #: 0.055 mm scratch 4 deg off the hatch, bench seed 580021, stepped 1.6 px / 1.01 and
    #: 1.5 px / 0.72 where a groove crossed its end). Over 206 scratches drawn 0-7.5 deg
    #: off a family, 4 more found; no false defect changed on 540 clean station, wide (20,
    #: 30, 45, 65 deg) and twin frames
    square_end_sharp_min_height: float = 0.65
    #: an end where the mark runs on at more than this share of its darkness, while the
    #: other end is square, makes it a piece of a longer mark: measured again with its line
    #: left out of the wall model's grooves (``examine_candidate``)
    square_end_max_run_on: float = 0.2
    #: ... and such a mark must be at least this dark (the fitted cross profile's
    #: contrast): the twin's deep grooves (10 % on average, up to 30 %) leave pieces of
    #: 0.12-0.13 there; the true scratches along the hatch fitted 0.13 and more
    aligned_min_scratch_contrast: float = 0.14
    #: a mark whose region runs along the hatch and ends in no cut is groove residue, but a
    #: strong one (its peak this many times the patch's noise) is measured as a line first:
    #: residue joined to a scratch pulls the region's axis onto the hatch (``_examine_once``)
    along_hatch_remeasure_k: float = 15.0
    #: ... and at least this share of the frame's own darkest groove stretches along its
    #: family (``groove_stretches``: the darkness integrated across the lines, which the
    #: blur leaves unchanged, over stretches of ``aligned_stretch_mm``; the population's
    #: ``aligned_stretch_quantile``-th percentile, the marks left out). The ends tell a
    #: furrow from a groove that fades along its length; a honing whose grooves stop short
    #: (a grain that bites and leaves: cut ends) makes groove pieces with square ends too,
    #: and then a mark along the hatch fainter than the frame's darkest grooves is one of
    #: them. A foreign renderer of ours (grooves broken by a threshold, so with cut ends;
    #: 20 + 20 frames) had 20 such "scratches" of 0.10-1.2 mm in its clean frames; the
    #: marks along the hatch there read 0.12-1.5 of the population's (3 of 56 at 0.9 or
    #: more), the twin's true scratches along the hatch (33 found on 60 frames, seeds
    #: 541000-541059) 0.65-6.1 (5 under 0.9)
    aligned_min_stretch_share: float = 0.9
    #: ... and where any mark along the hatch of the frame falls under that bar, the frame's
    #: grooves evidently stop short (on a wall whose grooves fade, the ends' test passes no
    #: groove piece: none of 172, session 45), its ends' test is no evidence there, and
    #: every mark along its hatch must reach this share. The twin's walls with 40 % of the
    #: grooves' length broken out (50 clean frames, seeds 1790000-1790049): 22 "scratches"
    #: with neither bar, 9 with the first alone, 5 with this; scratches drawn along the
    #: hatch on walls that fade (541000-541059, 56 above the limit): 51, 47, 46 found
    aligned_min_stretch_share_stopped: float = 1.2
    aligned_stretch_quantile: float = 99.9
    #: a scratch that keeps to one line of a groove family (``on_groove_line``) whose line
    #: runs on beyond it as a groove is a piece of that groove: its line's stretches at
    #: least ``groove_run_on_darkness`` of its own darkness over ``groove_run_on_share`` more
    #: of the line's length on the wall beyond its ends than of the whole wall's places
    #: (``line_runs_on``; not judged when less than ``groove_run_on_min_mm`` of it lies
    #: there). A groove runs across the frame, its depth fading, its pieces cut apart where
    #: the grooves stop short; a scratch is one furrow. Session 73, every scratch within
    #: 20 deg of a family logged on dev frames (station 994000, grooves 30 % broken 1650000,
    #: scratches along the hatch on walls broken 1660000 and fading 541000, scratches within
    #: 20 deg of the hatch 1670000 and, broken, 1680000): of 128 true scratches that keep to
    #: a line, the share read 0.106 at most (all but that one under 0.05; wide 610168's
    #: 0.21 mm scratch 13 deg off: 0.119); of the 29 groove pieces the other tests passed,
    #: all but one read 0.226-0.62 (the one, 2650027: a 1.26 mm piece whose line's rest is
    #: faint, 0.014). The whole wall's share (taken off since) read 0.006-0.11 on the walls
    #: whose grooves stop short, under the pieces' shares by 0.227 or more; up to 0.115 on
    #: wide walls, where a faint true scratch 15 deg off, its middle on a groove's line,
    #: still reads 0.36 over it (610128: 0.34 x 0.03 mm, lost)
    groove_run_on_darkness: float = 0.5
    groove_run_on_share: float = 0.2
    #: ... or, for a mark not along the hatch (``is_along_hatch``), when that excess is this
    #: many of its standard deviations had the line been any of the wall's (``RunOn.z``: its
    #: stretches beyond the mark independent draws at the wall's share, read as at least one
    #: stretch's worth). A share of 0.2 is much on a wall where nothing else reaches the bar
    #: and little on a wall of deep grooves. Session 74, the same log on 13 sets (station,
    #: broken, along and within 20 deg of the hatch, wide, a 20 deg hatch broken at 0.007
    #: mm/px, a smeared lens on broken walls; 266 true scratches read 0.2 mm or longer that
    #: keep to a line): the true ones read z 3.15 at most (wide 610009: a 0.42 mm scratch 11 deg off
    #: on deep grooves, share 0.119; then 2.8), but for 610128 above (9.5); the groove pieces
    #: that passed the share's bar and every other test read 4.2-7.6 for six of eleven
    #: (shares 0.089-0.197), 3.6 and less for the rest (a long piece whose line's rest is
    #: faint, pieces at a 20 deg hatch's V). Along the hatch a scratch may lie on a groove's
    #: line over its whole length: a fresh 1.44 mm one drawn along it read z 6.0 at share
    #: 0.092 (720067) and is judged by its ends and its darkness (above) instead; so are two
    #: of the six pieces
    groove_run_on_z: float = 4.0
    groove_run_on_min_mm: float = 0.5
    #: ... the mark's own darkness read over this share of its length round its middle
    groove_run_on_middle: float = 0.35
    #: a pore cut by the frame's border (``partial``) that reads as a short piece of a groove
    #: is one too (``frame._drop_hatch_like``): its long axis, at least
    #: ``border_piece_min_aspect`` times its width, within ``border_piece_max_off_deg`` of a
    #: family and nearer it than the border's direction (the family at least that far off the
    #: border's); no wider than ``border_piece_max_width_mm``; and its line running on beyond
    #: it by ``groove_run_on_share``. Where a honing's grooves stop short, a piece may end a
    #: few px inside the frame, and the grooves' means along the lines, one-sided at the
    #: border, leave it out; its few px are no line, and it was measured as a pore. The visible
    #: part of a round pore cut by a straight border lies along that border, or is most of the
    #: pore and nearly round. Session 75, every pore of six sets logged (wide walls broken
    #: 20 %, clean and with defects; station, wide and broken walls with 3 pores drawn across the
    #: border of each frame; 1,541 reads of pores): the 20 false pores at the border were such
    #: pieces, 16 of them within 15 deg of a family, 1.4-2.2 times as long as wide, 0.06-0.145
    #: mm wide (as read in either of a frame's two examinations), their lines running on by
    #: 0.43-0.90 (but one at a corner, where too little of its line is in the frame to tell).
    #: Of the 14 true pores cut by the border within 15 deg of a family whose lines ran on by
    #: 0.2 or more, 12 were 0.20-0.39 mm wide (pores of 0.26-0.50 mm); the other two, a 0.15 mm
    #: pore about as wide as long and one of 0.064 mm. With these bars 15 of the 20 go, and of
    #: the 1,376 true pores cut by the border the one of 0.064 mm
    border_piece_min_aspect: float = 1.3
    border_piece_max_off_deg: float = 15.0
    border_piece_max_width_mm: float = 0.15
    #: and a small mark cut by the border, whatever its axis, no longer than
    #: ``border_stub_max_length_mm`` nor wider than ``border_stub_max_width_mm``, on a line of
    #: either family that runs on beyond it by ``border_stub_min_run_on`` or more, is a
    #: groove's stub too: where two grooves cross at the border, or one meets it, the darkness
    #: the one-sided means leave is cut by the border, and lies along it as a cut pore's visible
    #: part does (session 76: of 12 false pores at the border over 550 clean frames of wide and
    #: broken walls, 9 were 0.09-0.14 x 0.055-0.09 mm, their lines running on by 0.52-0.90).
    #: Such a mark shows too little of a pore to size it: a round one whose chord is 0.14 mm
    #: and which shows 0.03 mm of itself is under 0.2 mm across, and a coverage scan sees it
    #: whole in the next frame. Of 1,495 true pores cut by the border (four sets) 7 go, all
    #: under 0.2 mm
    border_stub_max_length_mm: float = 0.14
    border_stub_max_width_mm: float = 0.09
    border_stub_min_run_on: float = 0.5
    #: a pore inside the frame whose darkness two crossing grooves explain is their
    #: crossing (``frame._drop_crossings``): each family's profile across its lines, read
    #: beside the mark along the line through it (over ``crossing_arm_mm`` beyond its
    #: blurred outline, the median along the line, the side that holds more), laid along
    #: that line through the mark, explains at least ``crossing_min_explained`` of the
    #: mark's darkness over its blurred outline, and each family at least
    #: ``crossing_min_family_share`` of it. Where a honing's grooves stop short, the
    #: frame's and the patch's means along the lines hold their pieces' depth too low, and
    #: where two pieces cross, the two shortfalls add up to a dark spot the size of a pore
    #: (session 78, wide walls broken 20 %: 9 false interior pores, explained 0.57-1.17,
    #: the lesser family 0.10-0.57). A pore takes the wall's place, grooves and all: of
    #: 405 true interior pores (those walls, the wide envelope's, the station's) small ones
    #: on one groove were explained up to 0.80 by its family, and where over 0.25 the
    #: lesser family explained 0.13 at most (a 0.32 mm pore where two grooves cross).
    #: Only a mark at least ``crossing_min_length_mm`` long is judged so: a pore far under
    #: any limit may be no larger than a crossing of two fine grooves, and be explained as
    #: much (a 0.074 x 0.053 mm pore where two grooves cross, wide frame 95088: 0.43 and
    #: 0.49); the crossings read as pores were 0.11-0.39 mm
    #: And the mark's darkness must follow the lines' laid through it, pixel by pixel over
    #: its outline (their correlation, at least ``crossing_min_follows``): a crossing's
    #: darkness peaks where the lines cross and runs out along their bands, a pore's
    #: floor is even across them. A pale 0.43 mm pore on a crossing of two deep grooves
    #: (session 81, wide frame 4510084) was explained 0.36 and 0.21, over both bars, and
    #: lost; its darkness follows the lines' at 0.20, the seven crossings session 78
    #: dropped on 3220000's and 3230000's sets and an eighth (5400019) at 0.70-0.98, drawn
    #: pores as pale as the lines on crossings of broad lines at 0.44 at most.
    crossing_min_length_mm: float = 0.1
    crossing_arm_mm: float = 0.2
    crossing_min_explained: float = 0.5
    crossing_min_family_share: float = 0.2
    crossing_min_follows: float = 0.5
    #: what a seed's defects leave of it unclaimed, in parts of at least
    #: ``rest_min_area_mm2``, is examined as a seed of its own (``frame._seed_rest``), up to
    #: ``rest_max_depth`` times over: a candidate is one connected mark of the residual, and
    #: defects that touch (a pore on a scratch's line) are one. A 0.40 mm pore on a 2.5 mm
    #: scratch was never reported, and the scratch read 1.47 mm, its part beyond the pore
    #: left with it. Session 79, pores drawn on the scratches' lines (station envelope,
    #: 100 frames, ``--pores-on-scratches 1``): pores over the limit found 25 -> 39 of 42,
    #: scratches 70 -> 79 of 94, no false mark either way (docs/surface.md)
    rest_min_area_mm2: float = 0.005
    rest_max_depth: int = 2
    #: a seed measured whole as one mark is read again as a scratch through pores when a
    #: thin mark's arms lie on one line through its blobs and reach together at least
    #: ``through_min_reach_mm`` beyond or between them (``wall.line_through_blob``): the
    #: scratch, measured with the blobs hidden, is kept when the seed read as a pore or as
    #: a shorter scratch, and the seed's rest then gives the pores. Session 80, pores drawn
    #: on the scratches' lines (station envelope, 100 frames, ``--pores-on-scratches 1``):
    #: scratches over the limit found 79 -> 91 of 94, pores 66 -> 69 of 69 (docs/surface.md)
    through_min_reach_mm: float = 0.1
    #: the stretches' length along the lines and the width of the core across them that
    #: is integrated, from its first row to its last (mm; at the station's 0.010 mm/px, 20
    #: px and +/- 2 px: three half-res rows), the flanks beside the core its baseline
    aligned_stretch_mm: float = 0.2
    aligned_stretch_core_mm: float = 0.04
    #: the least angle (deg) at which a groove family crosses a mark along the other for
    #: its grooves to be read along their own lines and taken out of the mark's ends'
    #: read (``end_steps``); nearer, the lines beside the mark run along it
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
    #: Session 85, every chip candidate that reached this test on six sets (wide 4700000,
    #: 4720000 at 22 deg, 4620000 at 65 deg; station 4710000, 4630000 at 20 deg; 100 clean
    #: wide 5700000): 290 true chips at most 0.30 (0.294 and 0.299 at the 20 and 65 deg
    #: hatches); a deep groove meeting the rim obliquely on a clean frame 0.377 (5700027,
    #: a 0.11 mm "chip", under the old 0.4), the other deep grooves 0.41-1.9
    chip_groove_share: float = 0.35
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
    #: a chip's broken face slopes into the hole in shadow: its floor, read where the notch
    #: is deep enough to hold one (``_chip_floor``), stands near the hole's level. A notch
    #: whose floor stands under this share of the wall-to-hole step is lit as the bottom
    #: of a groove is (a deep groove grazing or meeting the rim, two in a V), and a chip
    #: lit so is under the edge's crossing (``rim_crossing``) and not found as one (a 10 x
    #: 7 px chip lit to 0.5 of the step is lost under 1 px of blur). Session 87, every chip
    #: candidate that reached the groove tests on 14 sets with defects and 4 clean ones
    #: (1,800 frames: wide 4910000, 4920000, 4810000, 4700000, 94000, 95000, 4720000 at 22
    #: deg, 4620000 at 65 deg, 129000 at 26 deg; station 4800000, 4900000, 4710000, 4630000
    #: at 20 deg, 4820000 at 65 deg with 30 % of the grooves broken; clean wide 5910000,
    #: 5700000, 1082000, clean station 5820000): the 698 true chips over the limit read
    #: 0.538 at least (wide 129081, a 0.082 x 0.042 mm chip) but for one that the run-on
    #: test drops (0.435); the six false chips that passed the groove tests
    #: 0.355-0.477 (grooves grazing or meeting rims). Six true chips under the limit, 0.014-
    #: 0.018 mm deep and read 3.9-10.6 px for it (the floor read beside them is a groove's
    #: and their depth was divided by it), read 0.367-0.401 and are no longer reported
    chip_min_floor: float = 0.5
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
    #: ... or, whatever the gap's darkness, when the gap is at most this share of each
    #: piece's length and the pieces are in line within this turn (deg) and their core
    #: (``_in_line``)
    scratch_join_line_gap_share: float = 0.2
    scratch_join_line_turn_deg: float = 5.0
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

    def edge_blur_limit(self, camera_blur_px: float | None) -> float:
        """The largest edge blur (px) a pore's or a scratch's fit may read and still be a
        cavity or a furrow: ``max_edge_blur_px``, raised to the camera's blur plus
        ``edge_blur_over_camera_px`` where that blur is known."""
        if camera_blur_px is None:
            return self.max_edge_blur_px
        return max(self.max_edge_blur_px, float(camera_blur_px) + self.edge_blur_over_camera_px)


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
