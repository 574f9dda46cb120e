"""Synthetic endoscope frames of the honed bore wall with compensating holes.

Why a renderer: sub-pixel claims need ground truth that a real camera cannot give.
Each frame is built the way the physics orders it, so that every effect the measurer
must survive is present and its size is known:

1. scene radiance in *ideal* (undistorted) pixel coordinates: the honed wall
   (cross-hatch grooves at +/-30 deg, fine grain, low-frequency blotches) and dark
   holes (discs or ellipses);
2. the lens: Brown distortion moves the geometry (each sensor pixel asks which ideal
   point it sees), vignetting darkens the corners, Gaussian blur spreads edges (and,
   when asked, a defocus disc or a motion smear on top of it: ``psf_kernel``);
3. the sensor: each pixel integrates its area (hole edges are rendered by 48x48
   supersampling of the edge band, i.e. exact area coverage to 1/2304), shot noise,
   read noise, 8-bit quantisation.

The camera blurs the scene before the pixels integrate it.  The frame is blurred on the
pixel grid, which is that order for the wall's texture (defined per pixel); a hole's
sharp edge is blurred on a grid ``EDGE_FINE`` times finer and area-averaged back
(``_edge_blur_correction``): blurring the pixels' coverage instead aliases the edge, a
ripple of up to 0.6 % of the step near axis-aligned stretches of rim at 1 px of blur,
which a grain-aware fit turned into a diameter bias (docs/vision-history.md, round 17).

Pixel convention (shared with ``station.vision``): the centre of pixel (0, 0) is at
(0, 0), x to the right, y down; pixel (i, j) covers [j-0.5, j+0.5] x [i-0.5, i+0.5].

Ground truth is given in ideal pixel coordinates (what a calibrated measurement
recovers); without distortion those are the image coordinates.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import lru_cache

import cv2
import numpy as np
from scipy.ndimage import gaussian_filter1d

from sim.camera.lens import BrownLens, ideal_pixel_grid
from sim.camera.sensor import SensorFlaws
from sim.camera.sensor import collect as sensor_collect
from sim.camera.sensor import through_window as sensor_window
from sim.camera.sensor import transfer as sensor_transfer

#: supersampling per axis for hole-edge pixels: 48 x 48 samples, 12 x 12 per sub-pixel
#: of ``EDGE_FINE`` (before round 17: 16 x 16, 0.09 s per station frame against 0.13 s)
SUPERSAMPLE = 48
#: a hole's edge is blurred on a grid this many times finer than the pixels (the
#: supersamples grouped into EDGE_FINE^2 sub-pixels), then area-averaged back: against
#: the exact disc (x) Gaussian (x) pixel, 7e-5 of the step RMS at 1 px of blur and 1e-4
#: at 0.8 px, against 1.8e-3 (6e-3 at worst) for the pixels' coverage blurred (16
#: supersamples per axis: 3e-4, 32: 1.1e-4); 1: the coverage blurred
EDGE_FINE = 4
#: honing cross-hatch half-angle; plateau-honed cylinder bores use 20-35 deg
#: (typical specification 30 deg +/- 5, e.g. Sunnen/Nagel honing guides)
HONING_ANGLE_DEG = 30.0


@dataclass(frozen=True)
class HoleSpec:
    """One hole in ideal pixel coordinates.

    ``diameter_px`` is the mean diameter (sum of the two semi-axes); ``aspect`` is
    major/minor axis (a round hole seen on the curved bore wall looks slightly oval).
    """

    x_px: float
    y_px: float
    diameter_px: float
    aspect: float = 1.0
    angle_deg: float = 0.0

    @property
    def semi_axes_px(self) -> tuple[float, float]:
        b = self.diameter_px / (1.0 + self.aspect)
        return self.aspect * b, b


@dataclass(frozen=True)
class HoleTruth:
    """Ground truth of one rendered hole.

    ``x_px``, ``y_px``, ``diameter_px`` are ideal (undistorted) pixel coordinates;
    ``image_x_px``/``image_y_px`` where the lens puts the centre on the sensor.
    ``partial`` when part of the hole lies outside the frame.
    """

    x_px: float
    y_px: float
    diameter_px: float
    image_x_px: float
    image_y_px: float
    partial: bool
    aspect: float = 1.0


@dataclass(frozen=True)
class FrameParams:
    """Everything that shapes a frame besides the holes (levels in DN of an 8-bit sensor)."""

    width_px: int = 1280
    height_px: int = 1024
    wall_level_dn: float = 150.0
    hole_level_dn: float = 35.0
    groove_depth: float = 0.10  # mean relative darkening of one honing groove
    groove_spacing_px: float = 14.0  # mean distance between grooves of one direction
    grain: float = 0.03  # relative std of the fine grain
    blotch: float = 0.05  # relative std of low-frequency reflectance variation
    blur_sigma_px: float = 1.2
    gain_e_per_dn: float = 10.0  # shot noise: sigma_dn = sqrt(signal_dn / gain)
    read_noise_dn: float = 1.5
    vignetting: float = 0.35  # relative fall-off at the frame corner (r^2 law)
    lens: BrownLens | None = None
    #: the cross-hatch's half-angle (deg from the frame's x axis, both signs)
    hatch_deg: float = HONING_ANGLE_DEG
    #: the wall's texture (grooves' widths and spacing, the grain's and the blotches'
    #: sizes) in px is this times its size at the station's 0.010 mm/px: a camera of
    #: s mm/px sees it 0.010 / s as large (the sensor's noise stays per pixel)
    texture_scale: float = 1.0
    #: the share of each groove family's length that is missing: a honing whose grooves
    #: stop short (a coarse grain that bites and leaves, a plateau pass that takes the
    #: shallow stretches off) leaves groove pieces with cut ends, darkness stepping within
    #: the camera's blur as a furrow's does. 0: every groove runs on, fading in and out
    groove_breaks: float = 0.0
    #: the lens's point spread beyond the Gaussian (``blur_sigma_px``), convolved with it:
    #: a defocused lens's disc of this radius (px; geometric optics: the exit pupil's
    #: image, uniform), and a smear of this length (px) at ``psf_smear_deg`` from the x
    #: axis (a camera or part still moving during the exposure: a uniform line). 0: the
    #: Gaussian alone, and every frame is what it was before these existed
    psf_disc_px: float = 0.0
    psf_smear_px: float = 0.0
    psf_smear_deg: float = 0.0
    #: the sensor's flawed pixels (``sim.camera.sensor``: hot and dim pixels, a trap in a
    #: column), the same in every frame; None: a flawless sensor, and every frame is what
    #: it was before flaws existed
    sensor: SensorFlaws | None = None


@dataclass
class Frame:
    image: np.ndarray  # uint8, (height, width)
    holes: list[HoleTruth] = field(default_factory=list)
    params: FrameParams | None = None
    #: ``sim.camera.defects.DefectTruth`` of each surface defect rendered (issue 23)
    defects: list = field(default_factory=list)
    #: ground truth for benches only (``render_frame(keep_grooves=True)``): the honing
    #: grooves' relative darkening of the wall at each pixel's centre (float32, <= 0),
    #: before the holes, the blur and the vignetting; None when not kept
    grooves: np.ndarray | None = None


def _groove_profile(rng: np.random.Generator, length_px: float, params: FrameParams, step_px: float = 0.25):
    """1-D darkening profile across one groove family: Poisson-placed Gaussian grooves."""
    n = int(length_px / step_px) + 8
    profile = np.zeros(n)
    k = params.texture_scale
    for sigma_px in (0.8 * k, 1.5 * k, 3.0 * k):  # fine, medium and coarse stones of a honing tool
        count = rng.poisson(length_px / (params.groove_spacing_px * k) / 3.0)
        idx = rng.integers(0, n, count)
        depth = np.minimum(rng.exponential(params.groove_depth, count), 3 * params.groove_depth)
        impulses = np.zeros(n)
        np.add.at(impulses, idx, depth)
        # a Gaussian groove of peak depth d: impulse d * sqrt(2 pi) sigma / step, then smoothed
        profile += gaussian_filter1d(impulses * np.sqrt(2 * np.pi) * sigma_px / step_px, sigma_px / step_px)
    return profile


def _lowfreq(rng: np.random.Generator, width_px: int, height_px: int, cell_px: int) -> np.ndarray:
    """Smooth unit-std random field with features of about ``cell_px``."""
    coarse = rng.standard_normal((height_px // cell_px + 2, width_px // cell_px + 2)).astype(np.float32)
    field_ = cv2.resize(coarse, (width_px, height_px), interpolation=cv2.INTER_CUBIC)
    return field_ / max(float(field_.std()), 1e-6)


#: the cells of the grooves' breaks: across the lines (px, under a groove's spacing, so
#: that grooves side by side break apart) and along them (a piece's length scale)
BREAK_CELL_PX = (4.0, 48.0)


def _breaks(rng: np.random.Generator, u: np.ndarray, t: np.ndarray, params: FrameParams) -> np.ndarray:
    """1 where a groove family's lines run, 0 where they are cut (``groove_breaks`` of the
    area): a random field on cells across (``u``) and along (``t``) the lines, bilinear
    between them and thresholded, so a groove stops and starts at a step."""
    if not 0.0 <= params.groove_breaks < 1.0:
        raise ValueError(f"groove_breaks must be in [0, 1), not {params.groove_breaks}")
    du, dt = (c * params.texture_scale for c in BREAK_CELL_PX)
    u0, t0 = float(u.min()), float(t.min())
    nu, nt = int((float(u.max()) - u0) / du) + 3, int((float(t.max()) - t0) / dt) + 3
    cells = rng.standard_normal((nu, nt)).astype(np.float32)
    field_ = cv2.remap(cells, ((t - t0) / dt).astype(np.float32), ((u - u0) / du).astype(np.float32),
                       cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return (field_ >= np.quantile(field_, params.groove_breaks)).astype(np.float32)


def wall_radiance(rng: np.random.Generator, xu: np.ndarray, yu: np.ndarray, params: FrameParams,
                  parts: dict | None = None) -> np.ndarray:
    """Honed wall reflectance (DN) at ideal coordinates ``xu``, ``yu``; ``parts``, if
    given, receives ``"grooves"``: the grooves' share of it (relative, a copy)."""
    h, w = xu.shape
    k = params.texture_scale
    if not k > 0:
        raise ValueError(f"texture_scale must be positive, not {k}")
    rel = np.zeros((h, w), np.float32)
    for sign in (+1.0, -1.0):
        phi = np.deg2rad(sign * params.hatch_deg)
        u = (-np.sin(phi) * xu + np.cos(phi) * yu).astype(np.float32)
        u0 = float(u.min()) - 4.0
        profile = _groove_profile(rng, float(u.max()) - u0 + 8.0, params)
        grid = u0 + 0.25 * np.arange(profile.size)
        grooves = np.interp(u, grid, profile).astype(np.float32)
        # grooves fade in and out along their length (worn stones, plateau honing)
        fade = 0.6 + 0.4 * np.tanh(_lowfreq(rng, w, h, max(2, round(96 * k))))
        if params.groove_breaks > 0.0:
            fade *= _breaks(rng, u, (np.cos(phi) * xu + np.sin(phi) * yu).astype(np.float32), params)
        rel -= grooves * fade
    if parts is not None:
        parts["grooves"] = rel.copy()
    grain = rng.standard_normal((h, w), dtype=np.float32)
    grain = cv2.GaussianBlur(grain, (0, 0), 0.7 * k)
    rel += params.grain * grain / max(float(grain.std()), 1e-6)
    rel += params.blotch * _lowfreq(rng, w, h, max(2, round(64 * k)))
    return params.wall_level_dn * (1.0 + rel)


def _inside(hole: HoleSpec, xu: np.ndarray, yu: np.ndarray) -> np.ndarray:
    """Normalised ellipse radius q (q < 1 inside) at ideal coordinates."""
    a, b = hole.semi_axes_px
    t = np.deg2rad(hole.angle_deg)
    dx, dy = xu - hole.x_px, yu - hole.y_px
    xr = dx * np.cos(t) + dy * np.sin(t)
    yr = -dx * np.sin(t) + dy * np.cos(t)
    return np.sqrt((xr / a) ** 2 + (yr / b) ** 2)


@lru_cache(maxsize=4)
def _grid_jacobian(lens: BrownLens, width_px: int, height_px: int) -> tuple[np.ndarray, ...]:
    """d(ideal x, y) / d(sensor x, y) at every pixel (central differences of the grid)."""
    gx, gy = ideal_pixel_grid(lens, width_px, height_px)
    jxy, jxx = np.gradient(gx)
    jyy, jyx = np.gradient(gy)
    return jxx, jxy, jyx, jyy


def _pixel_box(ex: np.ndarray, ey: np.ndarray, w: int, h: int) -> tuple[bool, int, int, int, int]:
    """The sensor pixels an outline (its points on the sensor) may touch, with a margin
    for the blur's start, clipped to the frame; and whether the outline runs off it."""
    partial = bool(ex.min() < -0.5 or ey.min() < -0.5 or ex.max() > w - 0.5 or ey.max() > h - 0.5)
    x0 = int(np.clip(np.floor(ex.min()) - 3, 0, w))
    x1 = int(np.clip(np.ceil(ex.max()) + 4, 0, w))
    y0 = int(np.clip(np.floor(ey.min()) - 3, 0, h))
    y1 = int(np.clip(np.ceil(ey.max()) + 4, 0, h))
    return partial, x0, y0, x1, y1


def _ideal_centres(lens: BrownLens | None, w: int, h: int, box: tuple[int, int, int, int]):
    """The ideal coordinates of the box's pixel centres (from the frame's cached grid
    through a distorting lens; the pixel indices themselves without one)."""
    x0, y0, x1, y1 = box
    if lens is not None and lens.has_distortion:
        gx, gy = ideal_pixel_grid(lens, w, h)
        return gx[y0:y1, x0:x1], gy[y0:y1, x0:x1]
    yy, xx = np.mgrid[y0:y1, x0:x1].astype(np.float64)
    return xx, yy


def _edge_coverage(inside, xu: np.ndarray, yu: np.ndarray, band: np.ndarray, n: int, lens: BrownLens | None,
                   w: int, h: int, box: tuple[int, int, int, int], fine: int = 1) -> np.ndarray:
    """Area fraction inside (``inside(x, y)``: a boolean array) of the pixels in ``band``,
    from n x n sub-samples per pixel. Through a distorting lens the sub-samples follow
    its local Jacobian: inside one pixel the distortion is linear to ~1e-5 px (its
    second derivative is ~1e-4 / px).  ``fine`` > 1 (a divisor of n): each pixel's
    fine x fine sub-pixels' fractions instead, (band pixels, fine rows, fine columns)."""
    x0, y0, x1, y1 = box
    off = (np.arange(n) + 0.5) / n - 0.5
    ox, oy = (o.ravel()[None, :] for o in np.meshgrid(off, off))
    cx_, cy_ = xu[band][:, None], yu[band][:, None]
    if lens is not None and lens.has_distortion:
        jxx, jxy, jyx, jyy = (j[y0:y1, x0:x1][band][:, None] for j in _grid_jacobian(lens, w, h))
        sx = cx_ + jxx * ox + jxy * oy
        sy = cy_ + jyx * ox + jyy * oy
    else:
        sx, sy = cx_ + ox, cy_ + oy
    hits = inside(sx, sy)
    if fine == 1:
        return hits.mean(axis=1)
    q = n // fine  # the sub-samples are row-major (y, x): group them in fine x fine blocks
    return hits.reshape(-1, fine, q, fine, q).mean(axis=(2, 4))


def hole_coverage(hole: HoleSpec, params: FrameParams, fine: int = 1
                  ) -> tuple[tuple[int, int, int, int], np.ndarray, bool, tuple]:
    """Area fraction of each pixel inside the hole, over the hole's bounding box.

    Returns (x0, y0, x1, y1), coverage (y1-y0, x1-x0), partial flag, image centre; with
    ``fine`` > 1 the coverage of each pixel's fine x fine sub-pixels instead, ((y1-y0)
    fine, (x1-x0) fine), from the same supersamples.
    """
    lens = params.lens
    a, b = hole.semi_axes_px
    t = np.linspace(0, 2 * np.pi, 256, endpoint=False)
    th = np.deg2rad(hole.angle_deg)
    ex = hole.x_px + a * np.cos(t) * np.cos(th) - b * np.sin(t) * np.sin(th)
    ey = hole.y_px + a * np.cos(t) * np.sin(th) + b * np.sin(t) * np.cos(th)
    if lens is not None and lens.has_distortion:
        ex, ey = lens.distort_px(ex, ey)
        icx, icy = lens.distort_px(np.array(hole.x_px), np.array(hole.y_px))
    else:
        icx, icy = np.array(hole.x_px), np.array(hole.y_px)
    w, h = params.width_px, params.height_px
    partial, x0, y0, x1, y1 = _pixel_box(ex, ey, w, h)
    if x1 <= x0 or y1 <= y0:
        return (x0, y0, x0, y0), np.zeros((0, 0)), True, (float(icx), float(icy))
    box = (x0, y0, x1, y1)
    xu, yu = _ideal_centres(lens, w, h, box)
    q = _inside(hole, xu, yu)
    cover = (q < 1.0).astype(np.float64)
    if fine > 1:
        cover = np.repeat(np.repeat(cover, fine, axis=0), fine, axis=1)
    # band where a pixel may be cut by the edge: distance ~ (q-1)*b, pixel half-diagonal
    # 0.71 px, widened for the local magnification of the lens
    band = np.abs(q - 1.0) * b < 1.5
    if band.any():
        part = _edge_coverage(lambda x, y: _inside(hole, x, y) < 1.0, xu, yu, band, SUPERSAMPLE, lens, w, h, box,
                              fine)
        if fine > 1:
            iy, ix = np.nonzero(band)
            cover.reshape(y1 - y0, fine, x1 - x0, fine)[iy, :, ix, :] = part
        else:
            cover[band] = part
    return (x0, y0, x1, y1), cover, partial, (float(icx), float(icy))


def _edge_blur_correction(fine_cover: np.ndarray, cover: np.ndarray, box: tuple[int, int, int, int], blur_px: float,
                          fine: int, w: int, h: int) -> tuple[tuple[int, int, int, int], np.ndarray]:
    """What blurring a hole's edge before the pixels integrate it (the camera's order)
    changes against blurring its pixels' coverage, per unit of the step across the edge:
    the fine coverage (``hole_coverage(fine=...)``) blurred on its grid and area-averaged
    back, less the pixel coverage (``cover``, its mean over each pixel) blurred on the
    pixels' grid, over the hole's box widened by the blur's reach.  Both blurs reflect at
    the frame's border, as the frame's does.
    Returns the window (x0, y0, x1, y1) and the correction there."""
    x0, y0, x1, y1 = box
    pad = int(np.ceil(4.0 * blur_px)) + 2
    wx0, wy0, wx1, wy1 = max(x0 - pad, 0), max(y0 - pad, 0), min(x1 + pad, w), min(y1 + pad, h)
    cf = np.zeros(((wy1 - wy0) * fine, (wx1 - wx0) * fine), np.float32)
    cf[(y0 - wy0) * fine:(y1 - wy0) * fine, (x0 - wx0) * fine:(x1 - wx0) * fine] = fine_cover
    coarse = np.zeros((wy1 - wy0, wx1 - wx0), np.float32)
    coarse[y0 - wy0:y1 - wy0, x0 - wx0:x1 - wx0] = cover
    fine_blurred = cv2.GaussianBlur(cf, (0, 0), blur_px * fine, borderType=cv2.BORDER_REFLECT)
    exact = fine_blurred.reshape(wy1 - wy0, fine, wx1 - wx0, fine).mean(axis=(1, 3))
    return (wx0, wy0, wx1, wy1), exact - cv2.GaussianBlur(coarse, (0, 0), blur_px, borderType=cv2.BORDER_REFLECT)


def wall_patch(params: FrameParams, seed: int | None) -> np.ndarray:
    """The bore wall's radiance over the whole frame, before holes, blur and noise: a
    camera that stays put sees the same patch again (``render_frame(wall=...)``)."""
    xu, yu = ideal_pixel_grid(params.lens, params.width_px, params.height_px)
    return wall_radiance(np.random.default_rng(seed), xu, yu, params)


#: sub-samples per pixel axis for the extra spread's kernel: its area coverage to ~1/1000
PSF_FINE = 32


def psf_kernel(params: FrameParams) -> np.ndarray | None:
    """The spread beyond the Gaussian (``FrameParams.psf_disc_px``, ``psf_smear_px``)
    as a normalised float32 kernel on the pixel grid, or None when there is none.

    The disc: each kernel pixel's share of the disc's area (``PSF_FINE``^2 sub-samples);
    its variance per axis is radius^2 / 4 and what the pixels' areas add (0.02-0.14
    px^2 with the disc edge's phase on the grid). The smear: a uniform line, each
    pixel's share of it from ``PSF_FINE`` x the length sub-samples along it, bilinearly
    spread; its variance along the line is length^2 / 12 and at most 1/6 px^2 of the
    spreading. Both are cached by their sizes; the two together are convolved (both are
    symmetric about their centre, so cv2's correlation is the convolution)."""
    r, length = float(params.psf_disc_px), float(params.psf_smear_px)
    if r < 0 or length < 0:
        raise ValueError(f"psf_disc_px and psf_smear_px must be >= 0, not {r} and {length}")
    if r == 0 and length == 0:
        return None
    k = _disc_kernel(round(r, 4)) if r > 0 else np.ones((1, 1), np.float32)
    if length > 0:
        k = cv2.filter2D(np.pad(k, int(np.ceil(length / 2)) + 1), -1,
                         _smear_kernel(round(length, 4), round(float(params.psf_smear_deg) % 180.0, 3)),
                         borderType=cv2.BORDER_CONSTANT)
        k = k[np.any(k > 0, axis=1)][:, np.any(k > 0, axis=0)]
    return (k / k.sum()).astype(np.float32)


@lru_cache(maxsize=8)
def _disc_kernel(radius_px: float) -> np.ndarray:
    half = int(np.ceil(radius_px))
    sub = (np.arange(PSF_FINE) + 0.5) / PSF_FINE - 0.5
    c = np.arange(-half, half + 1, dtype=np.float64)
    xs = (c[:, None] + sub[None, :]).ravel()
    inside = (xs[None, :] ** 2 + xs[:, None] ** 2) <= radius_px**2
    k = inside.reshape(c.size, PSF_FINE, c.size, PSF_FINE).mean(axis=(1, 3)).astype(np.float32)
    k /= k.sum()
    k.setflags(write=False)
    return k


@lru_cache(maxsize=8)
def _smear_kernel(length_px: float, angle_deg: float) -> np.ndarray:
    half = int(np.ceil(length_px / 2)) + 1
    n = 2 * half + 1
    samples = max(int(np.ceil(length_px * PSF_FINE)), 1)
    t = (np.arange(samples) + 0.5) / samples - 0.5  # along the line, -1/2 .. 1/2 of it
    a = np.deg2rad(angle_deg)
    x, y = t * length_px * np.cos(a) + half, t * length_px * np.sin(a) + half
    k = np.zeros((n, n), np.float64)
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    for dx, dy, wgt in ((0, 0, (1 - fx) * (1 - fy)), (1, 0, fx * (1 - fy)), (0, 1, (1 - fx) * fy), (1, 1, fx * fy)):
        np.add.at(k, (y0 + dy, x0 + dx), wgt)
    k /= k.sum()
    k = k.astype(np.float32)
    k.setflags(write=False)
    return k


@lru_cache(maxsize=4)
def vignetting_gain(width_px: int, height_px: int, cx: float, cy: float, strength: float) -> np.ndarray:
    """Relative illumination (r^2 law), float32, cached: it is the same for every frame."""
    yy, xx = np.ogrid[0:height_px, 0:width_px]
    r2 = ((xx - cx) ** 2 + (yy - cy) ** 2) / ((width_px / 2) ** 2 + (height_px / 2) ** 2)
    gain = (1.0 - strength * r2).astype(np.float32)
    gain.setflags(write=False)
    return gain


def render_frame(params: FrameParams, holes: list[HoleSpec], seed: int | None = 0,
                 wall: np.ndarray | None = None, defects=(), keep_grooves: bool = False) -> Frame:
    """Render one frame; the same (params, holes, seed, wall, defects) gives the same image.

    ``wall``: the wall's radiance from :func:`wall_patch` (not modified), for a camera
    that looks at the same patch of wall again; without it the patch is drawn from
    ``seed``. The holes, blur, vignetting and the sensor's noise are drawn per frame.
    ``defects``: ``sim.camera.defects.DefectSpec`` (pores, scratches, burrs and chips at
    the holes' rims), painted after the holes and before the blur; their shapes come
    from their own seeds, so without defects the frame is exactly what it was before
    they existed, and with them only the defects differ.
    ``keep_grooves``: keep the grooves' field in ``Frame.grooves`` (a bench's ground
    truth; the image is the same either way); not with a given ``wall``.
    """
    rng = np.random.default_rng(seed)
    w, h = params.width_px, params.height_px
    parts: dict | None = {} if keep_grooves else None
    if wall is None:
        xu, yu = ideal_pixel_grid(params.lens, w, h)
        radiance = wall_radiance(rng, xu, yu, params, parts)
    else:
        if wall.shape != (h, w):
            raise ValueError(f"wall patch is {wall.shape[1]} x {wall.shape[0]} px, the frame {w} x {h}")
        radiance = wall.astype(np.float32, copy=True)
    # the bare wall, before the holes: scratches and burrs take its smooth level
    bare = radiance.copy() if defects else None
    truths: list[HoleTruth] = []
    inner_levels: list[float] = []
    edge_fixes = []
    fine = EDGE_FINE if params.blur_sigma_px > 0 else 1
    for hole in holes:
        (x0, y0, x1, y1), cover, partial, (icx, icy) = hole_coverage(hole, params, fine)
        inner = params.hole_level_dn
        if cover.size:
            fine_cover = cover
            if fine > 1:
                cover = fine_cover.reshape(y1 - y0, fine, x1 - x0, fine).mean(axis=(1, 3))
            # the hole's far side: dark, with a faint low-frequency sheen
            inner = params.hole_level_dn * (1.0 + 0.03 * rng.standard_normal())
            patch = radiance[y0:y1, x0:x1]
            if fine > 1:
                # the step across the edge: the hole's level less the wall's along the rim
                # (a burr or chip painted over the rim afterwards keeps this correction: at
                # most the 0.6 % of the step it corrects, where the defect covers the edge)
                rim = (cover > 0.0) & (cover < 1.0)
                wall_at_rim = float(np.mean(patch[rim])) if rim.any() else float(np.mean(patch))
                window, corr = _edge_blur_correction(fine_cover, cover, (x0, y0, x1, y1), params.blur_sigma_px,
                                                     fine, w, h)
                edge_fixes.append((window, (inner - wall_at_rim) * corr))
            radiance[y0:y1, x0:x1] = patch * (1.0 - cover) + inner * cover
        inner_levels.append(float(inner))
        truths.append(HoleTruth(hole.x_px, hole.y_px, hole.diameter_px, icx, icy, partial, hole.aspect))
    defect_truths = paint_defects(radiance, bare, params, holes, inner_levels, defects) if defects else []
    if params.blur_sigma_px > 0:
        radiance = cv2.GaussianBlur(radiance, (0, 0), params.blur_sigma_px, borderType=cv2.BORDER_REFLECT)
        for (wx0, wy0, wx1, wy1), fix in edge_fixes:
            radiance[wy0:wy1, wx0:wx1] += fix
    extra = psf_kernel(params)
    if extra is not None:
        # after the edges' correction: the convolutions are linear, so the exact edge
        # under the Gaussian is what the extra spread is applied to
        radiance = cv2.filter2D(radiance, -1, extra, borderType=cv2.BORDER_REFLECT)
    if params.sensor is not None:
        radiance = sensor_window(radiance, params.sensor)  # specks on the window, out of focus
    if params.vignetting:
        cx = params.lens.cx_px if params.lens else (w - 1) / 2
        cy = params.lens.cy_px if params.lens else (h - 1) / 2
        radiance *= vignetting_gain(w, h, float(cx), float(cy), float(params.vignetting))
    signal = np.clip(radiance, 0, None)
    if params.sensor is not None:
        signal = sensor_collect(signal, params.sensor)  # dim pixels' share, hot pixels' dark signal
    noise = np.sqrt(signal / params.gain_e_per_dn) * rng.standard_normal((h, w), dtype=np.float32)
    read = params.read_noise_dn * rng.standard_normal((h, w), dtype=np.float32)
    if params.sensor is not None:
        # the traps take charge on its way to the readout: after the shot noise, before the read's
        image = np.clip(np.rint(sensor_transfer(signal + noise, params.sensor) + read), 0, 255).astype(np.uint8)
    else:
        noise += read
        image = np.clip(np.rint(signal + noise), 0, 255).astype(np.uint8)
    return Frame(image=image, holes=truths, params=params, defects=defect_truths,
                 grooves=parts.get("grooves") if parts else None)


#: supersampling per axis for defect outlines: 64 samples -> area to 1/64 of a pixel,
#: far below what a 0.01 mm size tolerance (1 px at 0.01 mm/px) needs
DEFECT_SUPERSAMPLE = 8


def _defect_coverage(geom, params: FrameParams) -> tuple[tuple[int, int, int, int], np.ndarray, bool, tuple]:
    """Area fraction of each pixel inside a defect's outline, over its box (as
    :func:`hole_coverage`: sensor pixels ask which ideal points they see; pixels the
    outline may cut are supersampled through the lens's local Jacobian)."""
    lens = params.lens
    w, h = params.width_px, params.height_px
    distorted = lens is not None and lens.has_distortion
    bx0, by0, bx1, by1 = geom.bbox_ideal(0.0)
    ox, oy = geom.outline_points()
    ex = np.concatenate([np.asarray(ox, float), [bx0, bx1, bx1, bx0]])
    ey = np.concatenate([np.asarray(oy, float), [by0, by0, by1, by1]])
    cx, cy = (bx0 + bx1) / 2, (by0 + by1) / 2
    if distorted:
        ex, ey = lens.distort_px(ex, ey)
        icx, icy = (float(v) for v in lens.distort_px(np.array(cx), np.array(cy)))
    else:
        icx, icy = float(cx), float(cy)
    partial, x0, y0, x1, y1 = _pixel_box(ex, ey, w, h)
    if x1 <= x0 or y1 <= y0:
        return (x0, y0, x0, y0), np.zeros((0, 0)), True, (icx, icy)
    box = (x0, y0, x1, y1)
    xu, yu = _ideal_centres(lens, w, h, box)
    cover = geom.inside(xu, yu).astype(np.float64)
    # a pixel's corner is 0.71 px from its centre; the lens's local scale is within a few %
    band = geom.near(xu, yu, 1.5)
    if band.any():
        cover[band] = _edge_coverage(geom.inside, xu, yu, band, DEFECT_SUPERSAMPLE, lens, w, h, box)
    return (x0, y0, x1, y1), cover, partial, (icx, icy)


def paint_defects(radiance: np.ndarray, bare: np.ndarray, params: FrameParams, holes: list[HoleSpec],
                  inner_levels: list[float], defects) -> list:
    """Paint surface defects into ``radiance`` (in place, before blur and noise); their truths.

    ``bare``: the wall before the holes; ``inner_levels``: each hole's far-side level as
    painted. A pore's floor is a level of its own; a scratch's is the wall's smooth level
    (the cross-hatch cut away) times its reflectance; a burr takes its area out of its
    hole and shows the wall's smooth level there (torn metal, not honed) times its
    reflectance; a chip takes its area out of the wall and shows its hole's level (or
    its own reflectance of the wall's level).
    """
    from sim.camera.defects import DEFAULT_REFLECTANCE, geometry

    out = []
    lens = params.lens
    for spec in defects:
        geom = geometry(spec, holes)
        (x0, y0, x1, y1), cover, partial, _ = _defect_coverage(geom, params)
        truth = geom.truth()
        if lens is not None and lens.has_distortion:
            ix, iy = (float(v) for v in lens.distort_px(np.array(truth.x_px), np.array(truth.y_px)))
        else:
            ix, iy = truth.x_px, truth.y_px
        out.append(replace(truth, image_x_px=ix, image_y_px=iy, partial=partial))
        if not cover.size:
            continue
        refl = spec.reflectance if spec.reflectance is not None else DEFAULT_REFLECTANCE[spec.kind]
        patch = radiance[y0:y1, x0:x1]
        c = cover.astype(np.float32)
        if spec.kind == "pore":
            # a cavity in shadow: one dark level, with the holes' faint sheen (its own seed)
            sheen = 1.0 + 0.03 * np.random.default_rng(spec.shape_seed + 1).standard_normal()
            radiance[y0:y1, x0:x1] = patch * (1.0 - c) + np.float32(refl * params.wall_level_dn * sheen) * c
        elif spec.kind == "scratch":
            # the furrow's floor is smooth: the wall's local level without its grooves and grain
            smooth = cv2.GaussianBlur(bare[y0:y1, x0:x1], (0, 0), 4.0, borderType=cv2.BORDER_REFLECT)
            radiance[y0:y1, x0:x1] = patch * (1.0 - c) + np.float32(refl) * smooth * c
        elif spec.kind == "burr":
            # torn metal, not honed: the wall's smooth level (no grooves) times its reflectance
            inner = np.float32(inner_levels[spec.hole])
            smooth = cv2.GaussianBlur(bare[y0:y1, x0:x1], (0, 0), 4.0, borderType=cv2.BORDER_REFLECT)
            radiance[y0:y1, x0:x1] = patch + (np.float32(refl) * smooth - inner) * c
        else:  # chip
            level = inner_levels[spec.hole] if refl is None else refl * params.wall_level_dn
            radiance[y0:y1, x0:x1] = patch + (np.float32(level) - bare[y0:y1, x0:x1]) * c
    return out


#: the ranges random frames are drawn from.  "station": the bench's envelope (hole
#: contrast 40-85 %, grooves 3-8 % deep, 20-60 e-/DN, vignetting 10-40 %), narrowed from
#: "wide" after the first results; docs/vision.md says which of them real frames justify.
#: "wide" keeps the first, wider ranges (contrast 30-80 %, grooves 5-15 %, 5-20 e-/DN,
#: i.e. a camera at 2-4x analogue gain, vignetting 10-50 %) as a stress test.
ENVELOPES = {
    "station": dict(contrast=(0.4, 0.85), groove_depth=(0.03, 0.08), gain_e_per_dn=(20.0, 60.0), vignetting=(0.1, 0.4)),
    "wide": dict(contrast=(0.3, 0.8), groove_depth=(0.05, 0.15), gain_e_per_dn=(5.0, 20.0), vignetting=(0.1, 0.5)),
}


def random_params(rng: np.random.Generator, envelope: str = "station", **overrides) -> FrameParams:
    """A frame condition drawn across the ranges the station must cope with."""
    env = ENVELOPES[envelope]
    wall = rng.uniform(110, 190)
    contrast = rng.uniform(*env["contrast"])  # relative darkness of a hole: low to good contrast
    p = FrameParams(
        wall_level_dn=wall,
        hole_level_dn=wall * (1.0 - contrast),
        groove_depth=rng.uniform(*env["groove_depth"]),  # diffuse ring light: grooves a few % deep
        grain=rng.uniform(0.01, 0.05),
        blotch=rng.uniform(0.02, 0.06),
        blur_sigma_px=rng.uniform(0.8, 2.0),
        gain_e_per_dn=rng.uniform(*env["gain_e_per_dn"]),  # full well / 255 DN (less at analogue gain)
        read_noise_dn=rng.uniform(0.5, 3.0),
        vignetting=rng.uniform(*env["vignetting"]),
    )
    return replace(p, **overrides)


def random_holes(
    rng: np.random.Generator,
    params: FrameParams,
    n_whole: int,
    n_partial: int = 0,
    diameter_range_px: tuple[float, float] = (20.0, 100.0),
    max_aspect: float = 1.0,
    border_clearance_px: float = 12.0,
) -> list[HoleSpec]:
    """Non-overlapping holes: whole ones clear of the border, partial ones cut by it."""
    w, h = params.width_px, params.height_px
    holes: list[HoleSpec] = []
    attempts = 0
    while len(holes) < n_whole + n_partial and attempts < 1000:
        attempts += 1
        d = rng.uniform(*diameter_range_px)
        r = d / 2 * max_aspect
        if len(holes) < n_whole:
            m = r + border_clearance_px
            x, y = rng.uniform(m, w - 1 - m), rng.uniform(m, h - 1 - m)
        else:  # centre near an edge so that 15-60 % of the diameter is cut off
            cut = rng.uniform(0.15, 0.6) * d
            side = rng.integers(4)
            along = rng.uniform(r + 2, (h if side < 2 else w) - r - 2)
            inset = r - cut
            x, y = {0: (inset, along), 1: (w - 1 - inset, along), 2: (along, inset), 3: (along, h - 1 - inset)}[
                int(side)
            ]
        # keep neighbours apart so that one hole's search rays never reach the other's edge
        if any(np.hypot(x - o.x_px, y - o.y_px) < 1.6 * (r + o.diameter_px / 2 * max_aspect) for o in holes):
            continue
        aspect = rng.uniform(1.0, max_aspect) if max_aspect > 1 else 1.0
        holes.append(HoleSpec(float(x), float(y), float(d), float(aspect), float(rng.uniform(0, 180))))
    return holes


def random_frame(
    seed: int, n_whole: int | None = None, n_partial: int | None = None, envelope: str = "station",
    keep_grooves: bool = False, **overrides
) -> Frame:
    """A random frame (condition and holes) from one seed: the tests' and bench's unit of work
    (``keep_grooves``: as ``render_frame``'s)."""
    rng = np.random.default_rng(seed)
    params = random_params(rng, envelope, **overrides)
    if n_whole is None:
        n_whole = int(rng.integers(0, 4))
    if n_partial is None:
        n_partial = int(rng.integers(0, 2))
    holes = random_holes(rng, params, n_whole, n_partial)
    return render_frame(params, holes, seed=int(rng.integers(2**31)), keep_grooves=keep_grooves)
