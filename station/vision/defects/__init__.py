"""Surface defects of the honed bore wall: pores, scratches, burrs and chips (issue 23).

What fails a master cylinder in a plant is mostly its surface: a burr at a compensating
hole's edge cuts the seal cup, porosity of the casting and scratches of the honed bore
leak. This package finds each defect in one frame and measures it: kind, position (px),
length and width (px and mm) with standard uncertainties, and a confidence. Its modules
follow the stages below, each importing only those before it: ``config`` (settings,
the result), ``common`` (robust noise, the hatch, the bounded fit, shapes), ``wall``
(1-4), ``pores`` and ``scratches`` (5), ``rims`` (6), ``examine`` (4-5 for one
candidate), ``tracking`` (a scratch across the frame) and ``frame``
(:func:`detect_defects`).

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
   (along a groove direction, too faint, too soft an edge, too broad; a pore whose
   darkness the two groove lines through it explain is their crossing).
5. **Kind and size.** Elongated (3:1, the blur taken out by a blurred-ellipse fit) is a
   scratch, else a pore. *Pore*: its floor's contrast c from the blurred-ellipse fit; its
   outline from the darkening's angular density round its centroid, which is c r^2 / 2
   whatever the blur (a Fourier series of the pixels' angles, to the order the blur
   resolves), the grooves it cuts put back under the fitted ellipse first (a pore takes
   the wall's place, grooves and all); its greatest Feret diameter and the extent across
   it from that outline. A pore whose floor reads under the bar is examined again with
   the level taken round it (a large pale pore that the frame's level followed).
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
   out of it), ends at half the local height along the rim. Lengths and places are read
   on the baseline's circle, not the hole's fit, which large rim defects pull.

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

from station.vision.defects.config import Defect, DefectConfig, KINDS, MIN_HOLE_DIAMETER_MM
from station.vision.defects.common import feret
from station.vision.defects.wall import model_wall
from station.vision.defects.rims import camera_blur_from_edge
from station.vision.defects.frame import detect_defects

__all__ = [
    "Defect",
    "DefectConfig",
    "KINDS",
    "MIN_HOLE_DIAMETER_MM",
    "camera_blur_from_edge",
    "detect_defects",
    "feret",
    "model_wall",
]
