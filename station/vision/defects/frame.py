"""The whole frame: the holes measured first, the wall modelled, each candidate examined
at full resolution as a pore or a scratch, and every hole's rim judged for burrs and
chips (``detect_defects``).

Part of ``station.vision.defects`` (its docstring tells the method).
"""

from __future__ import annotations

from dataclasses import asdict, replace
from typing import NamedTuple
import math
import warnings

import cv2
import numpy as np

from station.vision.imageio import to_8bit, to_grey
from station.vision.defects.config import Defect, DefectConfig, GROUP_DOMINANT_SHARE
from station.vision.defects.common import circ_diff_deg, is_along_hatch, near_hatch, on_groove_line
from station.vision.defects.wall import (
    line_band, find_candidates, split_furrows, group_collinear, groove_stretches, hole_zone, line_runs_on, model_wall,
    line_through_blob, one_furrow, seed_in_box, stretch_darkness,
)
from station.vision.defects.rims import grow_by_skirt, hole_blur, marks_mask, rim_blur, rim_defects
from station.vision.defects.scratches import BLUR_PRIOR_PX
from station.vision.defects.examine import examine_candidate, ExaminedCandidate, KnownBlur, shared_blur
from station.vision.defects.tracking import (
    drop_scratch_pieces, join_scratch_pieces, line_points, measured_again, track_scratches,
)


def _coarse_discs(img: np.ndarray, mm_per_px: float) -> list:
    """The holes' coarse stage at this scale (``detect_candidates``): the dark discs the
    rims' holes (``_measure_holes_for_rims``) and the marks of a hole's size
    (``_dark_discs``) are read from, found once for both."""
    from station.vision.detect import detect_candidates, for_scale
    from station.vision.measure import MeasureConfig

    return list(detect_candidates(img, for_scale(MeasureConfig().detect, mm_per_px)))


def _measure_holes_for_rims(img: np.ndarray, mm_per_px: float, cfg: DefectConfig, coarse=None) -> list:
    """The frame's holes, as ``measure_holes`` measures them, and those it drops because
    their rim is no clean disc: a large burr or chip makes the photometric fit run away
    (``MeasureConfig.reject_unfitted_whole``), and such a hole, unmeasured, would be taken
    for a 0.7 mm pore (dev frames: a hole with two burrs of 0.2-0.3 mm). Those are
    measured by their rays alone (robust circle, Tukey weights: the defects are its
    outliers), which is all the rim analysis needs. ``coarse``: the coarse stage's discs
    (``_coarse_discs``) if already found."""
    from station.vision.detect import for_scale
    from station.vision.measure import MeasureConfig, measure_candidate, measure_holes

    # the rims need no grain-aware step: the weighted fit places them well within a px
    holes = list(measure_holes(img, mm_per_px, cfg=MeasureConfig(gls_steps=0)))
    rays_only = MeasureConfig(photometric=None, min_inlier_fraction=cfg.rim_hole_min_inlier_fraction,
                              min_confidence=cfg.rim_hole_min_confidence)
    rays_only = replace(rays_only, detect=for_scale(rays_only.detect, mm_per_px))
    for cand in (_coarse_discs(img, mm_per_px) if coarse is None else coarse):
        if 2.0 * cand.radius_px * mm_per_px < cfg.rim_hole_coarse_share * cfg.min_hole_diameter_mm:
            continue  # too small to be a hole, even as a coarse blob that rim defects cut into
        if any(np.hypot(cand.x_px - h.x_px, cand.y_px - h.y_px) < h.diameter_px / 2 for h in holes):
            continue
        m = measure_candidate(img, cand, rays_only)
        if m is None or m.diameter_px * mm_per_px < cfg.min_hole_diameter_mm:
            continue
        if _dark_disc_share(img, m) >= cfg.rim_hole_min_dark_share:
            holes.append(m)
    return holes


def _dark_discs(img: np.ndarray, mm_per_px: float, cfg: DefectConfig,
                coarse=None) -> list[tuple[float, float, float]]:
    """The frame's dark discs of a hole's size or more, as the holes' coarse stage finds
    them (``detect_candidates`` over the holes' range at this scale, and the
    ``oversized_discs`` beyond it; from ``cfg.stray_disc_min_share`` of the least hole's
    diameter): (x_px, y_px, diameter_px) each. Unmeasured: what a
    dark mark at none of the part's holes needs is its size, for the wall's level to
    reach past it (``detect_defects``). ``coarse``: as ``_measure_holes_for_rims``'."""
    from station.vision.detect import for_scale, oversized_discs
    from station.vision.measure import MeasureConfig

    if coarse is None:
        coarse = _coarse_discs(img, mm_per_px)
    smallest = cfg.stray_disc_min_share * cfg.min_hole_diameter_mm / mm_per_px
    wide = list(oversized_discs(img, for_scale(MeasureConfig().detect, mm_per_px)))
    return [(c.x_px, c.y_px, 2.0 * c.radius_px) for c in list(coarse) + wide if 2.0 * c.radius_px >= smallest]


def _dark_disc_share(img: np.ndarray, hole) -> float:
    """The share of ``hole``'s disc inside its rim's blur (radius R - 2 blur - 1 px) that
    is darker than midway between the ring beyond its rim (3 blur + 1 px to 3 blur + 9
    px out, its median) and the disc's darkest tenth; the frame's pixels only. 1 for a
    hole that is all dark inside; a dark blob that fills a part of the circle its rays
    agree on reads that part."""
    r_hole = hole.diameter_px / 2.0
    blur = rim_blur(hole)
    reach = r_hole + 3.0 * blur + 9.0
    x0, x1 = max(int(np.floor(hole.x_px - reach)), 0), min(int(np.ceil(hole.x_px + reach)) + 1, img.shape[1])
    y0, y1 = max(int(np.floor(hole.y_px - reach)), 0), min(int(np.ceil(hole.y_px + reach)) + 1, img.shape[0])
    if x1 <= x0 or y1 <= y0:
        return 0.0
    yy, xx = np.mgrid[y0:y1, x0:x1]
    r = np.hypot(xx - hole.x_px, yy - hole.y_px)
    patch = img[y0:y1, x0:x1].astype(np.float64)
    disc = patch[r < r_hole - 2.0 * blur - 1.0]
    ring = patch[(r > r_hole + 3.0 * blur + 1.0) & (r < reach)]
    if disc.size < 20 or ring.size < 20:
        return 1.0  # too little seen to judge: the circle's rays decide alone
    mid = 0.5 * (float(np.median(ring)) + float(np.percentile(disc, 10.0)))
    return float(np.mean(disc < mid))


def detect_defects(image: np.ndarray, mm_per_px: float, *, holes=None, blur_px: float | None = None,
                   hole_places=None, cfg: DefectConfig = DefectConfig()) -> list[Defect]:
    """Pores, scratches, burrs and chips of one grey (or BGR) frame of 8 or 16 bits.

    ``mm_per_px``: the scale at the wall (sizes in mm, and which dark discs are holes).
    ``holes``: the frame's holes (``HoleMeasurement``) if already measured; None
    measures them (``measure_holes``). Holes smaller than ``cfg.min_hole_diameter_mm``
    are not holes but dark marks, and are judged as such.
    ``blur_px``: the camera's blur (Gaussian sigma, px) if known (a calibration's MTF, or
    what the coverage scan read at the holes' edges in the bore scan,
    :func:`camera_blur_from_edge`); otherwise it is read from the frame's holes' edges,
    else from each scratch itself (its mean cross profile, its ends and a prior,
    ``_scratch_blur``) and each pore's own fit, and then from the frame's scratches
    together (``shared_blur``), under which the frame is examined again (what only the
    first examination found stays): a thin scratch's width is
    fixed only as well as the blur is known (its cross profile is the blur's, widened by
    w^2/12), and a small pore's size trades off against its blur (a 0.085 x 0.076 mm
    pore read 0.050 mm wide with the blur free, 0.090 x 0.072 mm with 1.2 px given:
    ``station bench surface``). (A pore's fitted edge blur was tried as a third
    source and dropped: its ragged outline reads as extra blur, up to 3 px on dev frames.)
    Given, it stands for the blur everywhere but at the rims, which each read their own
    hole's (``rim_defects``).
    ``hole_places``: where the part's holes may show in this frame, as (x_px, y_px,
    reach_px) (the whole-surface scan knows them from the bore scan); a dark disc the size
    of a hole whose centre is within reach of none is no hole of the part but a dark mark
    (a pore over the holes' smallest size, or a stray drilling), and is examined as one;
    its rim is not judged for burrs and chips. None: every dark disc of a hole's size is a
    hole (a frame alone does not say which are the part's).
    Sorted by y then x.
    """
    if not (mm_per_px and mm_per_px > 0):
        raise ValueError("mm_per_px must be positive")
    img = to_8bit(to_grey(image))
    # the holes' coarse stage, once for the rims' holes and the marks of a hole's size
    coarse = _coarse_discs(img, mm_per_px) if holes is None and hole_places is not None else None
    if holes is None:
        holes = _measure_holes_for_rims(img, mm_per_px, cfg, coarse)
    holes = [h for h in holes if h.diameter_px * mm_per_px >= cfg.min_hole_diameter_mm]
    largest_mark_px = cfg.min_hole_diameter_mm / mm_per_px
    if hole_places is not None:
        places = [(float(x), float(y), float(r)) for x, y, r in hole_places]

        def at_a_hole(x: float, y: float) -> bool:
            return any(math.hypot(x - px, y - py) <= r for px, py, r in places)

        # a dark disc at none of the part's holes is a mark: the wall's level must reach
        # past the largest of them, as past a pore (a 1.15 mm one, under a level that
        # followed it, read a floor from -0.08 to 0.55 of the wall's darkness and was lost)
        stray = [(h.x_px, h.y_px, h.diameter_px) for h in holes if not at_a_hole(h.x_px, h.y_px)]
        stray += [(x, y, d) for x, y, d in _dark_discs(img, mm_per_px, cfg, coarse) if not at_a_hole(x, y)]
        holes = [h for h in holes if at_a_hole(h.x_px, h.y_px)]
        largest_mark_px = max([largest_mark_px] + [cfg.stray_disc_reach * d for _, _, d in stray])
        if stray:  # each is a cavity whatever its outline: not judged by the floor test
            cfg = replace(cfg, floor_test_exempt=tuple(stray))
    # the wall model leaves out each hole and the band its rim defects may occupy
    reach_px = cfg.rim_reach_mm / mm_per_px + 6.0
    wall = model_wall(img, holes, reach_px, cfg, largest_mark_px=largest_mark_px)
    zone = hole_zone(img.shape, holes, reach_px)
    hh, ww = img.shape
    level_full = cv2.resize(wall.level, (ww // 2 * 2, hh // 2 * 2), interpolation=cv2.INTER_LINEAR)
    if level_full.shape != img.shape:  # an odd size: the last row or column repeats
        level_full = cv2.copyMakeBorder(level_full, 0, hh - level_full.shape[0], 0, ww - level_full.shape[1],
                                        cv2.BORDER_REPLICATE)
    blur_hint = blur_px
    hole_blurs = [hole_blur(h) for h in holes if getattr(h, "edge_sigma_px", None)]
    if blur_hint is None and hole_blurs:
        blur_hint = float(np.median(hole_blurs))
    found, examined = _find(img, mm_per_px, holes, wall, zone, level_full, reach_px, blur_hint, cfg)
    if blur_hint is None:
        # no blur given and no hole's edge to read it from: each scratch read its own (its
        # cross profile, its ends, a prior), but one lens at one focus blurs the whole
        # frame alike, and a strong scratch reads it better than a faint one can, whose
        # width and contrast trade off against it. Their reads combined stand for the
        # frame's blur, its variance carried into the widths, and the frame is examined
        # again with it: a faint 0.43 x 0.023 mm scratch on a frame without a hole read
        # 1.18 px of blur for 1.66 and contrast 0.10 under it, under the 0.11 bar, beside a
        # 0.74 mm one that read 1.75 +/- 0.07 px (bench seed 260088), and was lost
        shared = shared_blur([ex for ex in examined if ex.defect is not None and ex.defect.kind == "scratch"])
        if shared is not None and shared[1] <= cfg.frame_blur_max_sd_px ** 2:
            again, examined_again = _find(img, mm_per_px, holes, wall, zone, level_full, reach_px,
                                          KnownBlur(*shared), cfg)
            # ... but the frame's blur is known only so well, and a faint scratch's contrast
            # sits at its bar under either reading: a mark found under its own blur and not
            # under the frame's, nothing there then, stays as it was measured (the bench's
            # 490058: a 0.64 x 0.016 mm scratch read contrast 0.111 under its own 1.56 px,
            # 0.104 under the frame's 1.49; true 1.74)
            covered = _regions(img.shape, examined_again)
            kept = {(ex.defect.x_px, ex.defect.y_px) for ex in examined
                    if ex.defect is not None and ex.box is not None
                    and not covered[_region_slices(ex)][ex.region].any()}
            found = sorted(again + [d for d in found if d.kind in ("pore", "scratch") and (d.x_px, d.y_px) in kept],
                           key=lambda d: (d.y_px, d.x_px))
    return found


def _region_slices(ex: ExaminedCandidate) -> tuple[slice, slice]:
    x0, y0, x1, y1 = ex.box
    return slice(y0, y1), slice(x0, x1)


def _regions(shape: tuple[int, int], examined: list[ExaminedCandidate]) -> np.ndarray:
    """What the examined candidates that are defects cover over the frame."""
    mask = np.zeros(shape, bool)
    for ex in examined:
        if ex.defect is not None and ex.box is not None:
            mask[_region_slices(ex)] |= ex.region
    return mask


def _drop_hatch_like(examined: list[ExaminedCandidate], wall, claimed: np.ndarray, mm_per_px: float,
                     cfg: DefectConfig) -> list[ExaminedCandidate]:
    """The examined candidates less the honing grooves' pieces among their scratches.

    A scratch that keeps to one line of a groove family (``on_groove_line``) and whose
    line runs on beyond it as a groove (``line_runs_on``: ``cfg.groove_run_on_share`` of
    it at ``cfg.groove_run_on_darkness`` of the mark's darkness more than the wall's lines,
    or, a mark not along the hatch, ``cfg.groove_run_on_z`` of their spread more) is a
    piece of that groove.
    And a scratch along the hatch no darker than the frame's own darkest groove stretches
    along its family (``cfg.aligned_min_stretch_share`` of the population's
    ``cfg.aligned_stretch_quantile``-th percentile, ``groove_stretches``) is one too: a
    honing whose grooves stop short leaves groove pieces with cut ends, which the ends'
    test (``_square_end``) takes for furrows. When any falls under that bar, the frame's
    grooves stop short, and each must reach ``cfg.aligned_min_stretch_share_stopped``.
    A pore cut by the frame's border that reads as a short piece of a groove
    (``_border_piece_family``) whose line runs on by ``cfg.groove_run_on_share`` is a
    piece of that groove as well, and so is a small one (``_border_stub``) on a line of
    either family that runs on by ``cfg.border_stub_min_run_on``."""
    on_line = []  # (a scratch, the family whose line it keeps to or None, whether it runs along the hatch)
    border_pieces = []  # (a pore cut by the border, a family it may lie on, the run-on that makes it a piece)
    for ex in examined:
        if ex.defect is not None and ex.defect.kind == "scratch":
            angle, length = ex.defect.angle_deg % 180.0, ex.defect.length_px
            family = on_groove_line(angle, length, ex.defect.width_px, wall.angles_deg, cfg)
            along = is_along_hatch(angle, length, wall.angles_deg, cfg)
            if family is not None or along:
                on_line.append((ex, family, along))
        elif ex.defect is not None and ex.defect.kind == "pore" and ex.defect.partial:
            family = _border_piece_family(ex.defect, claimed.shape, wall.angles_deg, mm_per_px, cfg)
            if family is not None:
                border_pieces.append((ex, family, cfg.groove_run_on_share))
            if _border_stub(ex.defect, mm_per_px, cfg):
                # the family it lies along is judged above, by a lower bar
                border_pieces.extend((ex, g, cfg.border_stub_min_run_on) for g in wall.angles_deg if g != family)
    if not on_line and not border_pieces:
        return examined
    h, w = wall.darkness.shape
    marks = cv2.resize(claimed[: h * 2, : w * 2].astype(np.float32), (w, h), interpolation=cv2.INTER_AREA) > 0
    marks = cv2.dilate(marks.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    families = {}

    def stretches_of(family):
        if family not in families:
            families[family] = groove_stretches(wall, family, marks, mm_per_px, cfg)
        return families[family]

    pieces = set()
    for ex, family, along in on_line:
        if family is None:
            continue
        runs_on = _mark_runs_on(stretches_of(family), ex.defect, mm_per_px, cfg)
        # the excess's significance off the hatch only: a scratch drawn along it may lie on a
        # groove's line over its whole length (and its ends' tests judge it there)
        if runs_on is not None and (runs_on.share >= cfg.groove_run_on_share
                                    or (not along and runs_on.z >= cfg.groove_run_on_z)):
            pieces.add(id(ex))
    for ex, family, share in border_pieces:
        if id(ex) in pieces:
            continue
        runs_on = _mark_runs_on(stretches_of(family), ex.defect, mm_per_px, cfg)
        if runs_on is not None and runs_on.share >= share:
            pieces.add(id(ex))
    shares = {}
    for ex, _, along in on_line:
        if not along:
            continue
        d = ex.defect
        stretches = stretches_of(near_hatch(d.angle_deg % 180.0, wall.angles_deg, cfg))
        own = stretch_darkness(stretches, d.x_px, d.y_px, d.length_px)
        if stretches.quantile is not None and own is not None:
            shares[id(ex)] = own / stretches.quantile
    bar = cfg.aligned_min_stretch_share
    if any(v < bar for v in shares.values()):
        bar = max(bar, cfg.aligned_min_stretch_share_stopped)
    return [ex for ex in examined if id(ex) not in pieces and shares.get(id(ex), np.inf) >= bar]


class CrossingReading(NamedTuple):
    """What the groove families' lines through a mark explain of it (``_crossing_shares``):
    each family's share of its darkness, and how closely its darkness follows the lines'
    (their Pearson correlation over the mark's outline; 0 where the lines lay nothing
    there)."""

    shares: tuple[float, ...]
    follows: float


def _crossing_shares(dark: np.ndarray, d: Defect, angles_deg, blur: float, arm_px: float,
                     blocked: np.ndarray | None = None) -> CrossingReading:
    """How much of a mark's darkness each groove family's line through it explains: the
    family's profile across its lines, read beside the mark along the line (from 2 blur +
    2 px beyond its outline over ``arm_px``, the median along the line: the other family's
    grooves cross there; the side whose profile holds more: a piece may end at the mark),
    laid along the line through the mark; its sum over the mark's outline grown by the
    blur, over the mark's darkness summed there. ``dark``: the frame's relative darkness
    (level out, grooves in), NaN where nothing may be read (the holes); ``blocked``: where
    the arms may not read besides (other marks). A share is 0 where neither side has 80 %
    of its samples.

    And how the mark's darkness follows the lines' laid through it, pixel by pixel over
    its own outline (the blur's skirt beyond it shows a pore's grooves running on outside
    it): a crossing's darkness is the lines' (it peaks where they cross and runs out
    along their bands), while a pore takes the wall's place, grooves and all, and its
    floor is even across them. A pale 0.43 mm pore on a crossing of two deep grooves
    (wide frame 4510084) was explained 0.36 and 0.21 and dropped as their crossing; its
    darkness follows the lines' at 0.20, eight crossings read as pores at 0.70-0.98."""
    h, w = dark.shape
    th = np.deg2rad(d.angle_deg)
    half_l, half_w = d.length_px / 2.0, d.width_px / 2.0
    reach = int(np.ceil(half_l + blur + 1.0))
    yy, xx = np.mgrid[int(d.y_px) - reach:int(d.y_px) + reach + 1,
                      int(d.x_px) - reach:int(d.x_px) + reach + 1].astype(np.float32)
    du = (xx - d.x_px) * np.cos(th) + (yy - d.y_px) * np.sin(th)
    dv = -(xx - d.x_px) * np.sin(th) + (yy - d.y_px) * np.cos(th)
    inside = ((du / (half_l + blur)) ** 2 + (dv / (half_w + blur)) ** 2 <= 1.0) \
        & (xx >= 0) & (yy >= 0) & (xx <= w - 1) & (yy <= h - 1)
    own = dark[yy[inside].astype(np.int64), xx[inside].astype(np.int64)]
    total = float(np.nansum(np.clip(own, 0.0, None)))
    if total <= 0.0:
        return CrossingReading(tuple(0.0 for _ in angles_deg), 0.0)
    arms = dark if blocked is None else np.where(blocked, np.float32(np.nan), dark)
    shares = []
    laid = np.zeros(own.shape, np.float64)  # the lines' darkness over the outline
    for a in angles_deg:
        ar = np.deg2rad(a)
        t, n = np.array([np.cos(ar), np.sin(ar)]), np.array([-np.sin(ar), np.cos(ar)])
        along = np.hypot(half_l * np.cos(th - ar), half_w * np.sin(th - ar))
        across = np.hypot(half_l * np.sin(th - ar), half_w * np.cos(th - ar))
        c = np.arange(-across - 2.0 * blur - 2.0, across + 2.0 * blur + 2.01, 0.5)
        best = None
        for side in (-1.0, 1.0):
            s = side * (along + 2.0 * blur + 2.0 + np.arange(0.0, arm_px))
            ss, cc = np.meshgrid(s, c)
            mx = (d.x_px + ss * t[0] + cc * n[0]).astype(np.float32)
            my = (d.y_px + ss * t[1] + cc * n[1]).astype(np.float32)
            v = cv2.remap(arms, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=np.nan)
            if np.isfinite(v).mean() < 0.8:
                continue
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)  # a row wholly blocked: NaN, read as 0
                prof = np.clip(np.nan_to_num(np.nanmedian(v, axis=1)), 0.0, None)
            if best is None or prof.sum() > best.sum():
                best = prof
        if best is None:
            shares.append(0.0)
            continue
        across_px = (xx[inside] - d.x_px) * n[0] + (yy[inside] - d.y_px) * n[1]
        line = np.interp(across_px, c, best, left=0.0, right=0.0)
        laid += line
        shares.append(float(line.sum()) / total)
    # over the mark's own outline: the blur's skirt beyond it shows a pore's grooves
    # running on outside it
    core = (du[inside] / max(half_l, 1.0)) ** 2 + (dv[inside] / max(half_w, 1.0)) ** 2 <= 1.0
    seen = np.isfinite(own) & core
    follows = 0.0
    if seen.sum() >= 3 and float(np.std(laid[seen])) > 0.0 and float(np.std(own[seen])) > 0.0:
        follows = float(np.corrcoef(own[seen], laid[seen])[0, 1])
    return CrossingReading(tuple(shares), follows)


def _drop_crossings(examined: list[ExaminedCandidate], img: np.ndarray, level_full: np.ndarray, zone: np.ndarray,
                    angles_deg, blur: float, mm_per_px: float, cfg: DefectConfig) -> list[ExaminedCandidate]:
    """The examined candidates less the pores inside the frame, at least
    ``cfg.crossing_min_length_mm`` long, that are two grooves' crossing
    (``_crossing_shares``: the two lines through the mark explain
    ``cfg.crossing_min_explained`` of its darkness, each family
    ``cfg.crossing_min_family_share`` of it, and its darkness follows theirs at
    ``cfg.crossing_min_follows``)."""
    pores = [ex for ex in examined if ex.defect is not None and ex.defect.kind == "pore" and not ex.defect.partial
             and ex.defect.length_px * mm_per_px >= cfg.crossing_min_length_mm]
    if not pores or len(angles_deg) < 2:
        return examined
    hh, ww = img.shape
    count = np.zeros(img.shape, np.int32)  # how many defects' regions cover each pixel
    for ex in examined:
        if ex.defect is not None and ex.box is not None:
            b = ex.box
            count[b[1]:b[3], b[0]:b[2]] += ex.region if ex.cover is None else ex.region | ex.cover
    arm_px = max(cfg.crossing_arm_mm / mm_per_px, 8.0)
    drop = set()
    for ex in pores:
        d = ex.defect
        # the window the arms' samples reach into (``_crossing_shares``), and a margin
        reach = 0.5 * d.length_px + 2.0 * blur + 2.0
        r = int(np.ceil(np.hypot(reach + arm_px, reach))) + 3
        x0, y0 = max(int(d.x_px) - r, 0), max(int(d.y_px) - r, 0)
        x1, y1 = min(int(d.x_px) + r + 2, ww), min(int(d.y_px) + r + 2, hh)
        others = count[y0:y1, x0:x1].copy()
        if ex.box is not None:
            b = ex.box
            bx0, by0, bx1, by1 = max(b[0], x0), max(b[1], y0), min(b[2], x1), min(b[3], y1)
            if bx1 > bx0 and by1 > by0:
                others[by0 - y0:by1 - y0, bx0 - x0:bx1 - x0] -= ex.region[by0 - b[1]:by1 - b[1], bx0 - b[0]:bx1 - b[0]]
        with np.errstate(divide="ignore", invalid="ignore"):
            dark = 1.0 - img[y0:y1, x0:x1].astype(np.float32) / np.maximum(level_full[y0:y1, x0:x1], 1.0)
        dark = cv2.GaussianBlur(dark, (0, 0), 0.7, borderType=cv2.BORDER_REPLICATE)
        dark[zone[y0:y1, x0:x1]] = np.nan
        reading = _crossing_shares(dark, replace(d, x_px=d.x_px - x0, y_px=d.y_px - y0), angles_deg, blur, arm_px,
                                   blocked=others > 0)
        if sum(reading.shares) >= cfg.crossing_min_explained \
                and min(reading.shares) >= cfg.crossing_min_family_share \
                and reading.follows >= cfg.crossing_min_follows:
            drop.add(id(ex))
    return [ex for ex in examined if id(ex) not in drop]


def _mark_runs_on(stretches, d: Defect, mm_per_px: float, cfg: DefectConfig):
    """How the line of ``stretches``' family through a mark runs on beyond it
    (``line_runs_on``), the mark's own darkness read over its middle
    (``cfg.groove_run_on_middle``: a short mark a few degrees off the family leaves the
    three rows round the family's line towards its ends); None as there."""
    own = stretch_darkness(stretches, d.x_px, d.y_px, d.length_px, middle=cfg.groove_run_on_middle)
    return None if own is None else line_runs_on(stretches, d.x_px, d.y_px, d.length_px, own, mm_per_px, cfg)


def _border_piece_family(d: Defect, shape: tuple[int, int], angles_deg, mm_per_px: float,
                         cfg: DefectConfig) -> float | None:
    """The groove family a pore cut by the frame's border (``shape``, full res) lies along
    as a short piece of one of its grooves, or None: its long axis at least
    ``cfg.border_piece_min_aspect`` times its width and within
    ``cfg.border_piece_max_off_deg`` of the family and nearer it than the nearest border's
    direction, the family at least that far off the border's (the visible part of a round
    pore lies along the border that cuts it), and the mark no wider than
    ``cfg.border_piece_max_width_mm``."""
    if d.length_px < cfg.border_piece_min_aspect * d.width_px or d.width_px * mm_per_px > cfg.border_piece_max_width_mm:
        return None
    h, w = shape
    border_deg = 90.0 if min(d.x_px, w - 1 - d.x_px) <= min(d.y_px, h - 1 - d.y_px) else 0.0
    angle = d.angle_deg % 180.0
    off_border = circ_diff_deg(angle, border_deg)
    near = [g for g in angles_deg if circ_diff_deg(angle, g) <= min(cfg.border_piece_max_off_deg, off_border)
            and circ_diff_deg(g, border_deg) >= cfg.border_piece_max_off_deg]
    return min(near, key=lambda g: circ_diff_deg(angle, g)) if near else None


def _border_stub(d: Defect, mm_per_px: float, cfg: DefectConfig) -> bool:
    """A mark cut by the frame's border too small to tell a pore by
    (``cfg.border_stub_max_length_mm`` by ``cfg.border_stub_max_width_mm``): a groove's stub
    if a family's line through it runs on (``_drop_hatch_like``)."""
    return (d.length_px * mm_per_px <= cfg.border_stub_max_length_mm
            and d.width_px * mm_per_px <= cfg.border_stub_max_width_mm)


class _Rest(NamedTuple):
    """What a seed's defects left of it (``_seed_rest``): a seed of its own."""

    box: tuple[int, int, int, int]
    seed: np.ndarray  # over ``box``
    depth: int  # how many measurements it is the rest of
    #: over ``box``, where its region may not grow: what the seed's defects measured and
    #: what was claimed before them, less the part itself
    keep_out: np.ndarray
    #: whether only a scratch is taken from it: the rest of a seed measured as pores alone
    scratches_only: bool
    #: the defects measured from the seed (their examined candidates)
    parents: tuple


def _or_over(dst: np.ndarray, dst_box, src: np.ndarray, src_box) -> None:
    """``dst`` (over ``dst_box``) |= ``src`` (over ``src_box``) where the two boxes meet."""
    x0, y0 = max(dst_box[0], src_box[0]), max(dst_box[1], src_box[1])
    x1, y1 = min(dst_box[2], src_box[2]), min(dst_box[3], src_box[3])
    if x1 > x0 and y1 > y0:
        dst[y0 - dst_box[1]:y1 - dst_box[1], x0 - dst_box[0]:x1 - dst_box[0]] |= \
            src[y0 - src_box[1]:y1 - src_box[1], x0 - src_box[0]:x1 - src_box[0]]


def _seed_rest(seed: np.ndarray, claimed: np.ndarray, covers: list[np.ndarray], mm_per_px: float,
               cfg: DefectConfig) -> list[np.ndarray]:
    """The parts of a seed (over its box) that the defects measured from it leave
    unclaimed (``claimed``: over the same box, what they measured and what was claimed
    before them), each of at least ``cfg.rest_min_area_mm2``: a pore on a scratch's line
    is one seed with it, and once the scratch was measured the pore was never read. A
    scratch's cover (``covers``: the seed's scratches') cuts a mark it crosses in two, so
    the parts are closed across the widest cover within the seed."""
    left = seed & ~claimed
    if not left.any():
        return []
    across = max((2.0 * float(cv2.distanceTransform(c.astype(np.uint8), cv2.DIST_L2, 3).max()) for c in covers),
                 default=0.0)
    if across > 0.0:
        k = 2 * int(np.ceil(across / 2.0)) + 3
        left = cv2.morphologyEx(left.astype(np.uint8), cv2.MORPH_CLOSE,
                                cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))).astype(bool) & seed
    n, labels, stats, _ = cv2.connectedComponentsWithStats(left.astype(np.uint8), connectivity=8)
    least = cfg.rest_min_area_mm2 / mm_per_px ** 2
    return [labels == j for j in range(1, n) if stats[j, cv2.CC_STAT_AREA] >= least]


def _drop_rests_of_dropped(examined: list[ExaminedCandidate], before: set[int],
                           rest_of: dict[int, tuple]) -> list[ExaminedCandidate]:
    """The examined candidates less those measured from a seed's rest (``rest_of``, by
    ``id``: the candidate and its seed's defects, held so that no ``id`` is reused) all
    of whose seed's defects were dropped (their ``id`` in ``before``, not in
    ``examined``: a groove's piece, a crossing), and the rests of those in turn: what a
    groove's piece leaves of its seed is the grooves' residue (an X of two groove pieces
    left a 0.22 mm "pore" at its middle, wide frame 3220041)."""
    dropped = before - {id(ex) for ex in examined}
    changed = True
    while changed:
        changed = False
        for ex in examined:
            own = id(ex)
            if own not in dropped and own in rest_of and all(id(p) in dropped for p in rest_of[own][1]):
                dropped.add(own)
                changed = True
    return [ex for ex in examined if id(ex) not in dropped]


def _end_under_blob(ex: ExaminedCandidate, blob: np.ndarray, box, blur: float, factor: float) -> ExaminedCandidate:
    """A scratch read past pores (``blob``: their blobs over ``box``) whose end lies at one:
    where it ends under the pore no frame shows, and its extent stops at the pore's near
    edge or runs on to its far edge as the pore's blurred skirt carries its profile. Each
    such end adds the pore's chord along the line, read from an edge with the truth
    anywhere on it (its RMS: chord / sqrt 3), to the length's uncertainty (divided by the
    ``factor`` the fit's uncertainty is scaled by, ``DefectConfig.uncertainty_factor``: this
    term is no fit's)."""
    if ex.line is None or len(ex.line) < 2:
        return ex
    labels = cv2.connectedComponents(grow_by_skirt(blob.astype(np.uint8), blur), connectivity=8)[1]
    hh, ww = blob.shape
    a, b = (np.asarray(ex.line[k], float) - np.array([box[0], box[1]], float) for k in (0, -1))
    t = (b - a) / max(float(np.hypot(*(b - a))), 1e-9)
    var = 0.0
    for end in (a, b):
        x, y = int(round(end[0])), int(round(end[1]))
        if not (0 <= x < ww and 0 <= y < hh) or labels[y, x] == 0:
            continue
        ys, xs = np.nonzero((labels == labels[y, x]) & blob)
        if xs.size == 0:
            continue
        along = (np.column_stack([xs, ys]) - end) @ t
        var += (float(np.ptp(along)) + 1.0) ** 2 / 3.0
    if var == 0.0:
        return ex
    d = ex.defect
    return replace(ex, defect=replace(d, length_u_px=float(np.hypot(d.length_u_px, np.sqrt(var) / factor))))


def _find(img: np.ndarray, mm_per_px: float, holes: list, wall, zone: np.ndarray, level_full: np.ndarray,
          reach_px: float, blur_hint: float | None, cfg: DefectConfig) -> tuple[list[Defect], list[ExaminedCandidate]]:
    """``detect_defects`` under one blur (``blur_hint``; None: each mark reads its own):
    the candidates examined, the scratches' pieces joined and followed, the rims judged.
    Returns (the defects, sorted by y then x; the examined candidates)."""
    hh, ww = img.shape
    max_width_px = cfg.max_scratch_width_mm / mm_per_px
    examined: list[ExaminedCandidate] = []
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
    blur = blur_hint if blur_hint is not None else BLUR_PRIOR_PX[0]  # where one blur must be had
    pore_sizes = [0]  # each label's px (label 0: none)
    rest_of: dict[int, tuple] = {}  # a defect measured from a seed's rest: (it, the seed's defects)
    candidates = find_candidates(wall, cfg)
    # (a group; None, or for a member examined on its own what its group's defects claimed)
    queue = [(group, None) for group in group_collinear(candidates)]
    while queue:
        group, own_group = queue.pop(0)
        keep_out, depth, scratches_only, parents = None, 0, False, ()
        if isinstance(group, _Rest):
            # what a seed's defects left of it: examined on its own, its region kept off
            # what they measured beyond it (not off a scratch's whole region, which may
            # have grown over part of a pore on its line: the pore read 0.22 mm of 0.32,
            # and its other part, a candidate of its own, was reported again)
            box, seed, depth, inside, scratches_only, parents = group
            keep_out = claimed.copy()
            keep_out[box[1]:box[3], box[0]:box[2]] = inside
            group = []
        else:
            bx0 = min(candidates[i][2][0] for i in group)
            by0 = min(candidates[i][2][1] for i in group)
            bx1 = max(candidates[i][2][2] for i in group)
            by1 = max(candidates[i][2][3] for i in group)
            size = max(bx1 - bx0, by1 - by0) * 2
            margin = int(np.clip(0.6 * size, 14, 40))  # room for the wall model round the mark
            box = (max(2 * bx0 - margin, 0), max(2 * by0 - margin, 0), min(2 * bx1 + margin, ww),
                   min(2 * by1 + margin, hh))
            seed = np.zeros((box[3] - box[1], box[2] - box[0]), bool)
            for i in group:
                seed |= seed_in_box(candidates[i][0], candidates[i][1], box)
        taken = claimed[box[1]:box[3], box[0]:box[2]]
        if own_group is not None:  # its own group's claim grew over it, not a measurement of it
            taken = taken & ~own_group[box[1]:box[3], box[0]:box[2]]
        if keep_out is None and taken[seed].mean() > 0.5:
            continue  # already measured as part of another candidate's defect
        # two scratches crossing are one candidate (an X, a V): each furrow is examined on
        # its own, its region confined to its line, the other's pixels left out of the wall
        # model (one candidate's measurement read the X's bisector and neither scratch).
        # The furrows are kept only when they are scratches: a pore with deep grooves'
        # residue attached holds bands too, and its pieces were read as pores; such a
        # seed is examined whole
        results = []
        furrows = [(fx + box[0], fy + box[1], fa, bend) for fx, fy, fa, bend in split_furrows(seed)]
        if furrows:
            results = [examine_candidate(img, box, seed & line_band(seed.shape, box[:2], line, cfg.furrow_half_band_px),
                                         zone, wall.angles_deg, level_full, cfg, blur_hint, max_width_px, excl=seed,
                                         confine=line, others=claimed, keep_out=keep_out)
                       for line in furrows]
            if not any(ex.defect is not None for ex in results) or \
                    any(ex.defect is not None and ex.defect.kind != "scratch" for ex in results):
                results = []
        if not results:
            results = [examine_candidate(img, box, seed, zone, wall.angles_deg, level_full, cfg, blur_hint,
                                         max_width_px, others=claimed, keep_out=keep_out)]
            line = one_furrow(seed) if results[0].defect is None else None
            if line is not None:
                # one furrow whose region, grown unconfined, was no defect: a deep groove's
                # residue that crosses a scratch joins its region, which is then no line and
                # was measured as a pore and dropped (the twin's frames: a 1.66 mm scratch,
                # plain to see, not reported, seed 2086604). Examined again confined to the
                # seed's own line, kept only as a scratch
                line = (line[0] + box[0], line[1] + box[1], line[2], line[3])
                own_line = seed & line_band(seed.shape, box[:2], line, cfg.furrow_half_band_px)
                again = examine_candidate(img, box, own_line, zone, wall.angles_deg, level_full, cfg, blur_hint,
                                          max_width_px, excl=seed, confine=line, others=claimed, keep_out=keep_out)
                if again.defect is not None and again.defect.kind == "scratch":
                    results = [again]
        if len(results) == 1 and results[0].defect is not None and depth < cfg.rest_max_depth:
            # a blob with a thin mark's arms on one line through it: a pore on a scratch,
            # one seed, read whole as one long pore (a 0.39 mm pore on a 0.97 mm scratch read
            # 0.71 x 0.47 mm, the scratch lost), or as the scratch on one side of it (the
            # pore's darkness, wider than the scratch's filter, broke its profile there).
            # The scratch is examined on its line with the blob hidden, kept when the seed
            # read as a pore or as a shorter scratch; the seed's rest then gives the pore
            pair = line_through_blob(seed, min_arm_px=cfg.through_min_reach_mm / mm_per_px)
            if pair is not None:
                line, blob = pair
                line = (line[0] + box[0], line[1] + box[1], line[2], line[3])
                hide = np.zeros(img.shape, bool)
                hide[box[1]:box[3], box[0]:box[2]] = blob
                through = examine_candidate(img, box, seed & line_band(seed.shape, box[:2], line,
                                                                       cfg.furrow_half_band_px) & ~blob,
                                            zone, wall.angles_deg, level_full, cfg, blur_hint, max_width_px,
                                            excl=seed, confine=line, others=claimed, keep_out=keep_out, hide=hide)
                if through.defect is not None and through.defect.kind == "scratch" and (
                        results[0].defect.kind == "pore" or through.defect.length_px > results[0].defect.length_px):
                    results = [_end_under_blob(through, blob, box, blur, cfg.uncertainty_factor)]
        prior = claimed[box[1]:box[3], box[0]:box[2]].copy() if depth < cfg.rest_max_depth else None
        measured = []  # this seed's defects kept
        for ex in results:
            if ex.defect is None or (scratches_only and ex.defect.kind != "scratch"):
                continue
            if keep_out is not None and np.count_nonzero(ex.region) * mm_per_px ** 2 < cfg.rest_min_area_mm2:
                # a rest's mark is at least what a rest must be (a 16 px region on a scratch's
                # line, where a groove crosses it, read as a 0.17 mm pore: wide frame 3220090)
                continue
            rb = ex.box or box
            if ex.cover is not None and claimed[rb[1]:rb[3], rb[0]:rb[2]][ex.cover].mean() > 0.5:
                continue  # grown along its line into a scratch already measured (groove residue beside it)
            if ex.defect.kind == "pore" and measured_again(pore_regions[rb[1]:rb[3], rb[0]:rb[2]], ex.region,
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
            measured.append(ex)
            if parents:
                rest_of[id(ex)] = (ex, parents)
        if prior is not None and measured:
            # the rest of the seed, what its defects measured taken out: a scratch its line
            # (its cover: its region may have grown over a mark on its line), another mark
            # its region and its blurred skirt (a seed reaches past a pore's region, and
            # its skirt read as two more pores)
            for ex in measured:
                own = ex.cover if ex.cover is not None else grow_by_skirt(ex.region.astype(np.uint8), blur) > 0
                _or_over(prior, box, own, ex.box or box)
            rests = _seed_rest(seed, prior, [ex.cover for ex in measured if ex.cover is not None], mm_per_px, cfg)
            # after pores alone, a scratch through one (measured as it) is what may be left;
            # their seeds' other rests are the grooves' residue beside them (false "pores" of
            # 0.1-0.3 mm on the wide walls broken 20 %: three on 3220000's frames)
            only = not any(ex.defect.kind == "scratch" for ex in measured)
            queue.extend((_Rest(box, rest, depth + 1, prior & ~rest, only, tuple(measured)), None) for rest in rests)
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
                own = seed_in_box(candidates[i][0], candidates[i][1], box)
                if own.any() and inside[own].mean() < 0.05:
                    queue.append(([i], group_claim))
    examined = drop_scratch_pieces(examined)
    examined = track_scratches(img, level_full, examined, cfg, wall.angles_deg, wall.residual)
    examined = join_scratch_pieces(img, level_full, examined, cfg, pores=pore_regions > 0)
    before = {id(ex) for ex in examined}
    examined = _drop_hatch_like(examined, wall, claimed_regions, mm_per_px, cfg)
    examined = _drop_crossings(examined, img, level_full, zone, wall.angles_deg,
                               blur, mm_per_px, cfg)
    examined = _drop_rests_of_dropped(examined, before, rest_of)
    found: list[Defect] = [ex.defect if ex.line is None else replace(ex.defect, line_px=line_points(ex.line))
                           for ex in examined if ex.defect is not None]
    others = [hole_zone(img.shape, [h for j, h in enumerate(holes) if j != i], reach_px) for i in range(len(holes))]
    marks = marks_mask(img.shape, found, blur) if holes else None
    grown, labels = None, None
    if holes and claimed_regions.any():
        # a mark that reaches a rim's band, with its blurred skirt (2.5 blur + 1 px): a
        # scratch that ends at a rim darkens the wall beside its region too, read as a
        # 0.07 mm "chip" next to it (wide bench seed 82083). Only those: a pore 30 px out
        # whose skirt reached the ring that calibrates the wall cut a true chip between it
        # and the rim in two (hatch 22 deg, seed 89000)
        grown = grow_by_skirt(claimed_regions.astype(np.uint8), blur)
        labels = cv2.connectedComponents(grown)[1]
    for i, hole in enumerate(holes):
        own = hole_zone(img.shape, [hole], reach_px)
        marks_i = claimed_regions
        if labels is not None:
            near = np.unique(labels[own & (grown > 0)])
            near = near[near > 0]
            if near.size:
                marks_i = claimed_regions | np.isin(labels, near)
        found += rim_defects(img, hole, i, others[i] | (marks_i & ~own),
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
    return sorted(out, key=lambda d: (d.y_px, d.x_px)), examined
