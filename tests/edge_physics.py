"""The exact share of a blurred disc at a pixel, for the renderer's and the fit's tests of
the hole's edge: the disc of ``radius`` blurred by an isotropic Gaussian of ``blur`` (the
non-central chi-square cdf of the distance, exact), then averaged over the pixel's square
(8 x 8 Gauss-Legendre nodes of that smooth function: the camera blurs the scene, then the
pixel integrates it)."""

from __future__ import annotations

import numpy as np
from scipy.stats import ncx2


def exact_pixel_share(xx: np.ndarray, yy: np.ndarray, cx: float, cy: float, radius: float,
                      blur: float) -> np.ndarray:
    g, w = np.polynomial.legendre.leggauss(8)
    g, w = g / 2, w / 2
    out = np.zeros(np.shape(xx))
    for a, wa in zip(g, w):
        for b, wb in zip(g, w):
            out += wa * wb * ncx2.cdf((radius / blur) ** 2, 2, (np.hypot(xx + a - cx, yy + b - cy) / blur) ** 2)
    return out
