"""The frame's illumination: a smooth multiplicative field (vignetting, the ring light's fall-off).

Why: illumination multiplies everything the camera sees after the scene is formed,
the wall *and* the hole's dark far side, while the wall's own reflectance variations
(blotches, grooves) exist on the wall only.  A photometric fit whose hole level is a
constant reads the illumination's gradient across a hole as a displaced rim on one
side: a centre error.  On rendered frames with grain only (dev seeds 3000-3199 and
9000-9199, 585 holes) the fit's centre median was 0.0218 px with 10-40 % vignetting and
0.0158 px without.  A free gain tilt in the fit removes the bias but costs precision
(0.0198 px on both), since a gain gradient across the rim is partly confounded with a
centre shift.  So the gradient comes from outside the fit: the whole frame.

Model: every 4th pixel of the frame, area-averaged to 1/32 scale (holes, grooves and
grain average out or become outliers), fitted by a quadratic in x and y with Huber weights (the dark holes
are outliers).  A quadratic holds the r^2 law of vignetting exactly and the fall-off of
a ring light to first order; the wall's blotches (cells of ~64 px) enter only through
their frame-wide trend.  The photometric fit divides each hole's pixels by the field's
local linear part, 1 + g . (x - x0), i.e. flat-fields them, before it models anything.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from station.vision.fit import median

#: the fit's points: every STRIDE-th pixel of the frame, area-averaged in blocks of
#: SCALE px (1280 x 1024 -> 40 x 32 points of 64 samples each): the field is smooth on
#: the frame's scale, and reading 1/16 of the pixels keeps the cost at ~0.1 ms
SCALE = 32
STRIDE = 4
#: Huber threshold in robust standard deviations of the residuals
_HUBER_K = 1.5


@dataclass(frozen=True)
class Illumination:
    """A quadratic field P(x, y) over the frame (DN), in coordinates scaled to -1..1."""

    coef: tuple[float, ...]  # 1, x, y, x^2, x y, y^2
    centre: tuple[float, float]  # (x, y) of the scaled origin, px
    half: tuple[float, float]  # px per unit of the scaled coordinates

    def _scaled(self, x: float, y: float) -> tuple[float, float]:
        return (x - self.centre[0]) / self.half[0], (y - self.centre[1]) / self.half[1]

    def value(self, x: float, y: float) -> float:
        u, v = self._scaled(x, y)
        c = self.coef
        return c[0] + c[1] * u + c[2] * v + c[3] * u * u + c[4] * u * v + c[5] * v * v

    def relative_curvature(self, x: float, y: float) -> tuple[float, float, float]:
        """(qxx, qxy, qyy): the field's second-order part about pixel (x, y) relative to its
        value there, per px^2: P(x + dx, y + dy) / P(x, y) = 1 + g . d + qxx dx^2 + qxy dx dy
        + qyy dy^2 exactly (P is a quadratic)."""
        c = self.coef
        p = max(self.value(x, y), 1e-6)
        hx, hy = self.half
        return c[3] / (hx * hx) / p, c[4] / (hx * hy) / p, c[5] / (hy * hy) / p

    def relative_gradient(self, x: float, y: float) -> tuple[float, float]:
        """(dP/dx, dP/dy) / P at pixel (x, y), per px: the local tilt of the illumination."""
        u, v = self._scaled(x, y)
        c = self.coef
        p = max(self.value(x, y), 1e-6)
        du = c[1] + 2 * c[3] * u + c[4] * v
        dv = c[2] + c[4] * u + 2 * c[5] * v
        return du / self.half[0] / p, dv / self.half[1] / p


def estimate_illumination(image: np.ndarray, iterations: int = 4) -> Illumination | None:
    """The frame's illumination field; None for a frame too small to fit one."""
    h, w = image.shape[:2]
    sh, sw = h // SCALE, w // SCALE
    if sh < 4 or sw < 4:
        return None
    sampled = np.ascontiguousarray(image[: sh * SCALE : STRIDE, : sw * SCALE : STRIDE])
    small = cv2.resize(sampled, (sw, sh), interpolation=cv2.INTER_AREA).astype(np.float64)
    # a block's samples sit at SCALE k + STRIDE i (i = 0 .. SCALE / STRIDE - 1): their mean
    # position in full-resolution pixel coordinates
    offset = STRIDE * (SCALE // STRIDE - 1) / 2.0
    xs = SCALE * np.arange(sw) + offset
    ys = SCALE * np.arange(sh) + offset
    centre = ((w - 1) / 2.0, (h - 1) / 2.0)
    half = (w / 2.0, h / 2.0)
    u = np.broadcast_to(((xs - centre[0]) / half[0])[None, :], (sh, sw)).ravel()
    v = np.broadcast_to(((ys - centre[1]) / half[1])[:, None], (sh, sw)).ravel()
    z = small.ravel()
    a = np.stack([np.ones_like(u), u, v, u * u, u * v, v * v], axis=1)
    wts = np.ones_like(z)
    coef = np.zeros(6)
    for _ in range(iterations):
        aw = a * wts[:, None]
        coef = np.linalg.solve(aw.T @ a + 1e-9 * np.eye(6), aw.T @ z)
        res = z - a @ coef
        scale = max(1.4826 * median(np.abs(res - median(res))), 1e-3)
        r = np.abs(res) / (_HUBER_K * scale)
        wts = np.where(r <= 1.0, 1.0, 1.0 / np.maximum(r, 1e-12))
    if not np.all(np.isfinite(coef)) or coef[0] <= 0:
        return None
    return Illumination(tuple(float(c) for c in coef), centre, half)
