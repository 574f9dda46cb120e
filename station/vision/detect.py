"""Coarse hole detection: where are dark discs, roughly, in a whole frame?

Why this way: the fine stage is accurate but needs a start within a few pixels; the
coarse stage must be fast (a 1280x1024 frame in about a millisecond) and must not be
fooled by the honed texture, vignetting or low contrast.  So it works on a 4x
area-downsampled frame (holes of 20-100 px become 5-25 px, honing grooves of 1-3 px
are averaged away), divides by a local background, the median over a window twice the
largest hole (vignetting and blotches cancel), thresholds the relative darkness against
the frame's own robust spread, removes thin structures by an opening, and keeps
connected components whose area, fill and darkness look like a hole; a component that
fails (a hole merged with dark grooves) is searched again at rising thresholds.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np

from station.vision.fit import median

#: downsampling factor of the coarse stage (holes >= 20 px stay >= 5 px across)
COARSE_FACTOR = 4
#: further downsampling of the coarse frame for its (smooth) background estimate
BACKGROUND_FACTOR = 4


@dataclass(frozen=True)
class DetectConfig:
    min_diameter_px: float = 16.0  # smaller than the smallest hole we measure (20 px)
    max_diameter_px: float = 120.0  # larger than the largest (100 px)
    #: minimum relative darkness of a hole against its local wall.  The station's
    #: lighting gives holes 30-80 % darker than the wall (renderer's contrast range);
    #: honing grooves averaged over 4x4 px darken by < 10 %.
    min_darkness: float = 0.15
    #: threshold in robust standard deviations of the frame's darkness (texture + noise),
    #: capped so that a strongly textured wall cannot hide a low-contrast hole: on
    #: 13-15 % grooves a 30 %-contrast hole's coarse darkness is 0.22-0.28 (the grooves
    #: darken the median background), under the earlier cap of 0.3.  The fine stage
    #: rejects what the lower cap lets through (no closed, round rim; no blurred disc)
    k_sigma: float = 4.0
    max_threshold: float = 0.2
    min_fill: float = 0.45  # area / bounding-box area; a disc has pi/4 = 0.785
    #: a component that fails the shape tests (a hole merged with grooves or a blotch)
    #: is searched again at thresholds this much higher, step by step, until what is
    #: left passes or vanishes: a groove's darkness ends below a hole's, wherever the two
    #: lie (one fixed step of 0.2 overshot the darkness of holes of 30-40 % contrast)
    split_step: float = 0.05
    #: ... up to this relative darkness
    split_max: float = 0.95


#: the largest hole (mm) the coarse stage looks for when the frame's scale is known: its
#: 120 px at the station's camera (0.010 mm/px); a finer camera's frames show the same
#: holes larger in px (``for_scale``)
MAX_HOLE_MM = 1.2


def for_scale(cfg: DetectConfig, mm_per_px: float | None) -> DetectConfig:
    """``cfg`` with its largest diameter widened to ``MAX_HOLE_MM`` at this scale (never
    narrowed: the px range is also what the fine stage can measure).  At 0.007 mm/px the
    bench's 0.6-1.0 mm holes are 86-143 px, and those over 120 px were taken for pores."""
    if not mm_per_px or mm_per_px <= 0:
        return cfg
    widest = MAX_HOLE_MM / mm_per_px
    if widest <= cfg.max_diameter_px:
        return cfg
    return replace(cfg, max_diameter_px=float(widest))


@dataclass(frozen=True)
class Candidate:
    x_px: float
    y_px: float
    radius_px: float
    touches_border: bool
    darkness: float  # median relative darkness inside (0..1)


def oversized_discs(image: np.ndarray, cfg: DetectConfig = DetectConfig()) -> list[Candidate]:
    """Whole dark discs of ``image`` wider than ``cfg.max_diameter_px``, which
    ``detect_candidates`` with ``cfg`` leaves out (up to half the frame's shorter side).
    Without a scale the coarse stage stops at the station camera's largest hole; a finer
    camera's larger holes are then not measured, and this says that they are there."""
    widest = 0.5 * min(image.shape[:2])
    if widest <= cfg.max_diameter_px:
        return []
    wide = detect_candidates(image, replace(cfg, max_diameter_px=float(widest)))
    return [c for c in wide if not c.touches_border and 2.0 * c.radius_px > cfg.max_diameter_px]


def _odd(n: float) -> int:
    n = int(np.ceil(n))
    return n + 1 - n % 2


def detect_candidates(image: np.ndarray, cfg: DetectConfig = DetectConfig()) -> list[Candidate]:
    """Dark disc-like blobs of a grey frame, in full-resolution pixel coordinates."""
    f = COARSE_FACTOR
    h, w = image.shape
    hc, wc = h // f * f, w // f * f
    # 4x4 area means as two exact 2x2 steps in float32: OpenCV's INTER_AREA has a fast
    # path for a factor of 2 (0.2 ms per 1280x1024 frame against 0.6 ms for 4x at once)
    small = image[:hc, :wc].astype(np.float32)
    for _ in range(int(round(np.log2(f)))):
        small = cv2.resize(small, (small.shape[1] // 2, small.shape[0] // 2), interpolation=cv2.INTER_AREA)
    small_u8 = np.clip(np.rint(small), 0, 255).astype(np.uint8)  # medianBlur wants 8 bits
    # the wall's typical level: a median over a window twice the largest hole, where
    # a hole covers at most a fifth of the window and so cannot pull the median; unlike
    # a closing (upper envelope) it follows dark blotches and vignetted corners
    # The background is smooth (vignetting, blotches of ~64 px and more), so the median
    # runs on a further 4x downsampled frame (a 100 px hole is 6 px there, the window
    # 15 px), is smoothed to remove the median's steps, and is brought back up: the
    # same background as a 61 px median at 1/4 scale for a tenth of the time.
    g = BACKGROUND_FACTOR
    hb, wb = small_u8.shape[0] // g * g, small_u8.shape[1] // g * g
    tiny = cv2.resize(small_u8[:hb, :wb], (wb // g, hb // g), interpolation=cv2.INTER_AREA)
    k = _odd(2 * cfg.max_diameter_px / (f * g))
    background = cv2.medianBlur(tiny, k).astype(np.float32)
    background = cv2.blur(background, (3, 3), borderType=cv2.BORDER_REPLICATE)  # median steps
    background = cv2.resize(background, (small_u8.shape[1], small_u8.shape[0]), interpolation=cv2.INTER_LINEAR)
    darkness = 1.0 - small / np.maximum(background, 1.0)
    # robust spread of texture + noise; every 2nd pixel each way is plenty for a median
    sample = darkness[::2, ::2]
    med = median(sample)
    spread = 1.4826 * median(np.abs(sample - med))  # MAD -> sigma for Gaussian data
    threshold = med + min(max(cfg.k_sigma * spread, cfg.min_darkness), cfg.max_threshold)
    # higher thresholds separate a dark hole from a groove that touches it (merged, the
    # pair fails the shape tests).  A higher level's mask lies inside the lower one's, so
    # it is only searched inside the components that failed, each level inside the
    # previous level's failures; what two levels find is kept once
    out, failed = _components(darkness, threshold, cfg)
    first_failed = failed  # the ladder rebinds ``failed``, never changes this list
    level = threshold
    while failed and level + cfg.split_step <= cfg.split_max:
        level += cfg.split_step
        still: list[tuple[int, int, int, int]] = []
        for x0, y0, x1, y1 in failed:
            sub, sub_failed = _components(darkness, level, cfg, (x0, y0, x1, y1))
            still += sub_failed
            _keep_once(out, sub)
        failed = still
    # a hole that a groove darker than it touches: no level parts them (above the groove's
    # darkness the hole is gone as well; wide envelope at a 22 deg hatch, clean frame
    # 1097092: a 0.79 mm hole of 33 % contrast, its coarse darkness 0.26 beside 13 %
    # grooves, lost, and a piece of it read as a 0.47 mm pore). A groove is a few px wide
    # (one or two coarse px), a hole at least ``min_diameter_px``: where the rising levels
    # cannot part them, each window that failed is searched again with the mask opened
    # by a disc as wide as the smallest hole, which cuts the grooves off (in every window
    # that failed: the band alone, left at a higher level, may pass as a hole the
    # frame's border cuts). What it finds is a candidate as any other, kept once: the
    # fine stage judges its rim
    wide_open = _odd(cfg.min_diameter_px / f)
    for x0, y0, x1, y1 in first_failed:
        level, sub = threshold, []
        while level <= cfg.split_max:
            sub, sub_failed = _components(darkness, level, cfg, (x0, y0, x1, y1), open_px=wide_open)
            if sub or not (sub_failed or (darkness[y0:y1, x0:x1] > level).any()):
                break
            level += cfg.split_step
        _keep_once(out, sub)
    return out


def _keep_once(out: list[Candidate], found: list[Candidate]) -> None:
    """Append to ``out`` each of ``found`` whose centre is not within an earlier
    candidate's radius (at least 8 px): what two searches find is kept once."""
    for cand in found:
        if not any(np.hypot(cand.x_px - o.x_px, cand.y_px - o.y_px) < max(o.radius_px, 8.0) for o in out):
            out.append(cand)


def _components(
    darkness: np.ndarray, threshold: float, cfg: DetectConfig, window: tuple[int, int, int, int] | None = None,
    open_px: int = 3,
) -> tuple[list[Candidate], list[tuple[int, int, int, int]]]:
    """Disc-like connected components of ``darkness > threshold`` (full-resolution px).

    ``window`` (x0, y0, x1, y1, coarse px) limits the search to part of the frame;
    ``open_px``: the disc (coarse px) the mask is opened with.
    Also returns the windows (one coarse pixel larger) of components large enough to
    be a hole that failed the shape tests: a hole merged with a groove, perhaps.
    """
    f = COARSE_FACTOR
    fh, fw = darkness.shape
    wx0, wy0, wx1, wy1 = window if window is not None else (0, 0, fw, fh)
    dark = darkness[wy0:wy1, wx0:wx1]
    mask = (dark > threshold).astype(np.uint8)
    mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (open_px, open_px)))
    # Grana's block-based labelling: the same components as the default (Spaghetti) and
    # the same label order (raster scan), at a third of its time on these sparse masks
    # (0.09 against 0.30 ms on a 320x256 mask)
    n, labels, stats, centroids = cv2.connectedComponentsWithStatsWithAlgorithm(mask, 8, cv2.CV_32S, cv2.CCL_GRANA)
    min_area = np.pi / 4 * (cfg.min_diameter_px / f) ** 2
    max_area = np.pi / 4 * (cfg.max_diameter_px / f) ** 2
    out: list[Candidate] = []
    failed: list[tuple[int, int, int, int]] = []
    for i in range(1, n):
        x, y, bw, bh, area = stats[i]
        x, y = x + wx0, y + wy0
        touches = x == 0 or y == 0 or x + bw >= fw or y + bh >= fh
        # partial holes may be small slivers; demand at least a quarter of the minimum area
        if area < (0.25 if touches else 1.0) * min_area:
            continue
        if (
            area > max_area
            or area / float(bw * bh) < cfg.min_fill
            or (not touches and not (0.5 <= bw / bh <= 2.0))
        ):
            failed.append((max(x - 1, 0), max(y - 1, 0), min(x + bw + 1, fw), min(y + bh + 1, fh)))
            continue
        inside = dark[labels == i]
        cx_s, cy_s = centroids[i][0] + wx0, centroids[i][1] + wy0
        if touches:
            radius_s = max(bw, bh) / 2.0  # the cut component's area under-states the hole
        else:
            radius_s = np.sqrt(area / np.pi)
        # small pixel j covers full pixels f*j .. f*j+f-1, whose centre is f*j + (f-1)/2
        out.append(
            Candidate(
                x_px=float(cx_s * f + (f - 1) / 2),
                y_px=float(cy_s * f + (f - 1) / 2),
                radius_px=float(radius_s * f),
                touches_border=bool(touches),
                darkness=median(inside),
            )
        )
    return out, failed
