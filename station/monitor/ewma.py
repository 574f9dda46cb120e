"""The EWMA control chart, with its false-alarm rate stated, not guessed.

For standardised observations ``x`` (in control: mean 0, standard deviation 1) the
chart keeps ``z_t = lam * x_t + (1 - lam) * z_{t-1}``, ``z_0 = 0``, and signals when
``|z_t| > h``, ``h = L * sqrt(lam / (2 - lam))`` (the asymptotic limit, used from the
first point on, so the run-length properties below hold as computed).

The in-control average run length (ARL0: inspections between false alarms) of a pair
(lam, L) is computed by the Markov-chain approximation of Brook and Evans (1972): the
interval [-h, h] is cut into ``m`` cells, the transition probabilities between cells
come from the normal distribution, and the ARL from each cell solves
``(I - P) arl = 1``. With m = 201 the ARL agrees with the published tables (Lucas and
Saccucci 1990: lam = 0.1, L = 2.814 -> 500) to well under 1 %. ``limit_for_arl`` finds
the L that gives a wanted ARL0 (bisection: the ARL grows with L).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.special import ndtr  # the normal law's cdf (scipy.stats costs ~1 s of import)

#: cells of the Markov chain: enough for 0.1 % on ARLs up to 1e6 (tests against tables)
CELLS = 201


def arl(lam: float, L: float, shift: float = 0.0, cells: int = CELLS) -> float:
    """Average run length of a two-sided EWMA chart (weight ``lam``, limit ``L``
    standard deviations of the asymptotic statistic) for observations whose mean is
    ``shift`` standard deviations off target."""
    if not 0 < lam <= 1 or not L > 0:
        raise ValueError(f"lam must be in (0, 1] and L positive, not {lam}, {L}")
    h = L * math.sqrt(lam / (2.0 - lam))
    w = 2.0 * h / cells
    c = -h + w * (np.arange(cells) + 0.5)
    upper = (c[None, :] + w / 2 - (1 - lam) * c[:, None]) / lam
    lower = (c[None, :] - w / 2 - (1 - lam) * c[:, None]) / lam
    P = ndtr(upper - shift) - ndtr(lower - shift)
    run = np.linalg.solve(np.eye(cells) - P, np.ones(cells))
    return float(run[cells // 2])


@functools.lru_cache(maxsize=64)
def limit_for_arl(lam: float, arl0: float) -> float:
    """The L whose in-control ARL is ``arl0`` (to 0.1 %). Remembered per (lam, arl0):
    the bisection solves a dozen or more 201-cell chains per limit (the station's
    three charts: 36 chains, 0.4 s beside a CI run, seconds on a loaded PC), and a
    station builds the same charts at every session."""
    lo, hi = 0.5, 8.0
    if arl(lam, hi) < arl0:
        raise ValueError(f"an ARL0 of {arl0:g} needs L beyond {hi} at lam = {lam}")
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if arl(lam, mid) < arl0:
            lo = mid
        else:
            hi = mid
        if hi - lo < 1e-4:
            break
    return hi


@dataclass
class EwmaChart:
    """One chart: ``lam``, ``L``; observations are standardised by the caller."""

    name: str
    lam: float = 0.2
    L: float = 3.0
    z: float = 0.0
    n: int = 0
    history: list[tuple[float, float]] = field(default_factory=list)  # (x, z)

    @property
    def limit(self) -> float:
        return self.L * math.sqrt(self.lam / (2.0 - self.lam))

    def add(self, x: float) -> bool:
        """Add a standardised observation; True when the chart signals."""
        if not math.isfinite(x):
            raise ValueError(f"chart {self.name}: observation {x!r} is not a number")
        self.z = self.lam * x + (1.0 - self.lam) * self.z
        self.n += 1
        self.history.append((x, self.z))
        return abs(self.z) > self.limit

    def restart(self) -> None:
        """After an alarm has been dealt with (a check, a new model): from target again."""
        self.z = 0.0

    def arl0(self) -> float:
        return arl(self.lam, self.L)
