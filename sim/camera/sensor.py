"""The camera twin's sensor flaws: pixels that do not answer the light as their
neighbours do, the same pixels in every frame (fixed-pattern).

A real CCD or CMOS sensor of a million pixels ships with some of them flawed, and more
appear as it ages (cosmic-ray damage, heat):

* **hot pixels**: a pixel whose dark current is far above the others' collects a dark
  signal in every exposure, added to the light's and as noisy as charge is (Poisson).
  Their dark signals spread over decades: a log-normal law of ``hot_median_dn`` (at
  the twin's exposure) and a spread of ``hot_spread`` in the logarithm.
* **dead (dim) pixels**: a pixel whose photodiode answers with a fraction of the
  others' sensitivity, 0-50 % of it (a particle on the microlens, a bad diode).
* **a trap in a column**: a charge trap in a CCD's vertical register takes up to
  ``trap_dn`` of every charge packet that passes it on its way to the readout register
  (at the frame's last row): every pixel of that column from the trap upwards (rows 0
  to the trap's) reads that much less, a dark partial column in every frame. It takes
  charge after it was collected, so before the read noise and after the shot noise.

And on the lens's front, where the endoscope looks out:

* **specks**: dust or a dried drop of coolant on the endoscope's window, far out of
  focus: a soft dark blob (a Gaussian of ``speck_px`` px, taking ``speck_depth`` of
  the light at its middle) at the same place in every frame, over whatever the wall
  shows there.

The flaws are drawn once from ``seed`` and the frame's size (``pattern``): a sensor is
the same sensor in every frame. Without a ``SensorFlaws`` in ``FrameParams.sensor``
every frame is what it was before this existed.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np


@dataclass(frozen=True)
class SensorFlaws:
    """What the twin's sensor has wrong (shares of its pixels; DN of an 8-bit frame)."""

    seed: int = 0
    #: share of hot pixels (an industrial sensor: 1e-5 to 1e-3, more when warm or old)
    hot_share: float = 2e-4
    #: the hot pixels' median dark signal at the twin's exposure (DN) and its log spread
    hot_median_dn: float = 25.0
    hot_spread: float = 0.8
    #: share of dead (dim) pixels, each answering with 0-50 % of the light
    dead_share: float = 5e-5
    #: charge traps in the vertical register: how many columns, and the charge each takes
    traps: int = 1
    trap_dn: float = 12.0
    #: specks on the window: how many, their size (Gaussian sigma, px) and the share of
    #: the light each takes at its middle
    specks: int = 0
    speck_px: float = 8.0
    speck_depth: float = 0.3

    def __post_init__(self):
        for name in ("hot_share", "dead_share"):
            v = getattr(self, name)
            if not 0.0 <= v <= 0.05:
                raise ValueError(f"sensor flaws: {name} must be a share within 0-0.05, not {v}")
        if not 0.0 <= self.speck_depth <= 1.0:
            raise ValueError(f"sensor flaws: speck_depth must be a share within 0-1, not {self.speck_depth}")
        for name in ("hot_median_dn", "hot_spread", "trap_dn", "speck_px"):
            if getattr(self, name) < 0:
                raise ValueError(f"sensor flaws: {name} must be >= 0, not {getattr(self, name)}")
        for name in ("traps", "specks"):
            if not isinstance(getattr(self, name), int) or getattr(self, name) < 0:
                raise ValueError(f"sensor flaws: {name} must be a whole number >= 0, not {getattr(self, name)!r}")


@dataclass(frozen=True)
class FlawPattern:
    """The flaws drawn for one frame size: the truth a bench scores a map against."""

    hot_rows: np.ndarray
    hot_cols: np.ndarray
    hot_dn: np.ndarray
    dead_rows: np.ndarray
    dead_cols: np.ndarray
    dead_gain: np.ndarray
    #: (column, row of the trap, DN taken): rows 0..row of that column are short
    traps: tuple[tuple[int, int, float], ...]
    #: (x px, y px): the specks' middles on the frame
    specks: tuple[tuple[float, float], ...] = ()


@lru_cache(maxsize=8)
def pattern(flaws: SensorFlaws, width_px: int, height_px: int) -> FlawPattern:
    """The flaws of ``flaws``'s sensor on a ``width_px`` x ``height_px`` frame (the same
    every call: one sensor)."""
    rng = np.random.default_rng(flaws.seed)
    n = width_px * height_px
    n_hot = int(rng.binomial(n, flaws.hot_share))
    n_dead = int(rng.binomial(n, flaws.dead_share))
    idx = rng.choice(n, size=n_hot + n_dead, replace=False)
    hot, dead = idx[:n_hot], idx[n_hot:]
    hot_dn = flaws.hot_median_dn * np.exp(flaws.hot_spread * rng.standard_normal(n_hot))
    dead_gain = rng.uniform(0.0, 0.5, n_dead)
    cols = rng.choice(width_px, size=min(flaws.traps, width_px), replace=False)
    # a trap somewhere in the lower three quarters: the column is short above it
    traps = tuple((int(c), int(rng.integers(height_px // 4, height_px)), float(flaws.trap_dn)) for c in cols)
    # specks last, so that a sensor's other flaws do not change with their number
    specks = tuple((float(rng.uniform(0.1, 0.9) * width_px), float(rng.uniform(0.1, 0.9) * height_px))
                   for _ in range(flaws.specks))
    arrays = [hot // width_px, hot % width_px, hot_dn.astype(np.float32), dead // width_px, dead % width_px,
              dead_gain.astype(np.float32)]
    for a in arrays:
        a.setflags(write=False)
    return FlawPattern(*arrays, traps, specks)


@lru_cache(maxsize=4)
def window(flaws: SensorFlaws, width_px: int, height_px: int) -> np.ndarray | None:
    """The window's transmission over the frame (float32), None without specks."""
    p = pattern(flaws, width_px, height_px)
    if not p.specks:
        return None
    y, x = np.mgrid[0:height_px, 0:width_px].astype(np.float32)
    t = np.ones((height_px, width_px), np.float32)
    s2 = 2.0 * flaws.speck_px**2
    for sx, sy in p.specks:
        t *= 1.0 - np.float32(flaws.speck_depth) * np.exp(-((x - sx) ** 2 + (y - sy) ** 2) / s2)
    t.setflags(write=False)
    return t


def through_window(radiance: np.ndarray, flaws: SensorFlaws) -> np.ndarray:
    """The light past the window's specks (in place when there are any)."""
    t = window(flaws, radiance.shape[1], radiance.shape[0])
    if t is not None:
        radiance *= t
    return radiance


def collect(signal: np.ndarray, flaws: SensorFlaws) -> np.ndarray:
    """The charge the pixels collect (DN, before noise) from the light's ``signal``:
    dim pixels answer with their share of it, hot ones add their dark signal."""
    p = pattern(flaws, signal.shape[1], signal.shape[0])
    out = signal.copy()
    out[p.dead_rows, p.dead_cols] *= p.dead_gain
    out[p.hot_rows, p.hot_cols] += p.hot_dn
    return out


def transfer(charge: np.ndarray, flaws: SensorFlaws) -> np.ndarray:
    """The charge as it reaches the readout (in place): each trap takes its share of
    every packet that passes it, never more than the packet holds."""
    p = pattern(flaws, charge.shape[1], charge.shape[0])
    for col, row, dn in p.traps:
        column = charge[: row + 1, col]
        np.maximum(column - np.float32(dn), 0.0, out=column)
    return charge
