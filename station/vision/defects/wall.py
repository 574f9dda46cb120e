"""The honed wall's model: the whole frame's level and cross-hatch at half resolution, the
candidates it leaves, their grouping into furrows and lines, and the local model of
each candidate's patch at full resolution (its grooves as 1-D profiles).

Part of ``station.vision.defects`` (its docstring tells the method).
"""

from __future__ import annotations

from dataclasses import dataclass
import functools
from typing import NamedTuple

import cv2
import numpy as np

from station.vision.grooves import honing_directions, weighted_gaussian_mean
from station.vision.defects.config import DefectConfig, NOISE_FLOOR
from station.vision.defects.common import mad_sigma, near_hatch


def _rotation(shape: tuple[int, int], angle_deg: float) -> tuple[np.ndarray, tuple[int, int]]:
    """The affine map that turns a frame of ``shape`` so that lines of direction
    ``angle_deg`` (image sense) run along rows, and the size (w, h) that holds it whole."""
    h, w = shape
    m = cv2.getRotationMatrix2D((w / 2.0, h / 2.0), angle_deg, 1.0)
    c, s = abs(np.cos(np.deg2rad(angle_deg))), abs(np.sin(np.deg2rad(angle_deg)))
    w2, h2 = int(w * c + h * s) + 4, int(w * s + h * c) + 4
    m[0, 2] += (w2 - w) / 2.0
    m[1, 2] += (h2 - h) / 2.0
    return m, (w2, h2)


def _family_mean(values: np.ndarray, weights: np.ndarray, angle_deg: float, window: int) -> np.ndarray:
    """Weighted mean of ``values`` along lines of direction ``angle_deg`` (image sense),
    over ``window`` px: the frame rotated so those lines run along rows, a box filter of
    the weighted values and of the weights, rotated back."""
    h, w = values.shape
    m, (w2, h2) = _rotation((h, w), angle_deg)
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
    m, (w2, h2) = _rotation(shape, angle_deg)
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
    darkness: np.ndarray  # relative darkness under that level, the cross-hatch in it (half res)


def _half(image: np.ndarray) -> np.ndarray:
    h, w = image.shape
    return cv2.resize(image[: h // 2 * 2, : w // 2 * 2].astype(np.float32), (w // 2, h // 2),
                      interpolation=cv2.INTER_AREA)


def hole_zone(shape: tuple[int, int], holes, reach_px: float, scale: float = 1.0, offset: float = 0.0) -> np.ndarray:
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
    zone = hole_zone((h, w), holes, reach_px, 0.5, 0.5)
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
    noise4 = mad_sigma(res4[valid4])
    dark = (res4 > max(cfg.dark_floor, cfg.seed_k * noise4)).astype(np.uint8)
    dark = cv2.resize(cv2.dilate(dark, np.ones((3, 3), np.uint8)), (w, h), interpolation=cv2.INTER_NEAREST)
    if dark.shape != (h, w):
        dark = cv2.copyMakeBorder(dark, 0, h - dark.shape[0], 0, w - dark.shape[1], cv2.BORDER_REPLICATE)
    weights = valid.astype(np.float32) * (1.0 - dark.astype(np.float32))
    mean, den = weighted_gaussian_mean(small, weights, cfg.level_sigma_half_px)
    coarse_half = cv2.resize(coarse8, (w, h), interpolation=cv2.INTER_LINEAR)
    level = np.where(den > 0.05, mean, coarse_half).astype(np.float32)
    darkness = 1.0 - small / np.maximum(level, 1.0)
    darkness[~valid] = 0.0
    # where a groove family's lines hold less than a third of their window in the frame
    # (the frame's corners) the grooves are not known: no candidates there
    for a in angles:
        valid &= _line_support((h, w), round(float(a), 1), cfg.groove_window_half_px) >= 1.0 / 3.0
    residual = _remove_grooves(darkness, weights, angles, cfg.groove_window_half_px, valid)
    noise = max(mad_sigma(cv2.GaussianBlur(residual, (0, 0), 1.0)[valid]), NOISE_FLOOR)
    return _Wall(residual, valid, float(noise), angles, level, darkness)


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
        if near_hatch(float(a), wall.angles_deg, cfg) is not None:
            continue
        mean = _family_mean(q, (v > 0.99).astype(np.float32), float(a), cfg.line_length_quarter_px)
        inside = v > 0.99
        z = mean / max(mad_sigma(mean[inside]), NOISE_FLOOR / 5.0)  # a mean over ~25 half-res px
        np.maximum(best, np.where(inside, z, 0.0), out=best)
    up = cv2.resize(best, (w4 * 2, h4 * 2), interpolation=cv2.INTER_LINEAR)
    if up.shape != (h, w):
        up = cv2.copyMakeBorder(up, 0, h - up.shape[0], 0, w - up.shape[1], cv2.BORDER_REPLICATE)
    return up


@dataclass
class GrooveStretches:
    """One groove family's stretches over the frame (``groove_stretches``)."""

    rotation: np.ndarray  # half-res frame -> the turned frame in which the family runs along rows
    darkness: np.ndarray  # the turned frame's darkness integrated across the lines (x full-res px)
    quantile: float | None  # the population's cfg.aligned_stretch_quantile-th percentile (None: too few)
    on_wall: np.ndarray  # the turned frame's wall (the holes' zones and the frame's outside left out)
    along_px: int  # the stretches' length along the lines (half-res px)

    @functools.cached_property
    def best(self) -> np.ndarray:
        """Each place's best of the three rows round it, as a mark's line is read."""
        return cv2.dilate(self.darkness, np.ones((3, 1), np.uint8))

    @functools.cached_property
    def best_on_wall(self) -> np.ndarray:
        """Where the three rows round a place are all on the wall."""
        return cv2.erode(self.on_wall.astype(np.uint8), np.ones((3, 1), np.uint8)).astype(bool)

    def place(self, x_px: float, y_px: float) -> tuple[float, int] | None:
        """A full-res point on the turned frame: its column (half-res, fractional) and its
        row, or None when the three rows round it are not all in the frame."""
        px, py = self.rotation @ np.array([(x_px - 0.5) / 2.0, (y_px - 0.5) / 2.0, 1.0])
        r = int(round(py))
        return None if r < 1 or r > self.darkness.shape[0] - 2 else (float(px), r)


def groove_stretches(wall: _Wall, angle_deg: float, marks: np.ndarray, mm_per_px: float,
                     cfg: DefectConfig) -> GrooveStretches:
    """How dark a groove family's lines get over the frame: the wall's darkness (its level
    taken out, the cross-hatch left in), turned so the family runs along rows, averaged
    along them over ``cfg.aligned_stretch_mm``, and integrated across the lines over a
    core ``cfg.aligned_stretch_core_mm`` wide less the flanks beyond it (the same width
    again on each side). A line's darkness integrated across is what the blur leaves
    unchanged, so a thin deep groove and a broader shallow one compare fairly. The
    population is each line's crest (a maximum across the lines) on the wall clear of the
    holes' zones and of ``marks`` (half res, the defects measured), and the frame's dark
    end of it its ``cfg.aligned_stretch_quantile``-th percentile."""
    half = 2.0 * mm_per_px  # mm per half-res px
    along = max(int(round(cfg.aligned_stretch_mm / half)), 3)
    core = max(int(round(cfg.aligned_stretch_core_mm / 2.0 / half)), 1)
    m, (w2, h2) = _rotation(wall.darkness.shape, angle_deg)
    dark = cv2.warpAffine(np.where(wall.valid, wall.darkness, 0.0).astype(np.float32), m, (w2, h2))
    usable = cv2.warpAffine((wall.valid & ~marks).astype(np.float32), m, (w2, h2))
    mean = cv2.blur(dark, (along, 1))
    usable = cv2.blur(usable, (along, 1)) > 0.99
    n = 2 * core + 1
    kernel = np.zeros((3 * n, 1), np.float32)
    kernel[n:2 * n] = 1.0
    kernel[:n] = kernel[2 * n:] = -0.5
    integrated = 2.0 * cv2.filter2D(mean, -1, kernel, borderType=cv2.BORDER_REPLICATE)
    crest = (integrated >= np.roll(integrated, 1, 0)) & (integrated >= np.roll(integrated, -1, 0)) & (integrated > 0)
    usable &= cv2.erode(usable.astype(np.uint8), np.ones((3 * n, 1), np.uint8)).astype(bool)
    pop = integrated[crest & usable]
    q = float(np.percentile(pop, cfg.aligned_stretch_quantile)) if pop.size >= 1000 else None
    on_wall = cv2.warpAffine(wall.valid.astype(np.float32), m, (w2, h2)) > 0.99
    return GrooveStretches(m, integrated, q, on_wall, along)


def stretch_darkness(stretches: GrooveStretches, x_px: float, y_px: float, length_px: float,
                     middle: float = 0.7) -> float | None:
    """A mark's darkness integrated across it, as ``groove_stretches`` reads the grooves':
    the median, over the ``middle`` share of its length, of the best of the three rows
    round its centre line (full-res centre and length; the mark runs along the family)."""
    at = stretches.place(x_px, y_px)
    if at is None:
        return None
    px, r = at
    reach = middle * length_px / 4.0
    c0, c1 = max(int(np.floor(px - reach)), 0), min(int(np.ceil(px + reach)) + 1, stretches.darkness.shape[1])
    if c1 <= c0:
        return None
    return float(np.median(stretches.darkness[r - 1:r + 2, c0:c1].max(axis=0)))


class RunOn(NamedTuple):
    """How a mark's line runs on beyond it (``line_runs_on``)."""

    share: float  # the line's share beyond the mark at the bar, less the whole wall's share
    z: float  # that excess over its spread had the line been any line of the wall's


def line_runs_on(stretches: GrooveStretches, x_px: float, y_px: float, length_px: float, own: float,
                 mm_per_px: float, cfg: DefectConfig) -> RunOn | None:
    """How far a mark's line runs on as a groove beyond it: the share of its family's line
    through the mark's centre (``stretches``: the family's, the mark on one of its lines;
    full-res centre and length), beyond its ends and on the wall, where the line's stretches
    are at least ``cfg.groove_run_on_darkness`` of the mark's own darkness ``own``
    (``stretch_darkness``), read as that function reads the mark, the best of the three rows
    round the line; less the share of the whole wall's places that reach it so (what any
    line of the wall reads: a faint scratch among deep grooves has half its darkness
    reached along most lines). None when less than ``cfg.groove_run_on_min_mm`` of the line
    lies on the wall beyond the mark, or the mark is no darker than its flanks. A honing
    groove runs across the frame (its depth fading, its pieces cut apart where the grooves
    stop short); a scratch is one furrow, and its line beyond it is the wall's.

    ``z``: that excess in standard deviations of a line's share had the line been any of
    the wall's, its stretches beyond the mark (``along_px`` each) taken as independent
    draws at the wall's share, that share read as at least one stretch's worth (a wall
    where nothing reaches the bar cannot tell a share under one in so many)."""
    at = stretches.place(x_px, y_px) if own > 0.0 else None
    if at is None:
        return None
    px, r = at
    line, ok = stretches.best[r], stretches.best_on_wall[r]  # the three rows round its line
    # beyond its ends by half a stretch and a little: no stretch there reads the mark itself
    reach = length_px / 4.0 + stretches.along_px / 2.0 + 3.0
    beyond = ok & (np.abs(np.arange(line.size) - px) > reach)
    if beyond.sum() * 2.0 * mm_per_px < cfg.groove_run_on_min_mm:
        return None
    bar = cfg.groove_run_on_darkness * own
    anywhere = stretches.best[stretches.best_on_wall]
    wall_share = float(np.mean(anywhere >= bar)) if anywhere.size else 0.0
    excess = float(np.mean(line[beyond] >= bar)) - wall_share
    draws = max(float(beyond.sum()) / stretches.along_px, 1.0)
    p = min(max(wall_share, 1.0 / draws), 0.5)
    return RunOn(excess, excess / float(np.sqrt(p * (1.0 - p) / draws)))


def find_candidates(wall: _Wall, cfg: DefectConfig) -> list[tuple[np.ndarray, int, tuple[int, int, int, int], float]]:
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


def seed_in_box(labels: np.ndarray, label: int, box: tuple[int, int, int, int]) -> np.ndarray:
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


def split_furrows(seed: np.ndarray, band_px: float = 3.0, min_len_px: float = 40.0, min_turn_deg: float = 15.0,
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


def one_furrow(seed: np.ndarray, band_px: float = 3.0, min_len_px: float = 40.0, min_share: float = 0.75
               ) -> tuple[float, float, float, float] | None:
    """The line of a candidate's seed that is one furrow (``split_furrows``'s test for one
    mark: its principal axis holds 85 % of its half-res pixels within ``band_px``, bent
    by 2.5 % of its length; or, where a spur tilts that axis, the axis of the points
    within reach of it holds ``min_share`` of them), at least ``min_len_px`` long (full
    px), as ``split_furrows``'s lines (box px); None for any other seed."""
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


def line_through_blob(seed: np.ndarray, band_px: float = 3.0, min_arm_px: float = 20.0, min_share: float = 0.75
                      ) -> tuple[tuple[float, float, float, float], np.ndarray] | None:
    """The line of a thin mark that runs through blobs of a candidate's seed (pores on a
    scratch's line: one connected seed, which measured whole reads as one elongated pore
    and loses the scratch), as ``one_furrow``'s lines (box px), and the blobs on it (bool
    over the seed's box); None when the seed is no such mark. The blobs are what an
    opening by a disc half the seed's largest inscribed diameter keeps; the arms are the
    seed beyond them. The lines tried: the largest arm's axis, the axis of two arms, and
    the line from a blob's centre through an arm. A line passes (``_through_blobs``) when
    the arms on it (``min_share`` of the half-res pixels within ``band_px`` of it, bent by
    2.5 % of their length) pass through a blob (its centre within its inscribed radius of
    the line), are no wider than half the widest such blob, and hold at least
    ``min_arm_px`` (full px) of the line beyond the blobs or between them; of those that
    pass, the one holding most of the arms is the scratch's."""
    half = seed[::2, ::2].astype(np.uint8)
    if not half.any():
        return None
    dt = cv2.distanceTransform(half, cv2.DIST_L2, 3)
    r = float(dt.max())
    if r < 3.0:
        return None  # no blob wider than a scratch's arm
    k = 2 * int(np.ceil(r / 2.0)) + 1
    opened = cv2.morphologyEx(half, cv2.MORPH_OPEN, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k)))
    n, lab, stats, cents = cv2.connectedComponentsWithStats(opened, connectivity=8)
    if n < 2:
        return None
    arms = half.astype(bool) & ~cv2.dilate((lab > 0).astype(np.uint8), np.ones((3, 3), np.uint8),
                                           iterations=2).astype(bool)
    yy, xx = np.nonzero(arms)
    if yy.size < min_arm_px / 2.0:
        return None
    pts = np.column_stack([xx, yy]).astype(np.float64)
    # the line: the axis of the largest arm, then of the arms' points within reach of it
    # (a blob's ragged fringe leaves bits beside it that are no arm), three times ...
    na, alab = cv2.connectedComponents(arms.astype(np.uint8), connectivity=8)
    big = np.bincount(alab[yy, xx], minlength=na)[1:]
    order = 1 + np.argsort(big)[::-1][:4]
    if big[order[0] - 1] < 3:
        return None
    # ... or, of short arms (a few px: a 4 x 3 px arm has no axis of its own), the line
    # through two of them on the blob's opposite sides, or from a blob's centre through
    # one (an arm as wide as it is long: 7 x 6 px below a 0.3 mm pore, read across the
    # scratch): of those that pass the tests below, the one that holds most of the arms
    lines = []
    for group in [(order[0],)] + [(a, b) for i, a in enumerate(order) for b in order[i + 1:]]:
        sel = np.isin(alab[yy, xx], group)
        if sel.sum() >= 3:
            c_, t0, b_, _s = _principal_line(pts[sel], band_px)
            lines.append((c_, t0, b_, True))
    for jb in range(1, n):
        for a in order:
            sel = alab[yy, xx] == a
            if sel.sum() >= 3:
                c_ = pts[sel].mean(axis=0)
                d_ = c_ - cents[jb]
                if np.hypot(*d_) > 1.0:
                    lines.append((c_, d_ / np.hypot(*d_), 0.0, False))
    found = []
    for c_, t0, b_, refine in lines:
        got = _through_blobs(pts, c_, t0, b_, refine, r, n, lab, dt, cents, band_px, min_arm_px, min_share)
        if got is not None:
            c_, t0, b_ = got[:3]
            found.append((int(np.sum(np.abs((pts - c_) @ np.array([-t0[1], t0[0]])) <= band_px + b_)), got))
    if not found:
        return None
    centre, t_, bend, core, j = max(found, key=lambda hg: hg[0])[1]
    # the line's point: the widest blob's centre projected onto the arms' axis
    p = centre + ((cents[j] - centre) @ t_) * t_
    full = np.repeat(np.repeat(core, 2, axis=0), 2, axis=1)[:seed.shape[0], :seed.shape[1]]
    return (2.0 * p[0] + 0.5, 2.0 * p[1] + 0.5, float(np.arctan2(t_[1], t_[0])), 2.0 * bend), full & seed


def _through_blobs(pts, centre, t_, bend, refine, r, n, lab, dt, cents, band_px, min_arm_px, min_share):
    """``line_through_blob``'s tests of one line (half-res px: a point, its direction, its
    bend; ``refine``: fitted again to the arms' points near it): (the line, the blobs it
    runs through, the widest's label) or None."""
    normal = np.array([-t_[1], t_[0]])
    share = float(np.mean(np.abs((pts - centre) @ normal) <= band_px + bend))
    for reach in ((0.5 * r, 0.0, 0.0) if refine else ()):
        # first loosely: a short arm's own axis may be 10-15 deg off, and the arm on a
        # blob's other side then lies beside it
        near = np.abs((pts - centre) @ np.array([-t_[1], t_[0]])) <= band_px + bend + reach
        if near.sum() < 3:
            return None
        centre, t_, bend, share = _principal_line(pts[near], band_px)
    if share < min_share:
        return None
    normal = np.array([-t_[1], t_[0]])
    pts = pts[np.abs((pts - centre) @ normal) <= band_px + bend]
    if len(pts) < min_arm_px / 2.0:
        return None
    # the blobs the line runs through: each centre within its inscribed radius of it
    on = [(float(dt[lab == j].max()), j) for j in range(1, n)
          if abs((cents[j] - centre) @ normal) <= float(dt[lab == j].max())]
    if not on:
        return None
    r_on, j = max(on)
    # the arms' width across their axis (half-res px): thin beside the blobs
    if 2.0 * float(np.percentile(np.abs((pts - centre) @ normal), 90)) > r_on:
        return None
    core = np.isin(lab, [q for _r, q in on])
    # the arms' length along the line outside the blobs (full px): beyond them, or between
    # two of them (a scratch whose ends lie under two pores)
    cyy, cxx = np.nonzero(core)
    blob_bins = np.floor((np.column_stack([cxx, cyy]) - centre) @ t_).astype(int)
    arm_bins = np.floor((pts - centre) @ t_).astype(int)
    lo = min(int(blob_bins.min()), int(arm_bins.min()))
    covered = np.zeros(max(int(blob_bins.max()), int(arm_bins.max())) - lo + 1, bool)
    for jb in [q for _r, q in on]:
        yb, xb = np.nonzero(lab == jb)
        ab = (np.column_stack([xb, yb]) - centre) @ t_
        covered[int(np.floor(ab.min())) - lo:int(np.floor(ab.max())) - lo + 1] = True
    if 2.0 * np.count_nonzero(~covered[np.unique(arm_bins - lo)]) < min_arm_px:
        return None
    return centre, t_, bend, core, j


def line_band(shape: tuple[int, int], offset: tuple[int, int], line: tuple[float, float, float, float],
              half_px: float) -> np.ndarray:
    """The pixels of a box (``shape``, its corner at ``offset`` in the frame) within
    ``half_px`` of a line (``split_furrows``'s, frame px), widened by the line's allowance for
    a bend."""
    x, y, a, bend = line
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]]
    return np.abs((xx + offset[0] - x) * -np.sin(a) + (yy + offset[1] - y) * np.cos(a)) <= half_px + bend


def group_collinear(candidates, max_gap_half_px: float = 20.0) -> list[list[int]]:
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


def fit_plane(values: np.ndarray, xx: np.ndarray, yy: np.ndarray, use: np.ndarray) -> np.ndarray:
    """A robust plane through ``values`` where ``use`` (two least-squares passes, the
    second without points beyond 3 robust sigma)."""
    a = np.column_stack([np.ones(use.sum()), xx[use], yy[use]])
    v = values[use]
    coef = np.linalg.lstsq(a, v, rcond=None)[0]
    res = v - a @ coef
    keep = np.abs(res) < 3.0 * max(mad_sigma(res), 1e-6)
    if keep.sum() > 10:
        coef = np.linalg.lstsq(a[keep], v[keep], rcond=None)[0]
    return coef[0] + coef[1] * xx + coef[2] * yy


def groove_profiles(d: np.ndarray, xx: np.ndarray, yy: np.ndarray, use: np.ndarray, angles_deg,
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
class Patch:
    x0: int
    y0: int
    residual: np.ndarray  # relative darkness less level and grooves (full res)
    level: np.ndarray  # the wall's level (DN)
    excluded: np.ndarray  # bool: candidate (dilated) or hole zone
    zone: np.ndarray  # bool: the holes' zone alone
    grooves: np.ndarray  # the cross-hatch's modelled darkness (subtracted from residual)
    noise: float  # robust std of the residual per pixel
    noise_box5: float  # robust std of the residual's 5x5 box mean (correlated noise)


def level_dip(img: np.ndarray, patch: Patch, region: np.ndarray, level_sigma_px: float) -> float:
    """How far the frame's level lies under a mark (``region``, bool over the patch) below
    the level taken round it (a Gaussian of ``level_sigma_px``, full-res px, over the
    patch, its candidate and the holes' zone left out, as ``local_patch`` takes it again):
    the mean shortfall over the mark, as a share of the frame's level (0: none)."""
    h, w = patch.level.shape
    p = img[patch.y0:patch.y0 + h, patch.x0:patch.x0 + w].astype(np.float32)
    mean, den = weighted_gaussian_mean(p, (~patch.excluded).astype(np.float32), level_sigma_px)
    at = region & (den > 0.05)
    if not at.any():
        return 0.0
    level = np.maximum(patch.level[at], 1.0)
    return float(np.mean(np.maximum(mean[at] - level, 0.0) / level))


def local_patch(img: np.ndarray, box: tuple[int, int, int, int], seed_mask: np.ndarray, zone: np.ndarray,
                angles_deg, wall_level: np.ndarray, level_sigma_px: float | None = None) -> Patch | None:
    """The wall model of a patch at full resolution: the frame's level (``wall_level``,
    full res) and a robust plane for what it leaves, and the grooves as local profiles,
    all fitted outside the candidate (``seed_mask``, bool over the box, dilated here)
    and the holes' zone.

    ``level_sigma_px``: the frame level's Gaussian (full-res px). Given, the level is
    taken again over the patch with the candidate left out, and the higher of the two
    stands: the frame's level leaves out only what it found clearly dark, and a large
    pale mark that it did not find so pulled the level down under itself."""
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
    if level_sigma_px:
        mean, den = weighted_gaussian_mean(p, use.astype(np.float32), level_sigma_px)
        level = np.where(den > 0.05, np.maximum(level, mean), level).astype(np.float32)
    d = 1.0 - p / np.maximum(level, 1.0)
    d -= fit_plane(d, xx - x0, yy - y0, use)
    grooves = groove_profiles(d, xx, yy, use, angles_deg)
    r = (d - grooves).astype(np.float32)
    r[zone[y0:y1, x0:x1]] = 0.0
    noise = max(mad_sigma(r[use]), NOISE_FLOOR)
    box5 = cv2.blur(r, (5, 5))
    inner = cv2.erode(use.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    noise5 = max(mad_sigma(box5[inner]) if inner.sum() > 30 else noise / 2.0, NOISE_FLOOR / 5.0)
    return Patch(x0, y0, r, level, excluded, zone[y0:y1, x0:x1], grooves.astype(np.float32), float(noise),
                 float(noise5))
