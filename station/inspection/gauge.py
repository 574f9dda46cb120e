"""Type-1 gauge study (capability of the measuring system on a reference part).

For each characteristic, n repeated measurements x_i of one reference part with
reference value x_m, tolerance T = USL - LSL:

    s   = standard deviation of the x_i (n - 1)
    Cg  = (0.2 * T) / (6 * s)                     (K = 20 % of the tolerance, 6 s spread)
    Cgk = (0.1 * T - |mean(x) - x_m|) / (3 * s)

the usual convention (VDA 5 / AIAG MSA type-1 study). Common acceptance: Cg >= 1.33
and Cgk >= 1.33; the station's goal on the default twin is Cg >= 4 and Cgk >= 3.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: share of the tolerance the study compares the spread with (20 %) and the spread
#: taken as 6 s (+/- 3 s): the conventional type-1 parameters
K_TOLERANCE_SHARE = 0.2
SPREAD_S = 6.0


@dataclass(frozen=True)
class GaugeResult:
    characteristic: str
    n: int
    reference: float
    tolerance: float
    mean: float
    s: float
    bias: float
    cg: float
    cgk: float
    values: tuple[float, ...]

    def to_json(self) -> dict:
        d = dict(self.__dict__)
        d["values"] = list(self.values)
        for k in ("cg", "cgk"):
            if not math.isfinite(d[k]):
                d[k] = None  # s = 0: capability unbounded, JSON has no infinity
        return d


def type1(characteristic: str, values, reference: float, lower: float, upper: float) -> GaugeResult:
    x = np.asarray(values, dtype=float)
    if x.size < 2:
        raise ValueError(f"{characteristic}: a gauge study needs at least 2 measurements, got {x.size}")
    T = upper - lower
    s = float(x.std(ddof=1))
    mean = float(x.mean())
    bias = mean - reference
    cg = (K_TOLERANCE_SHARE * T) / (SPREAD_S * s) if s > 0 else math.inf
    cgk = (K_TOLERANCE_SHARE / 2 * T - abs(bias)) / (SPREAD_S / 2 * s) if s > 0 else math.inf
    return GaugeResult(characteristic, int(x.size), reference, T, mean, s, bias, cg, cgk, tuple(map(float, x)))


def plot_gauge(results: list[GaugeResult], path) -> None:
    """One histogram per characteristic: values, reference, +/- 10 % of T band."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(4.2 * len(results), 3.6))
    FigureCanvasAgg(fig)
    for i, r in enumerate(results):
        ax = fig.add_subplot(1, len(results), i + 1)
        dev_um = (np.asarray(r.values) - r.reference) * 1e3
        ax.hist(dev_um, bins=max(5, min(20, r.n // 2)), color="0.55", edgecolor="0.2")
        ax.axvline(0.0, color="k", lw=1.0, label="reference")
        band = K_TOLERANCE_SHARE / 2 * r.tolerance * 1e3
        s_um = max(r.s * 1e3, 1e-3)
        lo, hi = min(dev_um.min(), 0.0) - 3 * s_um, max(dev_um.max(), 0.0) + 3 * s_um
        if hi - lo > band:  # the +/-10 % band fits on a readable scale: draw it
            ax.axvspan(-band, band, color="0.9", zorder=-1, label="±10 % of T")
            lo, hi = min(lo, -band * 1.1), max(hi, band * 1.1)
        else:  # a capable gauge: the band is far off scale, say so instead
            ax.text(0.02, 0.97, f"±10 % of T = ±{band:.0f} um\n(off scale)", transform=ax.transAxes,
                    va="top", fontsize=7, color="0.3")
        ax.set_xlim(lo, hi)
        ax.set_title(f"{r.characteristic}\nCg {r.cg:.1f}  Cgk {r.cgk:.1f}  (n={r.n})", fontsize=9)
        ax.set_xlabel("measured - reference, um")
        if i == 0:
            ax.set_ylabel("count")
            ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
