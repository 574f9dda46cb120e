"""The coverage scan of the bore wall: every place in the spec's band seen, defects
placed on the part and measured re-centred, the frames stitched into one picture.

The plan (after the holes, so burrs and chips are put at the holes the scan found):

1. **Rings of frames.** The band ``axial_from_mm`` .. ``axial_to_mm`` of the part spec's
   ``[surface]`` is covered by rings of frames, the table turning forward frame after
   frame and on into the next ring while Z steps (a helix of stops: C never reverses, so
   its backlash is taken up once). Neighbouring frames overlap by ``overlap_mm`` (more
   than the largest pore), so every pore is whole in some frame; a scratch longer than
   a frame is cut by the frames' edges and is joined across them (3.).
2. **Each frame's defects** (``MeasureSurface``: ``station.vision.defects``), analysed
   while the axes move to the next frame with the camera's blur the bore scan read at
   the holes' edges (:func:`camera_blur`), are placed on the part as the holes are
   (``scan.py``): where compensation put the detection point, moved by what the grating
   saw that the model did not, plus the defect's offset from the frame's centre. Each
   frame is told where the part's holes show in it (:meth:`_SurfaceScan.hole_places`,
   from the bore scan): a dark disc at none of them is a mark of the wall (a pore
   larger than the least hole, or a drilling the drawing does not have), measured and
   reported as a pore with a note, not taken for a hole. Off
   the centre that offset carries the lens's distortion (the endoscope's: up to 2.7 % at
   a corner, 0.2 mm): with the camera's calibration (``CameraGeometry.calibration``) it
   is taken out, and the defect's sizes are corrected by the lens's local scale.
3. **One measurement per defect.** Sightings of one defect (from overlapping frames) are
   merged. With the calibration, the defect is measured in the coverage frame that saw it
   whole nearest its centre; a defect no frame saw whole (cut by every frame's edge), one
   whose frames, all off their centres, read sizes that disagree, and, without a
   calibration, every defect, is measured again in a frame centred on it
   (compensated as any move), where the distortion is below a few um
   (``recentre_reach_px``); one seen only cut by frames' borders that the frame centred
   on it does not show is the borders' mark and is not reported. Defects near each
   other share a re-centred frame, and
   defects too close to merge apart are told apart in the frame that measures them. A
   scratch that no frame sees whole is joined from its pieces first
   (:meth:`_SurfaceScan.join_scratches`): its centre line fitted to the pieces' middles
   and directions, its length along that line, its place the line's middle; without a
   calibration its ends and middle are read again re-centred.
4. **The picture.** Each frame, flat-fielded (its own smooth level divided out, so the
   vignetting and the light's blotches do not tile) and reduced to ``picture_mm_per_px``,
   fills the cell of the unrolled wall nearest its centre (``station.inspection.surface``
   for the picture's axes), undistorted with the calibration and placed to a fraction of
   its pixel. Without a calibration a seam may show the lens's distortion at a cell's
   corner (up to ~0.15 mm); the defects' places never come from the picture.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Mapping

import cv2
import numpy as np

from station.inspection.scan import CameraGeometry, HoleResult, ScanSettings, goto, hole_targets, wrap_deg
from station.inspection.surface import SurfaceDefect, SurfacePicture, SurfaceResult
from station.kinematics.model import StationModel
from station.motion import AxisLimits
from station.parts.spec import PartSpec, SURFACE_RIM_KINDS
from station.sequencer import messages as m
from station.vision.defects import DefectConfig, MIN_HOLE_DIAMETER_MM, camera_blur_from_edge


@dataclass(frozen=True)
class SurfaceSettings:
    #: neighbouring frames overlap by this much (mm): the largest pore the issue names
    #: (0.5 mm) and a margin, so every pore is whole in some frame
    overlap_mm: float = 0.6
    #: the picture's scale (mm per px on the unrolled wall): a quarter of the camera's
    #: 0.01, so the whole bore (120 x 70 mm) is 3000 x 1740 px
    picture_mm_per_px: float = 0.04
    #: a defect this near a frame's centre (px) is measured where it is: the endoscope's
    #: barrel distortion there (k1 r^3 / f^2) stays below 0.35 px (3.5 um)
    recentre_reach_px: float = 200.0
    #: readings of one defect's size from several frames are pooled when they agree within
    #: this Birge ratio (their scatter over what their own uncertainties allow); beyond it
    #: the reading with the most evidence is taken
    pool_birge_max: float = 2.0
    #: sightings of one defect from overlapping frames lie within this (mm) plus half the
    #: longer's length of each other (the distortion moves a corner's sighting ~0.2 mm);
    #: a pore's and a scratch's, within it plus half the *shorter's*, or the pore within it
    #: of the scratch's chord: the longer's half length took in a 0.28 mm pore 1.3 mm
    #: beside a 4.9 mm scratch, and the group was measured as the scratch alone
    #: (whole-surface seed 24405), while a long scratch's end that a frame's border cuts
    #: reads as a small pore on its line (seed 24402; session 49)
    merge_mm: float = 0.35
    #: a burr or chip at none of the part's holes this far (mm) beyond a pore's half length
    #: from its middle is the pore's edge read as a hole's rim (``without_pores_rims``)
    pore_rim_reach_mm: float = 0.1
    #: a frame's dark disc within this (mm) beyond a hole's radius of where the bore scan
    #: found it is that hole; one at none of the part's holes is a mark of the wall (a
    #: pore larger than a hole, or a stray drilling) and is measured and reported as a pore
    #: (``hole_places``). The scan's places are good to ~0.02 mm; the lens's distortion,
    #: where no calibration takes it out, moves a frame's corner ~0.2 mm
    hole_place_reach_mm: float = 0.3
    #: a mark seen at one place of the *image* in this many coverage frames, each at
    #: another place of the part, moves with the camera, not the part: a flaw of its
    #: sensor or a speck on its window (``camera_marks``). Two frames never look at one
    #: place from the same pose, so a part's defect lands on one image place in one
    #: frame at most; three is a margin against chance
    camera_mark_frames: int = 3
    #: ... "one place": centres within this (px) plus, along a scratch's line, their
    #: half lengths' difference, directions within ``camera_mark_deg``
    camera_mark_px: float = 4.0
    camera_mark_deg: float = 8.0
    #: pieces of one scratch longer than a frame, each cut by a frame's border, are
    #: joined when they overlap along the furrow or are apart by at most
    #: ``join_gap_mm``, their directions agree within ``join_angle_deg``, and each one's
    #: middle lies where the other's middle and the two chords' mean slope put it, within
    #: ``join_offset_mm`` plus the wider's width plus ``join_bend_share`` of the distance
    #: between the middles (:meth:`_SurfaceScan.misfit`). A scratch bends: the renderer's
    #: two modes of 1.2 % RMS of its length each left a misfit of 0.55 mm between two
    #: pieces 10 mm apart on a strongly bent 24 mm scratch, their chords ~8 deg apart
    #: (dev seeds 23700-23704). Pieces that follow each other are joined only as each
    #: other's best fit on the side they meet (:meth:`_SurfaceScan.join_scratches`).
    #: Without the lens's calibration a piece's place off a frame's centre is off by up
    #: to ``join_lens_mm`` (2.7 % of the offset at a corner), which the gap and the
    #: offset allow as well.
    join_gap_mm: float = 0.35
    join_offset_mm: float = 0.06
    join_angle_deg: float = 25.0
    join_bend_share: float = 0.06
    join_lens_mm: float = 0.2
    #: a scratch's end that a frame's border cut and no neighbouring frame's piece
    #: continued is followed in a frame centred on it (:meth:`_SurfaceScan.
    #: follow_scratches`): so many rounds, so many frames per scan at most
    follow_rounds: int = 3
    follow_max_looks: int = 12
    #: standard uncertainty (mm) of a joined scratch's end beside what its piece's fit
    #: says: mostly an end is right to ~0.01 mm, but now and then the detector loses an
    #: end that fades into a groove by 0.1-0.4 mm. Set on dev seeds 23600-23602 and
    #: 23700-23704 (37 long scratches) so that the length's U (k = 2) holds ~90 % of them
    join_end_u_mm: float = 0.04
    #: a cut scratch's end this near (px) a frame's border was cut there: the detector
    #: reads a furrow's end from a strip across it, which the border cuts short
    border_px: float = 40.0
    #: the flat field's Gaussian (mm): wide against a defect (0.5 mm), narrow against
    #: the vignetting and the light's blotches
    flat_sigma_mm: float = 1.0
    #: standard uncertainty of a defect's centroid in its re-centred frame (px): the
    #: outline's own raggedness (half a blur)
    centroid_u_px: float = 0.5
    #: ... and a share of its length along it (a scratch's ends fade into the grain)
    centroid_u_share: float = 0.02
    #: the grey level the flat-fielded wall is shown at (uint8)
    picture_level: int = 150


@dataclass(frozen=True)
class CoveragePlan:
    """Where the coverage frames go: ring centres along the bore and angles round it."""

    axials_mm: tuple[float, ...]
    angles_deg: tuple[float, ...]
    step_axial_mm: float
    step_wall_mm: float
    band_mm: tuple[float, float]

    @property
    def frames(self) -> int:
        return len(self.axials_mm) * len(self.angles_deg)


def coverage_plan(band_mm: tuple[float, float], geo: CameraGeometry, overlap_mm: float) -> CoveragePlan:
    """The fewest rings and columns whose frames, overlapping by ``overlap_mm``, cover
    the band all round."""
    lo, hi = band_mm
    fw, fh = geo.width_px * geo.mm_per_px, geo.height_px * geo.mm_per_px
    if overlap_mm >= min(fw, fh) / 2:
        raise ValueError(f"an overlap of {overlap_mm} mm leaves nothing of a {fw:.2f} x {fh:.2f} mm frame")
    extent = hi - lo
    if extent <= fh:
        axials = [(lo + hi) / 2.0]
        step_v = extent
    else:
        rows = math.ceil((extent - overlap_mm) / (fh - overlap_mm))
        step_v = (extent - fh) / (rows - 1) if rows > 1 else 0.0
        axials = [lo + fh / 2.0 + i * step_v for i in range(rows)]
    circ = 2.0 * math.pi * geo.bore_radius_mm
    cols = max(1, math.ceil(circ / (fw - overlap_mm)))
    angles = [j * 360.0 / cols for j in range(cols)]
    return CoveragePlan(tuple(axials), tuple(angles), step_v, circ / cols, band_mm)


@dataclass
class _Sighting:
    """A defect seen in one frame, placed on the part."""

    defect: object  # station.vision.defects.Defect
    axial_mm: float
    angle_deg: float
    r_px: float
    frame: int
    #: where the frame was centred on the part (grating included)
    centre: tuple[float, float] | None = None


def camera_marks(sightings: list[_Sighting], cfg: SurfaceSettings,
                 radius_mm: float) -> tuple[list[list[_Sighting]], list[_Sighting]]:
    """(marks, the rest): the sightings that sit at one place of the image in
    ``cfg.camera_mark_frames`` or more coverage frames (one kind; a scratch's line and
    extent alike), grouped per mark. The coverage frames look at the part from distinct
    poses, so only what moves with the camera (its sensor's flawed pixels, a speck on
    its window) stays put in the image while the part moves under it; but a scratch
    longer than several frames crosses each of a row of them at one image place, and
    whose places on the part lie along it is kept (``_one_scratch_on_the_part``;
    ``radius_mm``: the bore's)."""
    n = len(sightings)
    parent = list(range(n))

    def same_place(a, b) -> bool:
        if a.kind != b.kind:
            return False
        dx, dy = b.x_px - a.x_px, b.y_px - a.y_px
        if a.kind != "scratch":
            return math.hypot(dx, dy) <= cfg.camera_mark_px
        turn = abs((a.angle_deg - b.angle_deg + 90.0) % 180.0 - 90.0)
        if turn > cfg.camera_mark_deg:
            return False
        t = math.radians(a.angle_deg)
        along, across = dx * math.cos(t) + dy * math.sin(t), -dx * math.sin(t) + dy * math.cos(t)
        return (abs(across) <= cfg.camera_mark_px
                and abs(along) <= cfg.camera_mark_px + abs(a.length_px - b.length_px) / 2.0)

    for i in range(n):
        for j in range(i + 1, n):
            if sightings[i].frame != sightings[j].frame and same_place(sightings[i].defect, sightings[j].defect):
                parent[_root(parent, i)] = _root(parent, j)
    groups: dict[int, list[int]] = {}
    for i in range(n):
        groups.setdefault(_root(parent, i), []).append(i)
    marks, drop = [], set()
    for members in groups.values():
        group = [sightings[i] for i in members]
        if len({s.frame for s in group}) < cfg.camera_mark_frames:
            continue
        if group[0].defect.kind == "scratch" and _one_scratch_on_the_part(group, radius_mm, cfg):
            continue
        marks.append(group)
        drop.update(members)
    return marks, [s for i, s in enumerate(sightings) if i not in drop]


def _one_scratch_on_the_part(group: list[_Sighting], radius_mm: float, cfg: SurfaceSettings) -> bool:
    """Whether a scratch's sightings at one image place could be one long scratch of the
    part: a furrow along the bore's axis seen by the frames of consecutive rings at one
    angle, or round it by the frames of one ring, crosses each frame at the same image
    place. They could when their places on the part lie on one line (within
    ``join_offset_mm`` plus the lens's ``join_lens_mm``) along the scratch's own direction
    there (within ``camera_mark_deg``): then the scratch is the part's, and the joining
    of pieces measures it."""
    a0 = group[0].angle_deg
    pts = np.array([(s.axial_mm, math.radians(wrap_deg(s.angle_deg - a0)) * radius_mm) for s in group])
    pts -= pts.mean(axis=0)
    _, sv, vt = np.linalg.svd(pts, full_matrices=False)
    spread = sv[1] / math.sqrt(len(group)) if len(sv) > 1 else 0.0
    if spread > cfg.join_offset_mm + cfg.join_lens_mm:
        return False
    # the line's direction on the part against the scratch's: image x runs round the
    # bore, image y against its axis (``_SurfaceScan.place``)
    d_axial, d_round = vt[0]
    t = math.radians(group[0].defect.angle_deg)  # the group's lie within camera_mark_deg of it (mod 180)
    along = math.degrees(math.atan2(-math.sin(t), math.cos(t)))  # (round, axial) of the scratch
    line = math.degrees(math.atan2(d_axial, d_round))
    return abs((line - along + 90.0) % 180.0 - 90.0) <= cfg.camera_mark_deg


def _root(parent: list[int], i: int) -> int:
    """Union-find: the root of ``i``'s set, the path halved on the way."""
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@dataclass
class _Piece:
    """A scratch's sighting as a segment on the part: its two ends (axial mm, angle deg,
    the lens taken out when known), each end's image px and whether the frame's border
    cut it there."""

    sighting: _Sighting
    ends: tuple[tuple[float, float], tuple[float, float]]
    ends_px: tuple[tuple[float, float], tuple[float, float]]
    cut: tuple[bool, bool]
    #: the centre line's points on the part (axial mm, angle deg), end to end; None when
    #: the detector gave no line
    line: tuple[tuple[float, float], ...] | None = None


@dataclass
class _CentreLine:
    """A joined scratch's centre line: its offset across its chord (mm) as a polynomial in
    x = 2 t / length - 1 over the chord's 0 <= t <= length."""

    length_mm: float
    coef: np.ndarray

    def basis(self, t: float) -> np.ndarray:
        x = 2.0 * t / max(self.length_mm, 1e-9) - 1.0
        return x ** np.arange(self.coef.size)

    def offset(self, t: float) -> float:
        return float(self.basis(t) @ self.coef)

    def length(self) -> float:
        t = np.linspace(0.0, self.length_mm, max(int(self.length_mm / 0.02), 8) + 1)
        off = np.array([self.offset(x) for x in t])
        return float(np.hypot(np.diff(t), np.diff(off)).sum())


@dataclass
class _Look:
    """A frame taken re-centred: where it was centred on the part (grating included)."""

    axial_mm: float
    angle_deg: float
    defects: list


class _Picture:
    """The unrolled picture, filled frame by frame (the cell nearest each frame's centre)."""

    def __init__(self, plan: CoveragePlan, geo: CameraGeometry, cfg: SurfaceSettings, lens=None):
        self.geo, self.cfg, self.plan = geo, cfg, plan
        #: the calibration's undistortion maps (ideal pixels of the same camera matrix),
        #: so the cells meet without the lens's distortion at their seams; None: as taken
        self.maps = None
        if lens is not None:
            k = np.asarray(lens.camera_matrix, np.float64)
            self.maps = cv2.initUndistortRectifyMap(k, np.asarray(lens.dist_coeffs, np.float64), None, k,
                                                    (geo.width_px, geo.height_px), cv2.CV_32FC1)
        ppx = cfg.picture_mm_per_px
        self.lo, self.hi = plan.band_mm
        h = max(1, int(round((self.hi - self.lo) / ppx)))
        circ = 2.0 * math.pi * geo.bore_radius_mm
        w = max(1, int(round(circ / ppx)))
        self.image = np.zeros((h, w), np.uint8)
        self.filled = np.zeros((h, w), bool)
        # columns start half a cell before the first frame's angle: each cell is whole
        self.angle_from_deg = (plan.angles_deg[0] - math.degrees(plan.step_wall_mm / 2.0 / geo.bore_radius_mm)) % 360.0
        self.picture = SurfacePicture(self.image, ppx, self.lo, self.angle_from_deg, geo.bore_radius_mm)

    def add(self, image: np.ndarray, axial_mm: float, angle_deg: float, ring: int) -> None:
        geo, cfg, plan = self.geo, self.cfg, self.plan
        ppx = cfg.picture_mm_per_px
        factor = geo.mm_per_px / ppx
        grey = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        if self.maps is not None:
            grey = cv2.remap(grey, self.maps[0], self.maps[1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        small = cv2.resize(grey.astype(np.float32), None, fx=factor, fy=factor, interpolation=cv2.INTER_AREA)
        level = cv2.GaussianBlur(small, (0, 0), cfg.flat_sigma_mm / ppx)
        flat = np.clip(small / np.maximum(level, 1.0) * cfg.picture_level, 0, 255).astype(np.uint8)
        flat = flat[::-1, :]  # image rows run against the axis; the picture's with it
        th, tw = flat.shape
        # the tile's centre pixel lies at the frame's centre on the part: the tile is
        # shifted by the fraction of a picture pixel first, then pasted at whole pixels
        cx_exact, _cy_exact = self.picture.px_of(axial_mm, angle_deg)
        cx_pic, cy_pic = self.picture.px_of(axial_mm, angle_deg)
        fx, fy = cx_pic - math.floor(cx_pic), cy_pic - math.floor(cy_pic)
        if fx or fy:
            shift = np.float32([[1, 0, fx], [0, 1, fy]])
            flat = cv2.warpAffine(flat, shift, (tw, th), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        cx_pic, cy_pic = math.floor(cx_pic), math.floor(cy_pic)  # where the shifted tile's centre goes
        # the cell: half a step each side (the band's ends for the first and last ring)
        a_lo = self.lo if ring == 0 else axial_mm - plan.step_axial_mm / 2.0
        a_hi = self.hi if ring == len(plan.axials_mm) - 1 else axial_mm + plan.step_axial_mm / 2.0
        y0 = max(0, int(math.floor((a_lo - self.lo) / ppx)))
        y1 = min(self.image.shape[0], int(math.ceil((a_hi - self.lo) / ppx)))
        half_w = plan.step_wall_mm / 2.0 / ppx
        x0, x1 = int(math.floor(cx_exact - half_w)), int(math.ceil(cx_exact + half_w)) + 1
        ty0 = int(round(y0 - cy_pic + (th - 1) / 2.0))
        tx0 = int(round(x0 - cx_pic + (tw - 1) / 2.0))
        rows = np.arange(y0, y1)
        cols = np.arange(x0, x1)
        trows, tcols = rows - y0 + ty0, cols - x0 + tx0
        # a frame's edge on the band's end may fall a rounding short of the last row: the
        # tile's edge pixel stands in there (one pixel at most)
        keep_r = (trows >= -1) & (trows <= th)
        keep_c = (tcols >= -1) & (tcols <= tw)
        trows, tcols = np.clip(trows, 0, th - 1), np.clip(tcols, 0, tw - 1)
        rows, trows = rows[keep_r], trows[keep_r]
        cols, tcols = cols[keep_c] % self.image.shape[1], tcols[keep_c]
        if rows.size == 0 or cols.size == 0:
            return
        self.image[np.ix_(rows, cols)] = flat[np.ix_(trows, tcols)]
        self.filled[np.ix_(rows, cols)] = True

    @property
    def coverage(self) -> float:
        return float(self.filled.mean())


class _SurfaceScan:
    def __init__(self, model: StationModel, part: PartSpec, geo: CameraGeometry, settings: ScanSettings,
                 cfg: SurfaceSettings, motion: Mapping[str, AxisLimits] | None, holes: list[HoleResult],
                 findings=()):
        self.model, self.part, self.geo, self.settings, self.cfg = model, part, geo, settings, cfg
        self.motion = dict(motion or {})
        self.axes_at: dict[str, float] = {}
        self.c_now = 0.0
        self.radius = geo.bore_radius_mm
        self.holes = [h for h in holes if h.found]
        #: the bore scan's unexpected holes (``ScanFinding``), named in the notes of the
        #: pores of a hole's size reported where they are
        self.unexpected = [f for f in findings if f.kind == "unexpected_hole" and f.axial_mm is not None
                           and f.angle_deg is not None]
        #: the drawing's holes the bore scan did not find: where it searched, a dark disc is
        #: still taken for the hole (its verdict is the bore scan's, not the surface's)
        found_names = {h.name for h in self.holes}
        self.unfound = [t for t in hole_targets(part) if t.name not in found_names]
        self.plan = coverage_plan(part.surface_band_mm(), geo, cfg.overlap_mm)
        self.looks: list[_Look] = []
        self.notes: list[str] = []
        #: the camera's blur (Gaussian sigma, px) for every frame's defect detection, from
        #: the holes' edges in the bore scan (:func:`camera_blur`); None: none was read,
        #: and each frame reads it itself
        self.blur_px, self.blur_frames = camera_blur(self.holes)
        #: the camera's calibration when it fits the frames: defects are then measured
        #: where a coverage frame saw them, undistorted (re-centred only when no frame saw
        #: them whole); None: every defect re-centred
        self.lens = geo.calibration
        if self.lens is not None and tuple(self.lens.image_size) != (geo.width_px, geo.height_px):
            self.notes.append(f"the camera's calibration is for {self.lens.image_size[0]} x {self.lens.image_size[1]} "
                              f"px frames, not {geo.width_px} x {geo.height_px}: not used (defects re-centred)")
            self.lens = None

    def ideal(self, x_px: float, y_px: float) -> tuple[float, float]:
        """Image px -> ideal px of the same camera (the lens's distortion taken out)."""
        if self.lens is None:
            return x_px, y_px
        p = self.lens.undistort_px(np.array([[x_px, y_px]], np.float64))[0]
        return float(p[0]), float(p[1])

    def local_scale(self, x_px: float, y_px: float, angle_deg: float | None, half_px: float) -> float:
        """Ideal px per image px at (x, y) along ``angle_deg`` (image sense; None: the
        mean of x and y): the distortion shrinks a defect towards the frame's corners."""
        if self.lens is None:
            return 1.0
        h = max(half_px, 2.0)
        dirs = [angle_deg] if angle_deg is not None else [0.0, 90.0]
        out = []
        for a in dirs:
            c, s_ = math.cos(math.radians(a)), math.sin(math.radians(a))
            p = self.lens.undistort_px(np.array([[x_px - h * c, y_px - h * s_], [x_px + h * c, y_px + h * s_]]))
            out.append(float(np.hypot(*(p[1] - p[0]))) / (2 * h))
        return float(np.mean(out))

    def wall_mm(self, a: tuple[float, float], b: tuple[float, float]) -> float:
        return math.hypot(a[0] - b[0], math.radians(wrap_deg(a[1] - b[1])) * self.radius)

    def place(self, centre: tuple[float, float], x_px: float, y_px: float) -> tuple[float, float]:
        """A frame's image px on the part (the lens's distortion taken out when known)."""
        cx, cy = self.geo.centre_px
        s = self.geo.mm_per_px
        x_px, y_px = self.ideal(x_px, y_px)
        return centre[0] + (cy - y_px) * s, (centre[1] + math.degrees((x_px - cx) * s / self.radius)) % 360.0

    def image_px(self, centre: tuple[float, float], axial_mm: float, angle_deg: float) -> tuple[float, float]:
        """A place on the part in the image of a frame centred at ``centre``: :meth:`place`'s
        inverse (the lens's distortion put in when the calibration is known)."""
        cx, cy = self.geo.centre_px
        s = self.geo.mm_per_px
        x = cx + math.radians(wrap_deg(angle_deg - centre[1])) * self.radius / s
        y = cy - (axial_mm - centre[0]) / s
        if self.lens is None:
            return x, y
        p = self.lens.distort_px(np.array([[x, y]], np.float64))[0]
        return float(p[0]), float(p[1])

    def move(self, axial: float, angle: float, forward: bool = False):
        """To (axial, angle) on the part; the table forward (never back) when asked, else
        the short way. Returns the frame's centre on the part with the grating's
        correction: (axial + drift, angle)."""
        turn = (angle - self.c_now) % 360.0 if forward else wrap_deg(angle - self.c_now)
        z_cmd, c_cmd, carriage = yield from goto(self.model, axial, self.c_now + turn, self.settings, self.motion,
                                                 self.axes_at)
        self.c_now = c_cmd
        reading = yield m.ReadEncoder()
        drift = 0.0
        if reading is not None and self.settings.use_grating:
            drift = float(reading.position_mm) - carriage
        return axial + drift, angle % 360.0

    def hole_places(self, centre: tuple[float, float]) -> tuple[tuple[float, float, float], ...]:
        """Where the part's holes show in a frame centred at ``centre`` (axial mm, angle
        deg), as (x_px, y_px, reach_px) in its image (the lens's distortion put in when the
        calibration is known): each found hole where the bore scan measured it, its radius
        plus ``hole_place_reach_mm`` round it; each hole it did not find over the band it
        was searched in (:meth:`search_band`, and the same margin). Holes out of the frame
        by more than their reach are left out."""
        reach_mm = self.cfg.hole_place_reach_mm
        spots = [(h.position_mm, h.angle_deg, h.diameter_mm / 2.0 + reach_mm) for h in self.holes]
        for t in self.unfound:
            axial, angle, reach = self.search_band(t)
            spots.append((axial, angle, reach + reach_mm))
        out = []
        for axial, angle, reach in spots:
            # whether it reaches into the frame, on the wall (mm from the centre)
            du = math.radians(wrap_deg(angle - centre[1])) * self.radius
            half_w = (self.geo.width_px - 1) / 2.0 * self.geo.mm_per_px
            half_h = (self.geo.height_px - 1) / 2.0 * self.geo.mm_per_px
            if abs(du) <= half_w + reach and abs(axial - centre[0]) <= half_h + reach:
                x, y = self.image_px(centre, axial, angle)
                out.append((x, y, reach / self.geo.mm_per_px))
        return tuple(out)

    def search_band(self, target) -> tuple[float, float, float]:
        """Where the bore scan searched for a spec hole it did not find (its ``HoleTarget``,
        ``hole_targets``: the position's limits widened by the part's axial placement, the
        drawing's angular band, plus the placement's when a fixture sets the part's angle,
        as ``BoreScan.zone`` has it), as a circle on the wall round that zone and its
        largest radius: (axial mm, table angle deg, radius mm). With an angular datum the
        part's angle is what the found holes say (their angles less the drawing's, the
        median); none found: all round."""
        pl = self.part.placement
        lo, hi = target.zone_axial_mm
        half_deg = target.angle_half_deg + (pl.angle_deg if pl.angular_datum is None else 0.0)
        offset = 0.0
        if pl.angular_datum is not None:
            drawing = {h.id: h.angle_deg for h in self.part.holes}
            turns = [wrap_deg(h.angle_deg - drawing[h.name]) for h in self.holes if h.name in drawing]
            if turns:
                offset = float(np.median(turns))
            else:
                half_deg = 180.0
        arc = math.radians(min(half_deg, 180.0)) * self.radius
        return (lo + hi) / 2.0, (target.angle_deg + offset) % 360.0, \
            target.diameter_hi_mm / 2.0 + math.hypot((hi - lo) / 2.0, arc)

    def analyse(self, image, centre: tuple[float, float]):
        """A frame's defects (``MeasureSurface``): the camera's blur from the bore scan's
        holes, and where the part's holes show in it (``hole_places``)."""
        defects = yield m.MeasureSurface(image, blur_px=self.blur_px, hole_places=self.hole_places(centre))
        return list(defects or [])

    def frame(self, centre: tuple[float, float]):
        frame = yield m.Capture()
        return frame.image, (yield from self.analyse(frame.image, centre))

    def run(self):
        plan = self.plan
        c_now = yield m.ReadAxis("C")
        if isinstance(c_now, (int, float)) and math.isfinite(c_now):
            self.c_now = float(c_now)
        picture = _Picture(plan, self.geo, self.cfg, self.lens)
        sightings: list[_Sighting] = []
        total = plan.frames
        yield m.Note(f"surface: {len(plan.axials_mm)} rings of {len(plan.angles_deg)} frames over "
                     f"{plan.band_mm[0]:g}..{plan.band_mm[1]:g} mm")
        yield m.Note("surface: the camera's blur " + (
            f"{self.blur_px:.2f} px, the median over the holes' edges in {self.blur_frames} bore scan frame(s)"
            if self.blur_px is not None else "not known (no hole's edge measured): each frame reads its own"))
        yield m.Emit("surface", "start")  # the service times the surface's part of the cycle from here
        cx, cy = self.geo.centre_px
        k = 0
        pending = None  # the last frame, analysed while the axes move to the next

        def analysed(frame_k: int, centre: tuple[float, float], defects) -> None:
            for d in defects:
                ax, an = self.place(centre, d.x_px, d.y_px)
                sightings.append(_Sighting(d, ax, an, math.hypot(d.x_px - cx, d.y_px - cy), frame_k, centre))

        for ring, axial in enumerate(plan.axials_mm):
            yield m.Checkpoint(f"surface ring {ring + 1}")
            for angle in plan.angles_deg:
                done: list = []
                centre = yield from _measuring_on_the_way(self.move(axial, angle, forward=True), pending, done,
                                                          self.analyse)
                if done:
                    analysed(*done[0])
                frame = yield m.Capture()
                picture.add(frame.image, centre[0], centre[1], ring)
                pending = (k, centre, frame.image)
                k += 1
                yield m.Progress(k, total, f"surface frame {k} of {total}")
        if pending is not None:
            analysed(pending[0], pending[1], (yield from self.analyse(pending[2], pending[1])))
        marks, sightings = camera_marks(sightings, self.cfg, self.radius)
        for mark in marks:
            kind = mark[0].defect.kind
            length = float(np.median([s.defect.length_px for s in mark])) * self.geo.mm_per_px
            x, y = (float(np.median([getattr(s.defect, k) for s in mark])) for k in ("x_px", "y_px"))
            note = (f"surface: a {kind} about {length:.2f} mm long at image px ({x:.0f}, {y:.0f}) in "
                    f"{len({s.frame for s in mark})} frames at other places of the part moves "
                    f"with the camera, not the part (a flaw of its sensor or a speck on its window): not reported; "
                    f"`station check camera` maps the sensor's flaws")
            self.notes.append(note)
            yield m.Note(note)
        sightings += yield from self.follow_scratches(sightings)
        chains, rest = self.join_scratches(sightings)
        groups = self.merge(rest)
        yield m.Note(f"surface: {len(sightings)} sightings, {len(groups) + len(chains)} defect(s) to measure"
                     + (f" ({len(chains)} scratch(es) longer than a frame, joined from their pieces)" if chains else ""))
        defects = []
        for chain in chains:
            defects.append((yield from self.measure_joined(chain)))
        for g in self.route(groups):
            for d in (yield from self.measure(g)):
                # a re-centred frame shared by two groups shows a defect to both: once
                if not any(o.kind == d.kind and self.wall_mm((o.axial_mm, o.angle_deg), (d.axial_mm, d.angle_deg)) < 0.05
                           for o in defects):
                    defects.append(d)
        defects = self.without_pores_rims(defects)
        for d in defects:
            if d.kind == "pore" and d.length_mm >= MIN_HOLE_DIAMETER_MM:
                seen = next((f for f in self.unexpected
                             if self.wall_mm((f.axial_mm, f.angle_deg), (d.axial_mm, d.angle_deg))
                             <= max(d.length_mm / 2.0, self.cfg.merge_mm)), None)
                note = (f"surface: a dark disc {d.length_mm:.2f} x {d.width_mm:.2f} mm at {d.axial_mm:.3f} mm, "
                        f"{d.angle_deg:.2f} deg, the size of a hole, lies at none of the part's holes: reported as a "
                        f"pore (a pore larger than the least hole, or a drilling where the drawing has none)"
                        + ("" if seen is None else
                           f"; the bore scan found it too, an unexpected hole of {seen.diameter_mm:.3f} mm"))
                self.notes.append(note)
                yield m.Note(note)
        for i, d in enumerate(sorted(defects, key=lambda d: (d.axial_mm, d.angle_deg))):
            d.id = f"d{i + 1}"
        lo, hi = plan.band_mm
        out = SurfaceResult(sorted(defects, key=lambda d: (d.axial_mm, d.angle_deg)), picture.picture, plan.frames,
                            len(self.looks), lo, hi, picture.coverage, self.notes, self.blur_px)
        return out

    def without_pores_rims(self, defects: list[SurfaceDefect]) -> list[SurfaceDefect]:
        """The defects less the burrs and chips of a pore read as a hole: a rim defect at
        none of the part's holes (the bore scan's) that lies on a pore's outline (within
        its half length and ``pore_rim_reach_mm`` of its middle) is that pore's edge as a
        frame that took the pore for a hole read it (whole-surface part 91102: a 0.49 x
        0.44 mm pore, reported as one, and a 0.15 mm "burr" and a 0.26 mm "chip" 0.29 and
        0.25 mm off its middle). A rim defect at a hole the bore scan does not know (a hole
        drilled where the drawing has none) stays."""
        pores = [d for d in defects if d.kind == "pore"]
        out = []
        for d in defects:
            if self.family(d.kind) == "rim" and d.hole is None:
                on = next((p for p in pores if self.wall_mm((p.axial_mm, p.angle_deg), (d.axial_mm, d.angle_deg))
                           <= p.length_mm / 2.0 + self.cfg.pore_rim_reach_mm), None)
                if on is not None:
                    note = (f"surface: a {d.kind} at {d.axial_mm:.3f} mm, {d.angle_deg:.2f} deg, at none of the "
                            f"part's holes, lies on the outline of the {on.length_mm:.2f} mm pore at "
                            f"{on.axial_mm:.3f} mm, {on.angle_deg:.2f} deg (read as a hole in a frame): not reported")
                    self.notes.append(note)
                    continue
            out.append(d)
        return out

    # -------------------------------------------------------------- merging
    @staticmethod
    def family(kind: str) -> str:
        return "rim" if kind in SURFACE_RIM_KINDS else "wall"

    def merge(self, sightings: list[_Sighting]) -> list[list[_Sighting]]:
        """Sightings of one defect (within ``merge_mm`` plus half the longer's length of
        each other, the same family: wall or rim; a pore and a scratch within ``merge_mm``
        plus half the shorter's, or the pore within ``merge_mm`` of the scratch's chord:
        :meth:`on_chord`) as one group."""
        parent = list(range(len(sightings)))
        chords: dict[int, tuple] = {}  # a scratch sighting's chord ends, once each

        def root(i: int) -> int:
            return _root(parent, i)

        def on_scratch(i: int, j: int) -> bool:
            k, other = (i, j) if sightings[i].defect.kind == "scratch" else (j, i)
            if sightings[k].defect.kind != "scratch":
                return False
            if k not in chords:
                chords[k] = self.piece(sightings[k]).ends
            return self.on_chord(chords[k], sightings[other])

        for i, a in enumerate(sightings):
            for j in range(i):
                b = sightings[j]
                if self.family(a.defect.kind) != self.family(b.defect.kind):
                    continue
                la, lb = a.defect.length_mm or 0.0, b.defect.length_mm or 0.0
                same = a.defect.kind == b.defect.kind
                reach = self.cfg.merge_mm + 0.5 * (max(la, lb) if same else min(la, lb))
                if self.wall_mm((a.axial_mm, a.angle_deg), (b.axial_mm, b.angle_deg)) <= reach or \
                        (not same and on_scratch(i, j)):
                    parent[root(i)] = root(j)
        groups: dict[int, list[_Sighting]] = {}
        for i, s in enumerate(sightings):
            groups.setdefault(root(i), []).append(s)
        return list(groups.values())

    def on_chord(self, ends: tuple[tuple[float, float], tuple[float, float]], other: _Sighting) -> bool:
        """Whether ``other`` lies within ``merge_mm`` of a scratch's chord (``ends``: its
        places on the part; its end cut by a frame's border reads as a small pore there:
        whole-surface seed 24402)."""
        p0, p1 = ends
        v = self.wall_vec(p0, p1)
        w = self.wall_vec(p0, (other.axial_mm, other.angle_deg))
        t = float(np.clip((w @ v) / max(float(v @ v), 1e-12), 0.0, 1.0))
        return float(np.hypot(*(w - t * v))) <= self.cfg.merge_mm

    # -------------------------------------------------------------- scratches longer than a frame
    def wall_vec(self, a: tuple[float, float], b: tuple[float, float]) -> np.ndarray:
        """From place ``a`` to place ``b`` on the unrolled wall (mm: arc, axial)."""
        return np.array([math.radians(wrap_deg(b[1] - a[1])) * self.radius, b[0] - a[0]])

    def wall_path(self, origin: tuple[float, float], pts) -> np.ndarray:
        """Places along a piece (``pts``, in order) from ``origin`` on the unrolled wall
        (mm: arc, axial), unrolled along the piece: its first place the short way round
        from ``origin``, each next one from the one before. A piece near the far side of
        the bore from ``origin`` is not split by the seam there (its ends read 34 mm either
        side of it, and a piece half the bore away overlapped every other: whole-surface
        part 91101, a 23.6 mm scratch joined with a 1.5 mm one across the bore)."""
        pts = list(pts)
        out = [self.wall_vec(origin, pts[0])]
        for a, b in zip(pts[:-1], pts[1:]):
            out.append(out[-1] + self.wall_vec(a, b))
        return np.array(out)

    def off_wall(self, origin: tuple[float, float], v: np.ndarray) -> tuple[float, float]:
        """The place ``v`` (mm: arc, axial) from ``origin`` on the unrolled wall."""
        return origin[0] + float(v[1]), (origin[1] + math.degrees(float(v[0]) / self.radius)) % 360.0

    def piece(self, sg: _Sighting) -> _Piece:
        """A scratch's sighting as a segment on the part: its centre line's ends, each
        placed as a defect is (the line's own ends when the detector gives the line, else
        the centre +/- half its length along its direction), and the line's points."""
        d = sg.defect
        line_px = getattr(d, "line_px", None)
        if line_px is not None and len(line_px) >= 2:
            px = (tuple(line_px[0]), tuple(line_px[-1]))
        else:
            h = d.length_px / 2.0
            c, s_ = math.cos(math.radians(d.angle_deg)), math.sin(math.radians(d.angle_deg))
            px = ((d.x_px - h * c, d.y_px - h * s_), (d.x_px + h * c, d.y_px + h * s_))
            line_px = None
        b, w, hh = self.cfg.border_px, self.geo.width_px, self.geo.height_px
        cut = tuple(bool(getattr(d, "partial", False)) and (x <= b or y <= b or x >= w - 1 - b or y >= hh - 1 - b)
                    for x, y in px)
        line = None if line_px is None else tuple(self.place(sg.centre, float(x), float(y)) for x, y in line_px)
        return _Piece(sg, (self.place(sg.centre, *px[0]), self.place(sg.centre, *px[1])), px, cut, line)

    def width_mm(self, d) -> float:
        return float(d.width_mm if d.width_mm is not None else d.width_px * self.geo.mm_per_px)

    def misfit(self, p: _Piece, q: _Piece) -> tuple[float, float, float, float, float] | None:
        """How far two pieces are from being one bent furrow and how far they may be (mm),
        the share of the shorter that the two overlap along the furrow, and on which side
        of each (+1: along its chord's sense, -1: against) the other's middle lies; None
        when they cannot be one (one frame, neither cut, crossing, or apart along their
        direction by more than ``join_gap_mm``).

        A piece fixes its centre line's middle (a point on the bent line) and its chord's
        direction (the line's mean slope over the piece), not its ends across the line
        (they are off it by the piece's own bend). Along a smooth line the offset across
        between two middles is the distance along times the mean of the two slopes
        (exact for a parabola): the misfit is what the second middle lies off that, and a
        bend that is no parabola over the stretch adds ``join_bend_share`` of it."""
        if p.sighting.frame == q.sighting.frame:
            return None
        if not (getattr(p.sighting.defect, "partial", False) or getattr(q.sighting.defect, "partial", False)):
            return None
        cfg = self.cfg
        lens = 0.0 if self.lens is not None else cfg.join_lens_mm
        o = (p.sighting.axial_mm, p.sighting.angle_deg)
        vp, vq = self.wall_vec(*p.ends), self.wall_vec(*q.ends)
        lp, lq = float(np.hypot(*vp)), float(np.hypot(*vq))
        if lp <= 0.0 or lq <= 0.0:
            return None
        up, uq = vp / lp, vq / lq
        cos_turn = float(up @ uq)
        if math.degrees(math.acos(min(1.0, abs(cos_turn)))) > cfg.join_angle_deg:
            return None
        u = up + (uq if cos_turn >= 0.0 else -uq)
        u /= np.hypot(*u)
        n = np.array([-u[1], u[0]])
        tp = sorted(float(v @ u) for v in self.wall_path(o, p.ends))
        tq = sorted(float(v @ u) for v in self.wall_path(o, q.ends))
        if max(tq[0] - tp[1], tp[0] - tq[1]) > cfg.join_gap_mm + lens:
            return None
        mq = self.wall_vec(o, (q.sighting.axial_mm, q.sighting.angle_deg))
        dt = float(mq @ u)
        overlap = (min(tp[1], tq[1]) - max(tp[0], tq[0])) / max(min(lp, lq), 1e-9)
        sides = float(np.sign(dt * float(up @ u))), float(np.sign(-dt * float(uq @ u)))
        width = max(self.width_mm(p.sighting.defect), self.width_mm(q.sighting.defect))
        if p.line is not None and q.line is not None:
            lined = self.line_misfit(p, q, o, u, n)
            if lined is not None:
                misfit, gap = lined
                reach = cfg.join_offset_mm + width + lens + cfg.join_bend_share * gap
                return (misfit, reach, overlap) + sides
        slope_p, slope_q = float(vp @ n) / float(vp @ u), float(vq @ n) / float(vq @ u)
        misfit = float(mq @ n) - dt * 0.5 * (slope_p + slope_q)
        reach = cfg.join_offset_mm + width + lens + cfg.join_bend_share * abs(dt)
        return (misfit, reach, overlap) + sides

    def line_misfit(self, p: _Piece, q: _Piece, o: tuple[float, float], u: np.ndarray,
                    n: np.ndarray) -> tuple[float, float] | None:
        """Two pieces' centre lines (the detector's) against one furrow, along ``u``
        across ``n`` from ``o``: where they overlap along the furrow, the RMS of their
        offsets across it over the overlap; where they do not, how far the second's near
        end lies off the first's end continued across the gap at the mean of the two ends'
        slopes (over each line's last ~1 mm). Returns (misfit mm, gap mm), or None when a
        line does not run along ``u``."""
        lines = []
        for pc in (p, q):
            v = self.wall_path(o, pc.line)
            t, off = v @ u, v @ n
            if t[-1] < t[0]:
                t, off = t[::-1], off[::-1]
            if np.any(np.diff(t) <= 0.0):
                return None
            lines.append((t, off))
        (tp, op), (tq, oq) = lines
        lo, hi = max(tp[0], tq[0]), min(tp[-1], tq[-1])
        if hi - lo >= 0.05:
            ts = np.linspace(lo, hi, 25)
            d = np.interp(ts, tp, op) - np.interp(ts, tq, oq)
            return float(np.sqrt(np.mean(d * d))), 0.0
        if tp[-1] > tq[-1]:
            (tp, op), (tq, oq) = (tq, oq), (tp, op)  # p before q along u

        def end_slope(t: np.ndarray, off: np.ndarray, last: bool) -> float:
            sel = t >= t[-1] - 1.0 if last else t <= t[0] + 1.0
            if sel.sum() < 2:
                sel = np.zeros(t.size, bool)
                sel[[-2, -1] if last else [0, 1]] = True
            return float(np.polyfit(t[sel], off[sel], 1)[0])

        gap = float(tq[0] - tp[-1])
        slope = 0.5 * (end_slope(tp, op, True) + end_slope(tq, oq, False))
        return float(oq[0] - op[-1] - gap * slope), max(gap, 0.0)

    def scratch_components(self, sightings: list[_Sighting]) -> list[list[_Piece]]:
        """The scratch sightings as pieces, in sets that fit one furrow (:meth:`misfit`)
        across frames' borders: a lone piece is a set of its own."""
        pieces = [self.piece(sg) for sg in sightings
                  if sg.defect.kind == "scratch" and sg.centre is not None and sg.defect.length_px > 0]
        parent = list(range(len(pieces)))

        def root(i: int) -> int:
            return _root(parent, i)

        # a piece and another frame's view of the same stretch (overlapping by half the
        # shorter) are one; pieces that follow each other are joined only as each other's
        # best fit on the side they meet, so two parallel scratches a bend's allowance
        # apart, both cut by one border, are joined each to its own continuation
        best: dict[tuple[int, float], tuple[float, int]] = {}
        follow = []
        for i in range(len(pieces)):
            for j in range(i):
                r = self.misfit(pieces[i], pieces[j])
                if r is None or abs(r[0]) > r[1]:
                    continue
                misfit, reach, overlap, side_i, side_j = r
                if overlap >= 0.5:
                    parent[root(i)] = root(j)
                    continue
                score = abs(misfit) / reach
                for key, other in (((i, side_i), j), ((j, side_j), i)):
                    if key not in best or score < best[key][0]:
                        best[key] = (score, other)
                follow.append((i, j, side_i, side_j))
        for i, j, side_i, side_j in follow:
            if best[(i, side_i)][1] == j and best[(j, side_j)][1] == i:
                parent[root(i)] = root(j)
        comps: dict[int, list[_Piece]] = {}
        for i, pc in enumerate(pieces):
            comps.setdefault(root(i), []).append(pc)
        return list(comps.values())

    def join_scratches(self, sightings: list[_Sighting]) -> tuple[list[list[_Piece]], list[_Sighting]]:
        """Scratches longer than a frame: pieces that fit one furrow
        (:meth:`scratch_components`) as chains to measure joined, and the sightings left
        to merge. A chain that one frame saw whole (a whole piece as long as the chain)
        is left to the merge as any defect seen by overlapping frames."""
        chains, used = [], set()
        for comp in self.scratch_components(sightings):
            if len(comp) < 2:
                continue
            a, b, _ = self.chain_ends(comp)
            length = float(np.hypot(*self.wall_vec(a[0], b[0])))
            whole = max((float(np.hypot(*self.wall_vec(*pc.ends))) for pc in comp
                         if not getattr(pc.sighting.defect, "partial", False)), default=0.0)
            if whole >= length - max(0.05, 0.03 * length):
                continue
            chains.append(comp)
            used.update(id(pc.sighting) for pc in comp)
        return chains, [sg for sg in sightings if id(sg) not in used]

    def follow_scratches(self, sightings: list[_Sighting]):
        """Where a scratch leaves a frame and no neighbouring frame's piece continues it
        (an outer end of its pieces cut by a frame's border, inside the band), the
        neighbour lost it: a deep groove's residue across it, or a stretch that bends
        along the hatch, which the detector drops where the border cuts both its ends
        (``station.vision.defects``: a groove's piece at the border ends as square as a
        scratch's). A frame is taken centred on that end, where the scratch runs through
        the middle (with the stretch the coverage frame saw), and its scratches join the
        pieces; again from any end still cut, up to ``follow_rounds`` times. Returns the
        followed frames' sightings that joined a coverage frame's piece."""
        cfg = self.cfg
        lo, hi = self.plan.band_mm
        reach_mm = cfg.recentre_reach_px * self.geo.mm_per_px * 0.5
        extra: list[_Sighting] = []
        looked: list[tuple[float, float]] = []
        harvested: set[int] = set()
        for _ in range(cfg.follow_rounds):
            todo = []
            for comp in self.scratch_components(sightings + extra):
                if not any(any(pc.cut) for pc in comp):
                    continue
                (a, pa, ka), (b, pb, kb), _u = self.chain_ends(comp)
                for place, pc, k in ((a, pa, ka), (b, pb, kb)):
                    if not pc.cut[k] or min(abs(place[0] - lo), abs(place[0] - hi)) <= cfg.overlap_mm + 0.5:
                        continue  # a true end, or one where the scratch leaves the band
                    if any(self.wall_mm(place, q) <= reach_mm for q in looked + todo):
                        continue
                    todo.append(place)
            todo = todo[:max(cfg.follow_max_looks - len(looked), 0)]
            if not todo:
                break
            for place in todo:
                looked.append(place)
                look = yield from self.recentred_look(place, "surface scratch followed")
                idx = next(i for i, lk in enumerate(self.looks) if lk is look)
                if idx in harvested:
                    continue
                harvested.add(idx)
                centre = (look.axial_mm, look.angle_deg)
                cx, cy = self.geo.centre_px
                for d in look.defects:
                    if d.kind == "scratch" and d.length_px > 0:
                        ax, an = self.place(centre, d.x_px, d.y_px)
                        extra.append(_Sighting(d, ax, an, math.hypot(d.x_px - cx, d.y_px - cy), -1 - idx, centre))
        if not extra:
            return []
        # a followed frame's scratch counts only as a piece of one a coverage frame saw
        ours = {id(sg) for sg in extra}
        keep = set()
        for comp in self.scratch_components(sightings + extra):
            if any(id(pc.sighting) not in ours for pc in comp):
                keep.update(id(pc.sighting) for pc in comp if id(pc.sighting) in ours)
        if looked:
            self.notes.append(f"surface: {len(looked)} frame(s) taken to follow scratches that a frame's border cut "
                              f"and no neighbouring frame continued")
        return [sg for sg in extra if id(sg) in keep]

    def chain_ends(self, chain: list[_Piece]):
        """The chain's outer ends, each as (place, piece, which end), and the direction
        they are taken along (unit, mm: arc, axial; the pieces' length-weighted mean)."""
        o = chain[0].ends[0]
        acc = np.zeros(2)
        for pc in chain:  # directions as doubled angles: a piece's sense does not matter
            v = self.wall_vec(*pc.ends)
            ang = math.atan2(v[1], v[0])
            acc += np.hypot(*v) * np.array([math.cos(2 * ang), math.sin(2 * ang)])
        ang = 0.5 * math.atan2(acc[1], acc[0])
        u = np.array([math.cos(ang), math.sin(ang)])
        ends = [(float(self.wall_vec(o, e) @ u), pc, k) for pc in chain for k, e in enumerate(pc.ends)]
        lo, hi = min(ends, key=lambda t: t[0]), max(ends, key=lambda t: t[0])
        return (lo[1].ends[lo[2]], lo[1], lo[2]), (hi[1].ends[hi[2]], hi[1], hi[2]), u

    def end_recentred(self, end: tuple[float, float], direction: np.ndarray):
        """A joined scratch's end measured in a frame centred on it (no calibration: a
        coverage frame's piece ends at its border, where the lens moves it most): the
        scratch's end nearest ``end`` there, as (place, r_px, defect, end's px), or None."""
        cfg, geo = self.cfg, self.geo
        look = yield from self.recentred_look(end, "surface scratch end")
        cx, cy = geo.centre_px
        best = None
        for d in look.defects:
            if d.kind != "scratch" or d.length_px <= 0:
                continue
            pc = self.piece(_Sighting(d, look.axial_mm, look.angle_deg, 0.0, -1, (look.axial_mm, look.angle_deg)))
            v = self.wall_vec(*pc.ends)
            if abs(float(v @ direction)) / float(np.hypot(*v)) < math.cos(math.radians(cfg.join_angle_deg)):
                continue
            for k in (0, 1):
                if pc.cut[k]:
                    continue
                dist = self.wall_mm(pc.ends[k], end)
                r_px = math.hypot(pc.ends_px[k][0] - cx, pc.ends_px[k][1] - cy)
                if dist <= cfg.join_gap_mm + cfg.join_lens_mm and r_px <= cfg.recentre_reach_px \
                        and (best is None or dist < best[0]):
                    best = (dist, pc.ends[k], r_px, d, pc.ends_px[k])
        return None if best is None else best[1:]

    def recentred_look(self, place: tuple[float, float], why: str):
        """A frame centred on ``place`` (one taken within the re-centring reach serves)."""
        reach_mm = self.cfg.recentre_reach_px * self.geo.mm_per_px * 0.5
        look = next((lk for lk in self.looks if self.wall_mm((lk.axial_mm, lk.angle_deg), place) <= reach_mm), None)
        if look is None:
            yield m.Checkpoint(why)
            centre = yield from self.move(*place)
            _image, found = yield from self.frame(centre)
            look = _Look(centre[0], centre[1], found)
            self.looks.append(look)
        return look

    def middle_recentred(self, middle: tuple[float, float], direction: np.ndarray):
        """A joined scratch's middle read in a frame centred on it: the furrow's offset
        across ``direction`` at ``middle``, from the piece of it that passes there (its
        reported point lies on its bent centre line, near the frame's centre), or None."""
        cfg, geo = self.cfg, self.geo
        look = yield from self.recentred_look(middle, "surface scratch middle")
        cx, cy = geo.centre_px
        n = np.array([-direction[1], direction[0]])
        best = None
        for d in look.defects:
            if d.kind != "scratch" or d.length_px <= 0 or math.hypot(d.x_px - cx, d.y_px - cy) > cfg.recentre_reach_px:
                continue
            pc = self.piece(_Sighting(d, look.axial_mm, look.angle_deg, 0.0, -1, (look.axial_mm, look.angle_deg)))
            v = self.wall_vec(*pc.ends)
            along = float(v @ direction)
            if abs(along) / float(np.hypot(*v)) < math.cos(math.radians(cfg.join_angle_deg)):
                continue
            p = self.wall_vec(middle, self.place((look.axial_mm, look.angle_deg), d.x_px, d.y_px))
            at_middle = p - v * (float(p @ direction) / along)  # along the piece to the middle's place
            off = float(at_middle @ n)
            if abs(off) <= cfg.join_offset_mm + self.width_mm(d) + cfg.join_lens_mm and \
                    (best is None or abs(off) < abs(best)):
                best = off
        return None if best is None else self.off_wall(middle, best * n)

    def measure_joined(self, chain: list[_Piece]):
        """One scratch from its pieces: its centre line (:meth:`centre_line`) between the
        chain's outer ends, its length along that line, its place the line's middle (as
        the detector places a whole scratch), its width the pieces' length-weighted mean.
        Without the lens's calibration each outer end and the middle are read again
        re-centred."""
        cfg, geo, st = self.cfg, self.geo, self.settings
        s = geo.mm_per_px
        (a, pa, ka), (b, pb, kb), u = self.chain_ends(chain)
        ends = []
        for place, pc, k in ((a, pa, ka), (b, pb, kb)):
            d = pc.sighting.defect
            x, y = pc.ends_px[k]
            cx, cy = geo.centre_px
            r_px = math.hypot(x - cx, y - cy)
            if self.lens is None and not pc.cut[k] and r_px > cfg.recentre_reach_px:
                again = yield from self.end_recentred(place, u)
                if again is not None:
                    place, r_px, d, (x, y) = again
            # the end's own share of the piece's length u: the detector's u less its term
            # for a whole scratch's bend and fading (a share of its length), halved; and
            # the end's model term (an end that fades into a groove)
            share = DefectConfig.scratch_length_u_share * d.length_px
            u_end_px = math.sqrt(max(d.length_u_px ** 2 - share ** 2, 0.0) / 2.0)
            ends.append((place, math.sqrt((u_end_px * s) ** 2 + cfg.join_end_u_mm ** 2
                                          + self.point_u(x, y, r_px) ** 2), pc.cut[k]))
        (a, ua, cut_a), (b, ub, cut_b) = ends
        chord = self.wall_vec(a, b)
        length = float(np.hypot(*chord))
        e = chord / max(length, 1e-9)
        n = np.array([-e[1], e[0]])
        line = self.centre_line(chain, a, e, length)
        traced = line.length()
        place = self.off_wall(a, (0.5 * length) * e + line.offset(0.5 * length) * n)
        if self.lens is None:
            # the pieces' chords carry the lens's distortion across the furrow (up to
            # ~0.1 mm off a frame's centre): its middle is read again re-centred
            again = yield from self.middle_recentred(place, e)
            if again is not None:
                place = again
        weights = [float(np.hypot(*self.wall_vec(*pc.ends))) for pc in chain]
        widths = [self.width_mm(pc.sighting.defect)
                  * self.local_scale(pc.sighting.defect.x_px, pc.sighting.defect.y_px,
                                     float(pc.sighting.defect.angle_deg) + 90.0, pc.sighting.defect.width_px / 2.0)
                  for pc in chain]
        width = float(np.average(widths, weights=weights)) if sum(weights) > 0 else float(np.mean(widths))
        # the place: its ends' and the centroid's own term of a whole scratch of that
        # length (:meth:`defect`)
        u_centroid = cfg.centroid_u_px * s + cfg.centroid_u_share * length
        u_pos = 2.0 * math.sqrt(u_centroid ** 2 + (ua ** 2 + ub ** 2) / 4.0) + st.evidence_bound_um * 1e-3
        frames = len({pc.sighting.frame for pc in chain})
        lo, hi = self.plan.band_mm
        if any(cut and min(abs(end[0] - lo), abs(end[0] - hi)) <= cfg.overlap_mm + 0.5
               for end, cut in ((a, cut_a), (b, cut_b))):
            self.notes.append(f"a scratch at {place[0]:.3f} mm, {place[1]:.2f} deg runs out of the scanned band: "
                              f"its length ({traced:.3f} mm, joined over {frames} frames) is what the band shows")
        axial = place[0] * (1.0 - st.part_scale_ppm * 1e-6)
        zone = self.part.surface_zone(axial)
        conf = max(float(pc.sighting.defect.confidence) for pc in chain)
        # the length's U: its ends', and half what the bend adds to the chord (the pieces'
        # chords trace the bend only between them)
        size_u = math.sqrt(ua ** 2 + ub ** 2 + (0.5 * (traced - length)) ** 2)
        return SurfaceDefect("", "scratch", axial, place[1], traced, width, 2.0 * size_u,
                             u_pos, conf, zone=None if zone is None else zone.id, frames=frames)

    def centre_line(self, chain: list[_Piece], a: tuple[float, float], e: np.ndarray, length: float) -> "_CentreLine":
        """The scratch's centre line as its offset across the chord ``a`` + t ``e`` (0 <= t
        <= ``length``): a polynomial (cubic from three pieces, else quadratic) fitted by
        least squares to what each piece fixes: its reported middle (a point on its bent
        centre line) and its chord's direction (the line's mean slope over the piece). Not
        its ends: a piece's end is its middle +/- half its length along its chord, off the
        line across by the piece's own bend (up to ~0.15 mm on a 10 mm piece); along the
        chord they are right, and give the line's extent."""
        n = np.array([-e[1], e[0]])
        rows, rhs = [], []
        if all(pc.line is not None for pc in chain):
            # the detector's centre lines: a polynomial of degree 5 through their points
            # (a dragged chip's path bends in up to two modes, an S included, over the
            # whole chain)
            pts = np.array([self.wall_vec(a, pt) for pc in chain for pt in pc.line])
            t, off = pts @ e, pts @ n
            deg = int(min(5, max(len(pts) - 1, 0)))
            line = _CentreLine(length, np.zeros(deg + 1))
            basis = np.array([line.basis(float(x)) for x in t])
            coef, *_ = np.linalg.lstsq(basis, off, rcond=None)
            return _CentreLine(length, coef)
        deg = 3 if len(chain) >= 3 else 2
        line = _CentreLine(length, np.zeros(deg + 1))

        def add(row: np.ndarray, value: float, sd: float) -> None:
            rows.append(row / sd)
            rhs.append(value / sd)

        s = self.geo.mm_per_px
        for pc in chain:
            d = pc.sighting.defect
            mid = self.wall_vec(a, (pc.sighting.axial_mm, pc.sighting.angle_deg))
            v = self.wall_vec(*pc.ends)
            if float(v @ e) < 0.0:
                v = -v
            h = 0.5 * float(v @ e)
            t = float(mid @ e)
            add(line.basis(t), float(mid @ n), 0.01 + 0.5 * self.width_mm(d) / max(d.length_px * s, 1e-6))
            if h > 0.05:
                add((line.basis(t + h) - line.basis(t - h)) / (2.0 * h), float(v @ n) / float(v @ e), 0.001 + 0.02 / h)
        a_rows = np.asarray(rows)
        deg = min(deg, a_rows.shape[0] - 1)  # no more terms than what fixes them
        coef, *_ = np.linalg.lstsq(a_rows[:, :deg + 1], np.asarray(rhs), rcond=None)
        return _CentreLine(length, coef)

    def point_u(self, x_px: float, y_px: float, r_px: float) -> float:
        """Standard uncertainty (mm) of an image point placed on the part, beside its own
        scatter: the model at the detection point, the scale over the offset, and the
        lens: beyond the re-centring reach without a calibration its distortion (k1 r^3 /
        f^2 of the endoscope, up to 2.7 % of the offset) as a rectangular bound; with one,
        the calibration map's own error."""
        geo, cfg, st = self.geo, self.cfg, self.settings
        s = geo.mm_per_px
        u_model = st.model_u_um * 1e-3
        u_scale = geo.scale_u_rel * r_px * s
        u_lens = 0.0 if r_px <= cfg.recentre_reach_px or self.lens is not None \
            else 0.027 * (r_px * s) * (r_px / 820.0) ** 2 / math.sqrt(3)
        u_map = 0.0
        if self.lens is not None:
            mu = self.lens.undistort_u_px(np.array([[x_px, y_px]], np.float64))
            u_map = 0.0 if mu is None else float(np.max(mu)) * s
        return math.sqrt(u_model ** 2 + u_scale ** 2 + u_lens ** 2 + u_map ** 2)

    @staticmethod
    def best(group: list[_Sighting]) -> _Sighting:
        """The sighting to trust most: whole, then nearest its frame's centre."""
        return min(group, key=lambda s: (bool(getattr(s.defect, "partial", False)), s.r_px))

    def route(self, groups: list[list[_Sighting]]) -> list[list[_Sighting]]:
        """The groups in the order of a short path (nearest next, from the scan's end)."""
        left = list(groups)
        here = (self.plan.axials_mm[-1], self.c_now % 360.0)
        out = []
        while left:
            g = min(left, key=lambda g: self.wall_mm(here, (self.best(g).axial_mm, self.best(g).angle_deg)))
            left.remove(g)
            out.append(g)
            here = (self.best(g).axial_mm, self.best(g).angle_deg)
        return out

    # -------------------------------------------------------------- re-centred measurement
    def measure(self, group: list[_Sighting]):
        """The group's defects measured in a frame centred on them (one taken for a
        defect near enough serves), as :class:`SurfaceDefect` objects: every defect of the
        group's family that frame shows whole near one of the group's sightings (defects
        closer than the merging distance are told apart there). The best sighting's own
        figures when the re-centred frame shows none; no re-centring when a coverage
        frame saw the group's only defect whole near its centre. Nothing when the group was
        seen only cut by frames' borders and the re-centred frame shows nothing of its
        family there (a mark the border made)."""
        cfg, geo = self.cfg, self.geo
        best = self.best(group)
        want = (best.axial_mm, best.angle_deg)
        frames = len({s.frame for s in group})
        per_frame = max(sum(1 for s in group if s.frame == f) for f in {s.frame for s in group})
        whole = [sg for sg in group if not getattr(sg.defect, "partial", False)]
        if per_frame == 1 and best.r_px <= cfg.recentre_reach_px and not getattr(best.defect, "partial", False):
            # a coverage frame saw it centred; its size from every frame that saw it whole
            return [self.pooled(self.defect(best.defect, want, best.r_px, frames), whole)]
        if self.lens is not None and not (per_frame == 1 and len(whole) >= 2 and not self.agree(whole)):
            # calibrated: the coverage frame that saw most of the group whole, nearest its
            # centre; every whole defect of the group in it (a pair too close to merge apart).
            # Not when the frames that saw one defect whole, off their centres, read sizes
            # that disagree (``agree``): one frame lost an end or took a groove's stretch in,
            # and a frame centred on it reads it where the wall is best lit and the lens
            # least distorting (seed 88001: a 0.95 mm scratch read 0.80 and 0.93 mm in two
            # frames' corners; the more significant was the shorter)
            if whole:
                by_frame: dict[int, list[_Sighting]] = {}
                for sg in whole:
                    by_frame.setdefault(sg.frame, []).append(sg)
                chosen = min(by_frame.values(), key=lambda v: (-len(v), min(sg.r_px for sg in v)))
                out = [self.defect(sg.defect, (sg.axial_mm, sg.angle_deg), sg.r_px, frames) for sg in chosen]
                if per_frame == 1:
                    out = [self.pooled(out[0], whole)]  # one defect: its size from every whole sighting
                return out
        look = yield from self.recentred_look(want, "surface defect")
        fam = self.family(best.defect.kind)
        cx, cy = geo.centre_px

        def near_group(p: tuple[float, float]) -> bool:
            return any(self.wall_mm(p, (sg.axial_mm, sg.angle_deg)) <= max(0.15, 0.5 * (sg.defect.length_mm or 0.0))
                       for sg in group)

        out = []
        for d in look.defects:
            if self.family(d.kind) != fam or getattr(d, "partial", False):
                continue
            r_px = math.hypot(d.x_px - cx, d.y_px - cy)
            if r_px > cfg.recentre_reach_px:
                continue
            p = self.place((look.axial_mm, look.angle_deg), d.x_px, d.y_px)
            if near_group(p):
                out.append(self.defect(d, p, r_px, frames))
        if not out:
            d = best.defect
            centre = (look.axial_mm, look.angle_deg)

            def shows(e) -> bool:
                # at the group's place: its point, or a scratch's chord passing there
                if near_group(self.place(centre, e.x_px, e.y_px)):
                    return True
                if e.kind != "scratch" or not e.length_px:
                    return False
                ends = self.piece(_Sighting(e, *self.place(centre, e.x_px, e.y_px), 0.0, -1, centre)).ends
                return any(self.on_chord(ends, sg) for sg in group)

            shown = {e.kind for e in look.defects if self.family(e.kind) == fam and shows(e)}
            only_cut = all(getattr(sg.defect, "partial", False) for sg in group)
            if only_cut and not shown:
                # seen only where frames' borders cut it, and a frame centred on it shows nothing
                # there: the border's cut, not a defect (a crossing of deep grooves cut by a
                # frame's top edge at its corner read as a 0.33 mm pore: whole-surface part 24703)
                self.notes.append(f"a {d.kind} at {want[0]:.3f} mm, {want[1]:.2f} deg, seen only cut by frames' "
                                  f"borders ({best.r_px:.0f} px off a frame's centre), was not seen in a frame "
                                  f"centred on it: not reported")
                return []
            if only_cut and d.kind != "scratch" and shown == {"scratch"}:
                # ... or shows only a scratch passing there, longer than the frame: the mark
                # was that scratch's end cut by a border (whole-surface part 90103: a 0.15 mm
                # "pore" at a frame's left border on a 22.7 mm scratch's line, which its
                # chain measured)
                self.notes.append(f"a {d.kind} at {want[0]:.3f} mm, {want[1]:.2f} deg, seen only cut by frames' "
                                  f"borders ({best.r_px:.0f} px off a frame's centre), is a scratch's stretch in a "
                                  f"frame centred on it: not reported apart")
                return []
            self.notes.append(f"a {d.kind} at {want[0]:.3f} mm, {want[1]:.2f} deg was not seen again re-centred: "
                              f"measured {best.r_px:.0f} px off a frame's centre (the lens's distortion not corrected)")
            out.append(self.defect(d, want, best.r_px, frames))
        return out

    def sizes(self, d) -> tuple[float, float, float, float]:
        """A sighting's length and width on the wall (mm) with their standard
        uncertainties: the detector's, through the lens's local scale where the lens is
        calibrated."""
        s = self.geo.mm_per_px
        length = float(d.length_mm if d.length_mm is not None else d.length_px * s)
        width = float(d.width_mm if d.width_mm is not None else d.width_px * s)
        size_u = float(d.size_u_mm if d.size_u_mm is not None else d.length_u_px * s)
        width_u = float(d.width_u_mm if d.width_u_mm is not None else d.width_u_px * s)
        if self.lens is not None:
            # the lens's local scale along the length and across it (a rim defect: both
            # ways; its angle is round its hole)
            along = None if self.family(d.kind) == "rim" else float(d.angle_deg)
            k_len = self.local_scale(d.x_px, d.y_px, along, d.length_px / 2.0)
            k_wid = self.local_scale(d.x_px, d.y_px, None if along is None else along + 90.0, d.width_px / 2.0)
            length, width, size_u, width_u = length * k_len, width * k_wid, size_u * k_len, width_u * k_wid
        return length, width, size_u, width_u

    def agree(self, sightings: list[_Sighting]) -> bool:
        """Whether readings of one defect's length from several frames agree: their Birge
        ratio (:meth:`pooled`) within ``cfg.pool_birge_max``."""
        rows = np.array([self.sizes(sg.defect) for sg in sightings], float)
        return _birge(rows[:, 0], rows[:, 2])[2] <= self.cfg.pool_birge_max

    def pooled(self, out: SurfaceDefect, sightings: list[_Sighting]) -> SurfaceDefect:
        """One defect seen whole in several frames (``sightings``, one each), sized from
        all of them. Each frame reads it with its own noise and, off its centre, its own
        vignetting and wall: on the whole-surface bench (seed 25601) a 0.086 mm pore read
        0.060 mm (significance 8.8) in the frame nearest its centre and 0.093 mm (23.5)
        in the other, and the scan reported the first.

        - Readings that agree (their lengths within ``cfg.pool_birge_max`` of what their
          own uncertainties allow: the Birge ratio) are pooled: length and width the
          means weighted by their inverse variances, the length's uncertainty the mean's,
          widened by the Birge ratio where it is over 1.
        - Readings that do not are not one quantity read twice: a frame may have read a
          piece of a scratch whole, or a pore with a groove's stretch (seed 24804: a 1.65
          mm scratch pooled with a shorter reading came out 0.31 mm short). The reading
          with the most evidence (its significance) is taken, as it was read.

        The place stays the chosen reading's (nearest its frame's centre: the lens's
        residual)."""
        if len(sightings) < 2:
            return out
        rows = np.array([self.sizes(sg.defect) for sg in sightings], float)
        length, u_len, birge = _birge(rows[:, 0], rows[:, 2])
        if birge > self.cfg.pool_birge_max:
            k = max(range(len(sightings)), key=lambda i: float(getattr(sightings[i].defect, "significance", 0.0)))
            return replace(out, length_mm=float(rows[k, 0]), width_mm=float(rows[k, 1]),
                           size_u_mm=2.0 * float(rows[k, 2]))
        width, _, _ = _birge(rows[:, 1], rows[:, 3])
        return replace(out, length_mm=length, width_mm=width, size_u_mm=2.0 * u_len)

    def defect(self, d, place: tuple[float, float], r_px: float, frames: int) -> SurfaceDefect:
        geo, cfg, st = self.geo, self.cfg, self.settings
        s = geo.mm_per_px
        length, width, size_u, _ = self.sizes(d)
        # the place: the centroid's own scatter, and the point's (:meth:`point_u`)
        u_centroid = cfg.centroid_u_px * s + cfg.centroid_u_share * length
        u_pos = 2.0 * math.sqrt(u_centroid ** 2 + self.point_u(d.x_px, d.y_px, r_px) ** 2) + st.evidence_bound_um * 1e-3
        axial = place[0] * (1.0 - st.part_scale_ppm * 1e-6)
        hole = None
        if self.family(d.kind) == "rim":
            near = [(self.wall_mm((h.position_mm, h.angle_deg), place), h) for h in self.holes]
            near = [(dist, h) for dist, h in near if dist <= h.diameter_mm / 2.0 + 0.3]
            if near:
                hole = min(near, key=lambda t: t[0])[1].name
        zone = self.part.surface_zone(axial)
        return SurfaceDefect("", d.kind, axial, place[1] % 360.0, length, width, 2.0 * size_u, u_pos,
                             float(d.confidence), hole=hole, zone=None if zone is None else zone.id, frames=frames)


def _birge(values: np.ndarray, us: np.ndarray) -> tuple[float, float, float]:
    """Readings ``values`` of one quantity with their standard uncertainties ``us``:
    the mean weighted by their inverse variances, its uncertainty (widened by the Birge
    ratio where that is over 1), and the Birge ratio (their scatter over what their own
    uncertainties allow; a reading's uncertainty is never taken below 0.1 um)."""
    w = 1.0 / np.maximum(us, 1e-4) ** 2
    m = float(np.sum(w * values) / np.sum(w))
    birge = math.sqrt(float(np.sum(w * (values - m) ** 2)) / (values.size - 1))
    return m, max(birge, 1.0) / math.sqrt(float(np.sum(w))), birge


def _measuring_on_the_way(move, pending, done: list, analyse):
    """Run the ``move`` plan, and while its axes travel (after its moves are sent, before
    its first wait) analyse the ``pending`` frame (k, centre, image) with ``analyse``
    (image, centre: a plan whose value is its defects); they go to ``done`` as (k,
    centre, defects). The vision stage then costs no machine time of its own while there
    is a move to hide it in."""
    try:
        msg = next(move)
        while True:
            if pending is not None and isinstance(msg, m.Wait):
                done.append((pending[0], pending[1], (yield from analyse(pending[2], pending[1]))))
                pending = None
            reply = yield msg
            msg = move.send(reply)
    except StopIteration as stop:
        if pending is not None:  # nothing moved: analyse it now
            done.append((pending[0], pending[1], (yield from analyse(pending[2], pending[1]))))
        return stop.value


def camera_blur(holes: list[HoleResult]) -> tuple[float | None, int]:
    """The camera's blur (Gaussian sigma, px) as the bore scan read it: the median of
    ``camera_blur_from_edge`` over every measurement frame of the found ``holes`` whose
    vision stage gave the hole's edge width (``FrameObservation.edge_sigma_px``), and how
    many frames that is; (None, 0) when none did (the blur is then not invented: each
    frame's detection reads it itself).

    Why: the blur is the camera's (the same optics at the same distance to the wall in
    every frame of an inspection), but most coverage frames show no hole to read it from,
    and a small pore's size trades off against the blur its own fit finds (``station
    bench surface``: a 0.085 mm pore read 0.050 mm wide, true 0.076, with the blur free;
    0.090 x 0.072 mm with the camera's 1.2 px given)."""
    blurs = [camera_blur_from_edge(float(e)) for h in holes if h.found for o in h.frames
             if (e := getattr(o, "edge_sigma_px", None)) is not None and math.isfinite(e)]
    return (float(np.median(blurs)) if blurs else None), len(blurs)


def physical_limit(band_mm: tuple[float, float], geo: CameraGeometry, overlap_mm: float, camera,
                   c_limits: AxisLimits, settle_s: float) -> dict:
    """The least machine time any stop-and-shoot coverage of the band could take with
    this camera and table: the fewest frames that cover it (:func:`coverage_plan`: rings
    of the frame's height, columns of its width, overlapping by what the largest pore
    needs), each exposed still; between frames the table turns one column at its limits
    (Z's step between rings rides along that move) and the slide settles; the readout
    and the vision stage overlap the moves. ``{"frames", "limit_s"}``."""
    from station.motion import move_time_s

    plan = coverage_plan(band_mm, geo, overlap_mm)
    n, cols = plan.frames, len(plan.angles_deg)
    t_move = move_time_s(360.0 / cols, c_limits) if cols > 1 else 0.0
    return {"frames": n, "limit_s": n * camera.exposure_s + (n - 1) * (t_move + settle_s)}


def surface_scan(model: StationModel, part: PartSpec, geo: CameraGeometry, settings: ScanSettings,
                 holes: list[HoleResult], *, motion: Mapping[str, AxisLimits] | None = None,
                 cfg: SurfaceSettings | None = None, findings=()):
    """The coverage scan of ``part``'s surface band (a plan; returns a
    :class:`~station.inspection.surface.SurfaceResult`). ``holes``: the bore scan's
    results, to put burrs and chips at their holes; ``findings``: its findings
    (``ScanFinding``), whose unexpected holes the notes name where a pore of a hole's
    size is reported."""
    if part.surface is None:
        raise ValueError(f"{part.part_number} has no [surface] table: nothing to scan")
    if not settings.compensated:
        model = model.without_errors()
    return (yield from _SurfaceScan(model, part, geo, settings, cfg or SurfaceSettings(), motion, holes,
                                    findings).run())
