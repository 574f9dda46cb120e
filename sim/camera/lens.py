"""Pinhole camera with Brown radial/tangential distortion (OpenCV's k1, k2, p1, p2).

The renderer needs the model in both directions: ``distort_px`` maps ideal
(undistorted) pixel coordinates to where the lens puts them on the sensor, and
``undistort_px`` inverts that by fixed-point iteration, vectorised over any number of
points, because every rendered pixel must ask "which scene point do I see?".

Pixel convention (shared with ``station.vision``): the centre of pixel (0, 0) is at
(0, 0), x to the right, y down.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np


@dataclass(frozen=True)
class BrownLens:
    """Intrinsics (px) and distortion coefficients in OpenCV's order (k1, k2, p1, p2)."""

    fx_px: float = 1400.0
    fy_px: float = 1400.0
    cx_px: float = 639.5
    cy_px: float = 511.5
    k1: float = 0.0
    k2: float = 0.0
    p1: float = 0.0
    p2: float = 0.0

    @property
    def camera_matrix(self) -> np.ndarray:
        return np.array([[self.fx_px, 0.0, self.cx_px], [0.0, self.fy_px, self.cy_px], [0.0, 0.0, 1.0]])

    @property
    def dist_coeffs(self) -> np.ndarray:
        return np.array([self.k1, self.k2, self.p1, self.p2])

    @property
    def has_distortion(self) -> bool:
        return any(v != 0.0 for v in (self.k1, self.k2, self.p1, self.p2))

    def _offsets(self, xn: np.ndarray, yn: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Radial factor and tangential offsets of the Brown model at normalised (xn, yn)."""
        r2 = xn * xn + yn * yn
        radial = 1.0 + r2 * (self.k1 + self.k2 * r2)
        dx = 2.0 * self.p1 * xn * yn + self.p2 * (r2 + 2.0 * xn * xn)
        dy = self.p1 * (r2 + 2.0 * yn * yn) + 2.0 * self.p2 * xn * yn
        return radial, dx, dy

    def distort_px(self, x_px: np.ndarray, y_px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ideal pixel coordinates -> distorted (sensor) pixel coordinates."""
        xn = (np.asarray(x_px, float) - self.cx_px) / self.fx_px
        yn = (np.asarray(y_px, float) - self.cy_px) / self.fy_px
        radial, dx, dy = self._offsets(xn, yn)
        return (xn * radial + dx) * self.fx_px + self.cx_px, (yn * radial + dy) * self.fy_px + self.cy_px

    def undistort_px(self, x_px: np.ndarray, y_px: np.ndarray, iterations: int = 25) -> tuple[np.ndarray, np.ndarray]:
        """Distorted pixel coordinates -> ideal pixel coordinates (fixed-point inverse).

        The same iteration as OpenCV's undistortPoints; 25 steps converge to far below
        1e-6 px for the barrel distortion of an endoscope (|k1| <= 0.3 over the frame).
        It stops early once no point moves by more than 1e-12 of the focal length (a
        mild lens, the endoscope's k1 = -0.08, needs 9 steps: the whole sensor's grid,
        1.3 million points, is undistorted once per render process).
        """
        xd = (np.asarray(x_px, float) - self.cx_px) / self.fx_px
        yd = (np.asarray(y_px, float) - self.cy_px) / self.fy_px
        xn, yn = xd.copy(), yd.copy()
        if not self.has_distortion:
            return np.asarray(x_px, float).copy(), np.asarray(y_px, float).copy()
        for _ in range(iterations):
            radial, dx, dy = self._offsets(xn, yn)
            xn_new = (xd - dx) / radial
            yn_new = (yd - dy) / radial
            moved = max(float(np.max(np.abs(xn_new - xn), initial=0.0)),
                        float(np.max(np.abs(yn_new - yn), initial=0.0)))
            xn, yn = xn_new, yn_new
            if moved <= 1e-12:
                break
        return xn * self.fx_px + self.cx_px, yn * self.fy_px + self.cy_px


@lru_cache(maxsize=4)
def ideal_pixel_grid(lens: BrownLens | None, width_px: int, height_px: int) -> tuple[np.ndarray, np.ndarray]:
    """Ideal coordinates seen by every sensor pixel (cached: the same lens renders many frames)."""
    yy, xx = np.mgrid[0:height_px, 0:width_px].astype(np.float64)
    if lens is None or not lens.has_distortion:
        return xx, yy
    xu, yu = lens.undistort_px(xx, yy)
    return xu, yu
