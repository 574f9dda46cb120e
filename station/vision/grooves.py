"""The honing cross-hatch over a hole's wide neighbourhood: one profile per groove family;
and the hatch's two directions, read from the frame's power spectrum (``frame_hatch``,
``honing_directions``: the honing angle is the part's, not the station's: 20-35 deg for
plateau honing, 60-75 for helical slide honing).

Why: a honing groove is a straight line that crosses the whole frame, so its profile
across its direction is read on every wall pixel along it, not only on the 18 px ring
around one hole (``photometric._groove_field``).  On the ring each 0.5 px bin of a
family's profile holds some tens of pixels of grain; along a window of a few hundred px
it holds hundreds.  ``measure_holes`` reads a window of 250 px (150 before round 19)
beyond 1.3 x each candidate's radius (``MeasureConfig.groove_window_px``), not the
frame: a lens's barrel distortion bends a straight groove by tens of pixels across a
frame, by under a pixel across such a window near the optical axis.
What the frame cannot give is a groove's depth at the hole: grooves fade in and out
along their length (worn stones, plateau honing) over ~100 px.  So the frame gives the
shape P_k(u) of each family k, and each hole's ring gives only how deep the family is
there: an amplitude that varies linearly across the ring (three numbers per family, in
place of a profile of some hundred bins).
What that leaves, the ring reads as a profile of its own on each side of the hole along
the grooves, shrunk towards 0 (``PhotometricConfig.groove_frame_local_sides``): a
groove's two crossings of the rim differ as it fades.

Model: the wall's relative reflectance about its smooth level (``wall_level``: a 40 px
Gaussian of the frame normalised by a mask of its holes, at 1/8 scale, once per frame)
is the sum of the families' profiles, each a
function of u_k = -sin(a_k) x + cos(a_k) y, fitted by backfitting bin means of 0.5 px
(robust: pixels beyond 4 MAD, pores and scratches, drop out).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np
from numba import njit
from scipy.ndimage import gaussian_filter1d

#: the smooth level the grooves are read against: a Gaussian of this sigma (px), wide
#: against a groove (0.8-3 px) and narrow against the blotches and the vignetting
SMOOTH_SIGMA_PX = 40.0
#: pixels this many robust standard deviations off their bin are outliers (defects)
_CLIP = 4.0
#: every STRIDE-th row is read
STRIDE = 4
#: the smooth level is computed at 1/_LEVEL_SCALE of the resolution
_LEVEL_SCALE = 8
#: fewer wall pixels read than this: no profiles
MIN_PIXELS = 2000


@dataclass(frozen=True)
class FrameGrooves:
    """Each family's relative profile across its direction, over the frame."""

    angles_rad: tuple[float, ...]
    u0: tuple[float, ...]  # u of each profile's first bin centre
    step_px: float
    profiles: tuple[np.ndarray, ...]  # relative (0 = the wall's level), one per family
    level: "WallLevel"  # the wall's smooth level over the frame
    shape: tuple[int, int]  # (height, width) of the window read
    origin: tuple[int, int] = (0, 0)  # (x, y) of the window's first pixel in the frame

    def level_at(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """The wall's smooth level (DN) at frame pixels (x, y)."""
        return self.level.at(x, y)

    def values(self, x: np.ndarray, y: np.ndarray) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Per family: the relative profile at pixels (x, y), and its derivative in u."""
        vals, ders = [], []
        for a, u0, p in zip(self.angles_rad, self.u0, self.profiles):
            u = (-np.sin(a) * x + np.cos(a) * y - u0) / self.step_px
            grid = np.arange(p.size, dtype=np.float64)
            vals.append(np.interp(u, grid, p, left=0.0, right=0.0))
            ders.append(np.interp(u, grid, np.gradient(p) / self.step_px, left=0.0, right=0.0))
        return vals, ders


@dataclass(frozen=True)
class WallLevel:
    """The wall's smooth level over a frame (DN), the holes left out: a Gaussian of
    ``SMOOTH_SIGMA_PX`` normalised by the mask, kept at 1/``_LEVEL_SCALE`` scale."""

    small: np.ndarray
    shape: tuple[int, int]  # (height, width) of the frame

    def at(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """The level at frame pixels (x, y) (bilinear, held at the frame's edge)."""
        return _upsample(self.small, self.shape, np.asarray(x, np.float64), np.asarray(y, np.float64))


def _hole_mask(shape: tuple[int, int], holes, x0: int = 0, y0: int = 0) -> np.ndarray:
    mask = np.ones(shape, np.float32)
    for x, y, r in holes:
        cv2.circle(mask, (int(round(x - x0)), int(round(y - y0))), int(np.ceil(r + 6.0)), 0.0, -1)
    return mask


def wall_level(image: np.ndarray, holes: list[tuple[float, float, float]]) -> WallLevel:
    """The frame's ``WallLevel``; ``holes`` as ``frame_grooves`` takes them."""
    h, w = image.shape[:2]
    f = _LEVEL_SCALE
    sw, sh = max(w // f, 1), max(h // f, 1)
    # area-averaged first (the level is smooth on 40 px): the holes masked at that scale
    small = cv2.resize(image, (sw, sh), interpolation=cv2.INTER_AREA).astype(np.float32)
    mask = np.ones((sh, sw), np.float32)
    for x, y, r in holes:
        cv2.circle(mask, (int(round((x + 0.5) * sw / w - 0.5)), int(round((y + 0.5) * sh / h - 0.5))),
                   int(np.ceil((r + 6.0) * sw / w)) + 1, 0.0, -1)
    mean, _ = weighted_gaussian_mean(small, mask, SMOOTH_SIGMA_PX * sw / w, floor=1e-3)
    return WallLevel(mean.astype(np.float32), (h, w))


def weighted_gaussian_mean(values: np.ndarray, weights: np.ndarray, sigma: float,
                           floor: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """The Gaussian-weighted local mean of ``values`` over ``weights`` (normalised
    convolution: what the weights leave out does not count), and the weights' own
    Gaussian sum (near 0 where almost nothing was averaged; divided by no less than
    ``floor``). Borders reflected."""
    num = cv2.GaussianBlur(values * weights, (0, 0), sigma, borderType=cv2.BORDER_REFLECT)
    den = cv2.GaussianBlur(weights, (0, 0), sigma, borderType=cv2.BORDER_REFLECT)
    return num / np.maximum(den, floor), den


def frame_grooves(image: np.ndarray, holes: list[tuple[float, float, float]], angles_deg=(30.0, -30.0),
                  step_px: float = 0.5, sweeps: int = 3, stride: int = STRIDE,
                  window: tuple[int, int, int, int] | None = None,
                  level: WallLevel | None = None) -> FrameGrooves | None:
    """The families' profiles from the wall of a grey frame; ``holes``: (x, y, radius)
    of the dark holes to leave out (with a margin for their blur).  None when too little
    wall is left.  Every ``stride``-th row is read (a 0.5 px bin along a line across the
    frame still holds ~100 pixels or more).  ``window``: (x0, y0, x1, y1), read only
    that part of the frame (a lens's distortion bends a straight groove over a frame,
    not over a hole's neighbourhood).  ``level``: the frame's ``wall_level`` (computed
    here when not given: give it when reading several windows of one frame)."""
    x0, y0, x1, y1 = window if window is not None else (0, 0, image.shape[1], image.shape[0])
    x0, y0 = max(int(x0), 0), max(int(y0), 0)
    x1, y1 = min(int(x1), image.shape[1]), min(int(y1), image.shape[0])
    if x1 - x0 < 16 or y1 - y0 < 16:
        return None
    if level is None:
        level = wall_level(image, holes)
    img = image[y0:y1, x0:x1].astype(np.float32)
    h, w = img.shape
    mask = _hole_mask((h, w), holes, x0, y0)
    rows = np.arange(0, h, stride)
    lv = level.at(np.arange(x0, x1, dtype=np.float64)[None, :], (rows + y0).astype(np.float64)[:, None])
    ok = (mask[rows] > 0) & (lv > 5.0)
    if ok.sum() < MIN_PIXELS:
        return None
    rel = (img[rows] / np.maximum(lv, 1e-3) - 1.0).astype(np.float64)
    angles = np.array([np.deg2rad(a) for a in angles_deg], dtype=np.float64)
    prof, u0 = _profiles(rel, ok, np.arange(x0, x1, dtype=np.float64), (rows + y0).astype(np.float64), angles,
                         float(step_px), int(sweeps))
    return FrameGrooves(tuple(float(a) for a in angles), tuple(float(v) for v in u0), step_px,
                        tuple(np.ascontiguousarray(p) for p in prof), level, (h, w), (x0, y0))


def _upsample(small: np.ndarray, shape: tuple[int, int], x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``small`` (an area-averaged image of ``shape``) read bilinearly at full-resolution
    pixels (x, y), as ``cv2.resize(small, shape, INTER_LINEAR)`` would there; x and y
    broadcast together."""
    h, w = shape
    sh, sw = small.shape
    x, y = np.broadcast_arrays(x, y)
    mx = ((x + 0.5) * (sw / w) - 0.5).astype(np.float32).ravel()
    my = ((y + 0.5) * (sh / h) - 0.5).astype(np.float32).ravel()
    # remap's maps are at most 32767 on a side: the points as rows of 1024
    n = mx.size
    cols = 1024
    pad = (-n) % cols
    mx, my = np.pad(mx, (0, pad), mode="edge"), np.pad(my, (0, pad), mode="edge")
    out = cv2.remap(small, mx.reshape(-1, cols), my.reshape(-1, cols), cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_REPLICATE)
    return out.ravel()[:n].reshape(x.shape)


@njit(cache=True, nogil=True)
def _profiles(rel, ok, xs, ys, angles, step, sweeps):
    """Backfitted bin means of ``rel`` (rows at ``ys``, pixels where ``ok``) across each
    family's direction; after the first pass, pixels beyond ``_CLIP`` robust standard
    deviations of their fit drop out.  Returns the profiles and each one's first bin's u."""
    nr, w = rel.shape
    nf = angles.size
    u0 = np.empty(nf)
    nbs = np.empty(nf, dtype=np.int64)
    for f in range(nf):
        sn, cs = np.sin(angles[f]), np.cos(angles[f])
        lo, hi = 1e300, -1e300
        for yy in (ys[0], ys[nr - 1]):
            for xx in (xs[0], xs[w - 1]):
                u = -sn * xx + cs * yy
                lo, hi = min(lo, u), max(hi, u)
        u0[f] = lo - step
        nbs[f] = int((hi - u0[f]) / step) + 2
    nmax = nbs.max()
    idx = np.empty((nf, nr, w), dtype=np.int32)
    for f in range(nf):
        sn, cs = np.sin(angles[f]), np.cos(angles[f])
        for i in range(nr):
            for j in range(w):
                idx[f, i, j] = int((-sn * xs[j] + cs * ys[i] - u0[f]) / step)
    prof = np.zeros((nf, nmax))
    sums = np.zeros(nmax)
    cnts = np.zeros(nmax)
    weight = ok.astype(np.float64)
    for it in range(sweeps + 1):
        for f in range(nf):
            sums[:] = 0.0
            cnts[:] = 0.0
            for i in range(nr):
                for j in range(w):
                    if weight[i, j] == 0.0:
                        continue
                    other = 0.0
                    for g in range(nf):
                        if g != f:
                            other += prof[g, idx[g, i, j]]
                    k = idx[f, i, j]
                    sums[k] += rel[i, j] - other
                    cnts[k] += 1.0
            for k in range(nmax):
                prof[f, k] = sums[k] / cnts[k] if cnts[k] > 0 else 0.0
        if it == 0:
            # the robust scale of the residuals (a histogram's median of |residual|)
            res = np.empty(nr * w)
            n = 0
            for i in range(0, nr, 3):  # a third of the rows: enough for a median
                for j in range(w):
                    if weight[i, j] > 0:
                        v = rel[i, j]
                        for g in range(nf):
                            v -= prof[g, idx[g, i, j]]
                        res[n] = abs(v)
                        n += 1
            scale = max(1.4826 * np.median(res[:n]), 1e-4)
            for i in range(nr):
                for j in range(w):
                    if weight[i, j] > 0:
                        v = rel[i, j]
                        for g in range(nf):
                            v -= prof[g, idx[g, i, j]]
                        if abs(v) > _CLIP * scale:
                            weight[i, j] = 0.0
    # the profiles as bin centres: u of bin k's centre is u0 + (k + 0.5) step
    for f in range(nf):
        u0[f] += 0.5 * step
    return prof, u0


# ---------------------------------------------------------------- the hatch's directions
@functools.lru_cache(maxsize=4)
def _spectrum_geometry(hs: int, ws: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For ``honing_directions`` on an hs x ws spectrum (the same for every frame of a
    camera): the Hann window (no edge ringing along the axes), the ring of spatial periods
    4-24 px, and each of its frequencies' line direction in quarter-degree bins."""
    win = np.outer(np.hanning(hs), np.hanning(ws)).astype(np.float32)
    fy = np.broadcast_to(np.fft.fftfreq(hs)[:, None], (hs, ws))
    fx = np.broadcast_to(np.fft.fftfreq(ws)[None, :], (hs, ws))
    k = np.hypot(fx, fy)
    ring = (k > 1.0 / 24.0) & (k < 1.0 / 4.0)
    line_deg = ((np.rad2deg(np.arctan2(fy, fx)) + 90.0) % 180.0)[ring]
    line_bin = np.minimum((line_deg * 4).astype(np.int64), 180 * 4 - 1)
    for a in (win, ring, line_bin):
        a.setflags(write=False)
    return win, ring, line_bin


#: the cross-hatch's half-angles (deg from the circumferential x axis) searched for
HATCH_HALF_ANGLE_DEG = (6.0, 84.0)
#: the weaker of a hatch's two families stands at least this many times above the
#: median direction's power, or at a quarter of the stronger (``honing_directions``) ...
MIRROR_FAMILY_MIN = 10.0
#: ... or this many, when both families' peaks are peaks of their own: each at least
#: ``PEAK_PROMINENCE`` times the power ``PEAK_FLANK_DEG`` to either side of it
MIRROR_FAMILY_MIN_PROMINENT = 4.0
PEAK_PROMINENCE = 2.0
PEAK_FLANK_DEG = 4.0
#: no hatch read: a peak within this of the nominal hatch (deg) is a family there or a
#: mark along it (``honing_directions``, ``_lines_cover``)
NOMINAL_CLEAR_DEG = 7.5
#: ``_lines_cover``: the means along a direction over this many px, on a grid of this many
#: tiles a side, and the median over the tiles of their power over that of the means along
#: a typical direction that a family's lines reach
COVER_WINDOW_PX = 61
COVER_HIGH_PASS_PX = 4.0
COVER_TILES = 4
COVER_MIN_MEDIAN = 1.5


def _line_means(d: np.ndarray, weights: np.ndarray, angle_deg: float, window: int) -> tuple[np.ndarray, np.ndarray]:
    """The weighted means of ``d`` along lines of direction ``angle_deg`` (image sense)
    over ``window`` px, and where they hold half their window, on the frame's grid."""
    h, w = d.shape
    m = cv2.getRotationMatrix2D((w / 2.0, h / 2.0), float(angle_deg), 1.0)
    num = cv2.blur(cv2.warpAffine(d * weights, m, (w, h)), (window, 1))
    den = cv2.blur(cv2.warpAffine(weights, m, (w, h)), (window, 1))
    back = cv2.invertAffineTransform(m)
    mean = cv2.warpAffine(num / np.maximum(den, 1e-3), back, (w, h))
    held = cv2.warpAffine(den, back, (w, h)) > 0.5
    return mean, held


def _lines_cover(d: np.ndarray, valid: np.ndarray, angle_deg: float, typical_deg: float) -> bool:
    """Whether a groove family runs along ``angle_deg`` over the frame: its lines' means
    (over ``COVER_WINDOW_PX``) hold more power than the means along a typical direction
    ``typical_deg`` in most of the frame's tiles (``_tile_ratios``' median over
    ``COVER_MIN_MEDIAN``). One scratch lies in a few tiles only: a 2.9 mm and a 2.6 mm
    one on a 1280 x 1024 frame without grooves read a median of 1.18 (their own tiles
    18-43), a bent scratch's peaks 0.94-0.98; faint families (grooves 4 % deep on 640 x
    512 frames, 1.4-4x the median direction's power in the spectrum) 2.0-2.4."""
    ratios = _tile_ratios(d, valid, angle_deg, typical_deg)
    return not ratios or float(np.median(ratios)) > COVER_MIN_MEDIAN


def _tile_ratios(d: np.ndarray, valid: np.ndarray, angle_deg: float, typical_deg: float) -> list[float]:
    """Per tile of the frame (``COVER_TILES`` a side), the power of the means of ``d`` (in
    the spectrum's band) along ``angle_deg`` over that along ``typical_deg``."""
    weights = valid.astype(np.float32)
    # the spectrum's band only (periods of 24 px and less): the blotches' tens of px of
    # darkness run along every direction's lines alike, and their means varied 0.7-3.9x
    # from tile to tile on a wall of grain and blotches alone
    num, den = cv2.GaussianBlur(d * weights, (0, 0), COVER_HIGH_PASS_PX), cv2.GaussianBlur(weights, (0, 0),
                                                                                          COVER_HIGH_PASS_PX)
    band = (d - num / np.maximum(den, 1e-3)) * weights
    along, held_a = _line_means(band, weights, angle_deg, COVER_WINDOW_PX)
    typical, held_t = _line_means(band, weights, typical_deg, COVER_WINDOW_PX)
    h, w = d.shape
    ratios = []
    for r in range(COVER_TILES):
        for c in range(COVER_TILES):
            sl = np.s_[r * h // COVER_TILES:(r + 1) * h // COVER_TILES, c * w // COVER_TILES:(c + 1) * w // COVER_TILES]
            a, t = along[sl][held_a[sl]], typical[sl][held_t[sl]]
            if a.size < 64 or t.size < 64:
                continue
            ratios.append(float(np.var(a)) / max(float(np.var(t)), 1e-12))
    return ratios


def honing_directions(darkness: np.ndarray, valid: np.ndarray, default_deg: float = 30.0) -> tuple[float, ...]:
    """The cross-hatch's two line directions (deg, image sense, 0-180) from the frame's
    power spectrum: a family of straight grooves puts its power on the line through
    the origin perpendicular to them. The power over spatial periods of 4-24 px
    (groove widths and spacings; blotches and holes are larger) is histogrammed by the
    lines' direction; each family's direction is the power-weighted mean over +/-2 deg
    of its peak (dev frames: within 0.1 deg of the rendered 30 deg; the gradient
    orientation histogram tried first was 1-7 deg off, biased by the pixel grid).

    The hatch is symmetric about the bore's axis (the camera's y), so the second family
    is sought within 8 deg of the mirror of the first; no clear peak for either falls
    back to +/-``default_deg``, or to no direction at all (``()``) where a mark that is
    no groove family lies along it.
    """
    h, w = darkness.shape
    hs, ws = cv2.getOptimalDFTSize(h), cv2.getOptimalDFTSize(w)
    hs, ws = (hs if hs <= h else h), (ws if ws <= w else w)
    d = np.where(valid, darkness, 0.0).astype(np.float32)[:hs, :ws]
    d -= float(d.mean())
    win, ring, line_bin = _spectrum_geometry(hs, ws)
    spec = cv2.dft(d * win, flags=cv2.DFT_COMPLEX_OUTPUT)
    power = spec[..., 0] ** 2 + spec[..., 1] ** 2
    bins = 4  # per degree
    hist = np.bincount(line_bin, weights=power[ring], minlength=180 * bins)
    smooth = gaussian_filter1d(hist, 2.0, mode="wrap")
    base = float(np.median(smooth))
    fallback = (default_deg % 180.0, (-default_deg) % 180.0)

    def centroid(i: int) -> float:
        idx = np.arange(i - 2 * bins, i + 2 * bins + 1)
        wts = np.clip(hist[idx % hist.size] - base, 0.0, None)
        if wts.sum() <= 0:
            return (i + 0.5) / bins
        return float(((idx + 0.5) / bins * wts).sum() / wts.sum()) % 180.0

    # a clear hatch stands several times above the median direction (dev frames: 5-50x);
    # grain alone is flat within a factor of ~1.5. The hatch is a *pair* of peaks
    # mirrored about the bore's axis: each peak of the directions' power is paired with
    # the strongest peak within 8 deg of its mirror, and the pair whose weaker peak is
    # strongest is the hatch. So one long scratch on a bare wall (one peak) is no hatch,
    # and a scratch beside a hatch is not paired with the shoulder of a groove family's
    # peak (on a 640 x 512 frame a family's peak is several degrees wide: a scratch at 41
    # deg paired with the 150 deg family's flank at 145 outranked a 30 deg hatch whose
    # families differ in strength). Half-angles of 6-84 deg from the circumferential x
    # axis are searched: conventional and plateau honing make 20-35 deg, helical slide
    # honing 60-75 (a search of 18-42 deg read a 15 deg or 45 deg hatch as +/-30, and its
    # grooves became scratches); nearer the axes the two families are one. The mirror
    # family must carry a quarter of the first's power, or stand ``MIRROR_FAMILY_MIN``
    # (10x) above the median: the two families of a real hatch may differ by more than 4x
    # (a 22 deg hatch whose families stood 283x and 59x above the median fell back to
    # +/-30 deg under the quarter alone, and its grooves became seven "scratches"). When
    # both peaks stand clear of their flanks (a family's lines are one direction), 4x will
    # do: on a wide-envelope frame at 45 deg and 0.008 mm/px the families stood 25x and
    # 4.5x (flanks 4 deg off: 1/16 and 1/6 of the peaks), fell back to +/-30 deg, and five
    # grooves became "scratches" of 1.3-6.4 mm. Not without the flanks' test: a lone
    # scratch's broad peak paired its flank at 165 deg with the frame's near-horizontal
    # artefact at 8 deg (73x and 4.2x, each below its own flank), and the scratch was
    # taken for a groove and lost
    lines = (np.arange(hist.size) + 0.5) / bins
    half_angle = np.minimum(lines, 180.0 - lines)
    honing = (half_angle >= HATCH_HALF_ANGLE_DEG[0]) & (half_angle <= HATCH_HALF_ANGLE_DEG[1])
    if base <= 0:
        return fallback
    peak = (smooth >= np.roll(smooth, 1)) & (smooth > np.roll(smooth, -1)) & (smooth >= 3.0 * base)

    def dist(x, y):
        return np.abs((x - y + 90.0) % 180.0 - 90.0)

    best = None
    for i in np.flatnonzero(peak & honing):
        # its mirror family within the half-angles searched as well: a peak 6.9 deg off the
        # axis paired with one 0.5 deg off it on the same side, the wall's one scratch
        # (5.3 deg) read as a "hatch" of two families 6.4 deg apart on a wall without
        # grooves, and the scratch, 0.69 mm and plain to see, was taken for a groove
        # (seed 987014, groove depth 0)
        near = peak & honing & (dist(lines, 180.0 - lines[i]) <= 8.0) & (dist(lines, lines[i]) >= 5.0)
        if not near.any():
            continue
        j = int(np.argmax(np.where(near, smooth, -np.inf)))
        score = min(smooth[i], smooth[j])
        if best is None or score > best[0]:
            best = (score, int(i), j)
    side = int(round(PEAK_FLANK_DEG * bins))

    def prominent(k: int) -> bool:
        return bool(smooth[k] >= PEAK_PROMINENCE * max(smooth[(k - side) % hist.size], smooth[(k + side) % hist.size]))

    if best is not None:
        _, i, j = best
        strong, weak = max(smooth[i], smooth[j]), min(smooth[i], smooth[j])
        least = MIRROR_FAMILY_MIN_PROMINENT if prominent(i) and prominent(j) else MIRROR_FAMILY_MIN
        if weak >= max(3.0 * base, min(0.25 * strong, least * base)):
            return tuple(sorted((centroid(i), centroid(j))))
    # no hatch read: the nominal one, unless a mark of the frame lies along it that is no
    # groove family. On a wall whose grooves do not show (none, or a polished plateau) a
    # 2.9 mm scratch 0.05 mm wide at 29.7 deg, plain to see, was averaged away as the
    # nominal +30 deg family's line mean and lost. A peak within ``NOMINAL_CLEAR_DEG`` of
    # the nominal is a family when its lines cross the wall (``_lines_cover``: a faint
    # hatch of grooves 4 % deep on a 640 x 512 frame showed one family at 4x the median
    # direction, the other at 1.4x, and its grooves are the nominal's); one scratch's
    # peaks are one line, and the frame then has no hatch: ``()``
    along = [centroid(int(k)) for a in fallback for k in np.flatnonzero(peak & (dist(lines, a) <= NOMINAL_CLEAR_DEG))]
    if along:
        # the lines' power is judged against a direction of the median power (no peak
        # within 10 deg): the quietest one's is low by selection
        away = np.ones(hist.size, bool)
        for k in np.flatnonzero(peak):
            away &= dist(lines, lines[k]) > 10.0
        typical = (int(np.argmin(np.where(away, np.abs(smooth - base), np.inf))) + 0.5) / bins
        valid_s = np.asarray(valid[:hs, :ws], bool)
        if not any(_lines_cover(d, valid_s, a, typical) for a in along):
            return ()
    return fallback


def frame_hatch(image: np.ndarray, holes: list[tuple[float, float, float]],
                nominal_deg: tuple[float, ...] = (30.0, -30.0)) -> tuple[float, float]:
    """The cross-hatch's two line directions on a grey frame, as the photometric fit
    takes them (deg from the x axis, y down, in (-90, 90]): ``honing_directions`` on the
    frame's relative darkness at half resolution (about a 16 px Gaussian level, the
    holes given as ``frame_grooves`` takes them left out), or ``nominal_deg`` when the
    frame shows no clear hatch.

    Why: the honing angle is the part's (plateau honing specifies 20-35 deg, helical
    slide honing 60-75, and a machine holds it to a few degrees), not the station's.
    The hole fit reads each family's profile along its lines over hundreds of px, so a
    model half a degree off already costs (dev seeds: diameter z^2 +0.03 to +0.06), and
    a 25 deg hatch read as 30 deg costs +0.33 to +0.50 (docs/vision.md, "The hatch's
    angle")."""
    h, w = image.shape[:2]
    small = cv2.resize(image, (w // 2, h // 2), interpolation=cv2.INTER_AREA).astype(np.float32)
    level = cv2.GaussianBlur(small, (0, 0), 8.0, borderType=cv2.BORDER_REFLECT)
    darkness = 1.0 - small / np.maximum(level, 1.0)
    valid = np.ones(small.shape, np.uint8)
    for x, y, r in holes:  # the hole and the level's 8 px Gaussian round it (3 sigma)
        cv2.circle(valid, (int(round(x / 2)), int(round(y / 2))), int(np.ceil(r / 2 + 24.0)), 0, -1)
    default = abs(float(nominal_deg[0])) if nominal_deg else 30.0
    found = honing_directions(darkness, valid.astype(bool), default)
    if not found or (abs(found[0] - default % 180.0) < 1e-9 and abs(found[1] - (-default) % 180.0) < 1e-9):
        return tuple(float(a) for a in nominal_deg)  # no hatch read: the nominal, as given
    a1, a2 = found
    return tuple(float(a if a <= 90.0 else a - 180.0) for a in (a1, a2))
