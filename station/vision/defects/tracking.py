"""A scratch across the frame: its pieces joined, its ends followed on the raw darkness
past where the candidate's patch stopped (run on, a turn onto the hatch, a fade), and
pieces that another examination holds dropped.

Part of ``station.vision.defects`` (its docstring tells the method).
"""

from __future__ import annotations

from dataclasses import asdict
import warnings

import cv2
import numpy as np
from scipy.ndimage import gaussian_filter1d, map_coordinates

from station.vision.defects.config import Defect, DefectConfig
from station.vision.defects.common import circ_diff_deg, confidence_of, near_hatch, weighted_pca
from station.vision.defects.scratches import BLUR_PRIOR_PX
from station.vision.defects.examine import end_steps, ExaminedCandidate, shared_blur


def measured_again(labels: np.ndarray, region: np.ndarray, sizes: list[int]) -> bool:
    """Whether a pore's ``region`` is a pore already measured (``labels``: the measured
    pores' regions, each its own label, 0 elsewhere, over the region's box; ``sizes``:
    each label's whole region, px, by label): it covers at least half of one of them."""
    under = labels[region]
    return any(np.count_nonzero(under == lab) >= 0.5 * sizes[lab] for lab in np.unique(under[under > 0]))


def _cover_share(a: "ExaminedCandidate", b: "ExaminedCandidate") -> float:
    """The share of ``a``'s cover that lies in ``b``'s (frame px)."""
    (ax0, ay0, ax1, ay1), (bx0, by0, bx1, by1) = a.box, b.box
    x0, y0, x1, y1 = max(ax0, bx0), max(ay0, by0), min(ax1, bx1), min(ay1, by1)
    total = int(a.cover.sum())
    if x1 <= x0 or y1 <= y0 or total == 0:
        return 0.0
    inter = a.cover[y0 - ay0:y1 - ay0, x0 - ax0:x1 - ax0] & b.cover[y0 - by0:y1 - by0, x0 - bx0:x1 - bx0]
    return float(inter.sum()) / total


def drop_scratch_pieces(examined: list["ExaminedCandidate"]) -> list["ExaminedCandidate"]:
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


def _scratch_gap(img: np.ndarray, level: np.ndarray, a: "ExaminedCandidate", b: "ExaminedCandidate",
                 cfg: DefectConfig, pores: np.ndarray | None = None) -> tuple[float, int, int, np.ndarray] | None:
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
    over nearly all of the gap: a groove's residue does not carry it, the furrow does.
    Where the path crosses a pore measured (``pores``: the frame's pores' regions), the
    pore carries it: a scratch through a pore is dark across its whole width there, its
    core no darker than its flanks. Pieces in line across a short gap (``_in_line``) are
    joined whatever its darkness."""
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
        if pores is not None:
            ix = np.clip(np.round(path[:, 0]).astype(int), 0, pores.shape[1] - 1)
            iy = np.clip(np.round(path[:, 1]).astype(int), 0, pores.shape[0] - 1)
            c = np.where(pores[iy, ix], ref, c)
        if (float(np.median(c)) < cfg.scratch_join_dark_share * ref or
                float(np.mean(c >= 0.5 * cfg.scratch_join_dark_share * ref)) < 0.9) and \
                not _in_line(a, ka, b, kb, g, core, cfg):
            return None
    return g, ka, kb, path


def _in_line(a: "ExaminedCandidate", ka: int, b: "ExaminedCandidate", kb: int, g: float, core: float,
             cfg: DefectConfig) -> bool:
    """Whether two pieces lie on one line across a short gap so closely that they are one
    furrow even where the gap shows no darkness of its own: each piece at least
    1 / ``scratch_join_line_gap_share`` times the gap long, their directions (over the last
    quarter of each, up to 100 px) within ``scratch_join_line_turn_deg``, and each end
    within the furrow's core of the other's line continued. A thin scratch (a 1.5 px
    furrow, its width varying along it by half) fades to nothing for a stretch where it
    narrows beside a groove that darkens its flanks (a whole-surface part: a 12.9 mm
    scratch seen in one frame as 7.5 and 5.1 mm pieces, 0.3 mm apart, in line within
    1.4 deg and 1.4 px); two scratches in line to a px across a gap a fifth of their
    length are one scratch that the tool lifted off for a moment."""
    la, lb = float(a.defect.length_px), float(b.defect.length_px)
    if g > cfg.scratch_join_line_gap_share * min(la, lb):
        return False
    pa, pb = a.line[ka], b.line[kb]
    ta = _end_tangent(a.line, ka, min(100.0, 0.25 * la))
    tb = _end_tangent(b.line, kb, min(100.0, 0.25 * lb))
    if float(ta @ -tb) < np.cos(np.deg2rad(cfg.scratch_join_line_turn_deg)):
        return False
    for p0, t0, p1 in ((pa, ta, pb), (pb, tb, pa)):
        w = p1 - p0
        if float(w @ t0) < 0.0 or abs(float(t0[0] * w[1] - t0[1] * w[0])) > core:
            return False
    return True


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
    darkness inside it: ``end_steps``) but fades, as a groove does along its length or
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
    steps = end_steps(img, level, 0, 0, dict(line=(far[:, 0], far[:, 1]), width=width, blur=blur), ends=(-1,))
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
    _, _, axis, cov = weighted_pca(body[:, 0], body[:, 1], np.ones(body.shape[0]))
    if float(np.sqrt(max(np.linalg.eigvalsh(cov)[0], 0.0))) > RUN_ON_STRAIGHT_PX:
        return False
    body_deg = float(np.rad2deg(axis) % 180.0)
    end_deg = float(np.rad2deg(np.arctan2(t[1], t[0])) % 180.0)
    return any(circ_diff_deg(body_deg, g) <= RUN_ON_HATCH_DEG
               and circ_diff_deg(end_deg, g) >= cfg.groove_alignment_deg for g in angles_deg)


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
    if near_hatch(deg, angles_deg, cfg) is not None:
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


def track_scratches(img: np.ndarray, level: np.ndarray, examined: list["ExaminedCandidate"],
                    cfg: DefectConfig, angles_deg=(), residual: np.ndarray | None = None) -> list["ExaminedCandidate"]:
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
                continue  # beyond it the raw darkness is the groove's (``measure_scratch``)
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
        out.append(ExaminedCandidate(nd, ex.region, ex.box, ex.cover, line, ex.blur, ex.groove_ends, ex.blur_read))
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


def line_points(line: np.ndarray, step: float = 10.0) -> tuple[tuple[float, float], ...]:
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


def join_scratch_pieces(img: np.ndarray, level: np.ndarray, examined: list["ExaminedCandidate"],
                        cfg: DefectConfig, pores: np.ndarray | None = None) -> list["ExaminedCandidate"]:
    """Scratches of one frame that are pieces of one furrow (``_scratch_gap``) as one:
    its centre line the pieces' and the gap's path, its length theirs along it, its
    place that line's middle, its width the pieces' length-weighted mean. A gap may run
    through a pore (``pores``: the frame's pores' regions, ``_scratch_gap``)."""
    while True:
        items = [ex for ex in examined if ex.defect is not None and ex.defect.kind == "scratch"
                 and ex.line is not None and len(ex.line) >= 2]
        best = None
        for i, a in enumerate(items):
            for b in items[i + 1:]:
                r = _scratch_gap(img, level, a, b, cfg, pores)
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
        d = Defect("scratch", x, y, length, width, confidence_of(sig, cfg.min_significance), angle,
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
        joined = ExaminedCandidate(d, region, (x0, y0, x1, y1), cover, line, float(np.mean([a.blur or 0, b.blur or 0])),
                                   blur_read=shared_blur([a, b]))
        examined = [ex for ex in examined if ex is not a and ex is not b] + [joined]
