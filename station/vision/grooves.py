"""The honing cross-hatch over the whole frame: one profile per groove family.

Why: a honing groove is a straight line that crosses the whole frame, so its profile
across its direction is read on every wall pixel along it, not only on the 18 px ring
around one hole (``photometric._groove_field``).  On the ring each 0.5 px bin of a
family's profile holds some tens of pixels of grain; along the frame it holds hundreds.
What the frame cannot give is a groove's depth at the hole: grooves fade in and out
along their length (worn stones, plateau honing) over ~100 px.  So the frame gives the
shape P_k(u) of each family k, and each hole's ring gives only how deep the family is
there: an amplitude that varies linearly across the ring (three numbers per family, in
place of a profile of some hundred bins).

Model: the wall's relative reflectance about its smooth level (a normalised Gaussian
smoothing over the wall, holes masked) is the sum of the families' profiles, each a
function of u_k = -sin(a_k) x + cos(a_k) y, fitted by backfitting bin means of 0.5 px
(robust: pixels beyond 4 MAD, pores and scratches, drop out).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from station.vision.fit import median

#: the smooth level the grooves are read against: a Gaussian of this sigma (px), wide
#: against a groove (0.8-3 px) and narrow against the blotches and the vignetting
SMOOTH_SIGMA_PX = 10.0
#: pixels this many robust standard deviations off their bin are outliers (defects)
_CLIP = 4.0


@dataclass(frozen=True)
class FrameGrooves:
    """Each family's relative profile across its direction, over the frame."""

    angles_rad: tuple[float, ...]
    u0: tuple[float, ...]  # u of each profile's first bin centre
    step_px: float
    profiles: tuple[np.ndarray, ...]  # relative (1 = the wall's level), one per family
    level: np.ndarray  # the wall's smooth level (DN), the frame's shape

    def values(self, x: np.ndarray, y: np.ndarray) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Per family: the relative profile at pixels (x, y), and its derivative in u."""
        vals, ders = [], []
        for a, u0, p in zip(self.angles_rad, self.u0, self.profiles):
            u = (-np.sin(a) * x + np.cos(a) * y - u0) / self.step_px
            grid = np.arange(p.size, dtype=np.float64)
            vals.append(np.interp(u, grid, p, left=0.0, right=0.0))
            ders.append(np.interp(u, grid, np.gradient(p) / self.step_px, left=0.0, right=0.0))
        return vals, ders


def frame_grooves(image: np.ndarray, holes: list[tuple[float, float, float]], angles_deg=(30.0, -30.0),
                  step_px: float = 0.5, sweeps: int = 3, stride: int = 1) -> FrameGrooves | None:
    """The families' profiles from the wall of a grey frame; ``holes``: (x, y, radius)
    of the dark holes to leave out (with a margin for their blur).  None when too little
    wall is left."""
    img = image.astype(np.float32)
    h, w = img.shape
    mask = np.ones((h, w), np.float32)
    for x, y, r in holes:
        cv2.circle(mask, (int(round(x)), int(round(y))), int(np.ceil(r + 6.0)), 0.0, -1)
    num = cv2.GaussianBlur(img * mask, (0, 0), SMOOTH_SIGMA_PX)
    den = cv2.GaussianBlur(mask, (0, 0), SMOOTH_SIGMA_PX)
    level = num / np.maximum(den, 1e-3)
    ok = (mask > 0) & (den > 0.5) & (level > 5.0)
    if stride > 1:
        sub = np.zeros_like(ok)
        sub[::stride] = True
        ok &= sub
    ys, xs = np.nonzero(ok)
    if xs.size < 10_000:
        return None
    rel = (img[ys, xs] / level[ys, xs] - 1.0).astype(np.float64)
    xs, ys = xs.astype(np.float64), ys.astype(np.float64)
    angles = tuple(float(np.deg2rad(a)) for a in angles_deg)
    idx, u0s, nbs = [], [], []
    for a in angles:
        u = -np.sin(a) * xs + np.cos(a) * ys
        lo = float(u.min()) - step_px
        j = np.floor((u - lo) / step_px).astype(np.int64)
        idx.append(j)
        u0s.append(lo + 0.5 * step_px)
        nbs.append(int(j.max()) + 1)
    weights = np.ones_like(rel)
    prof = [np.zeros(n) for n in nbs]
    for it in range(sweeps + 1):
        for f in range(len(angles)):
            other = sum(prof[g][idx[g]] for g in range(len(angles)) if g != f)
            target = (rel - other) * weights
            cnt = np.bincount(idx[f], weights, minlength=nbs[f])
            prof[f] = np.bincount(idx[f], target, minlength=nbs[f]) / np.maximum(cnt, 1.0)
        if it == 0:  # after a first pass, drop the outliers (pores, scratches, glints)
            res = rel - sum(prof[g][idx[g]] for g in range(len(angles)))
            scale = max(1.4826 * median(np.abs(res)), 1e-4)
            weights = (np.abs(res) <= _CLIP * scale).astype(np.float64)
    return FrameGrooves(angles, tuple(u0s), step_px, tuple(p.astype(np.float64) for p in prof), level)
