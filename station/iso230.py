"""ISO 230-2:2014 evaluation of positioning accuracy and repeatability of one axis.

Why this module exists: a laser (linear axis) or rotary-calibrator (rotary axis)
recording is only useful to the plant once it is reduced to the figures that the
standard defines and that machine acceptance is written against (A, B, E, M, R).
The same per-target means also feed the compensation tables
(:mod:`station.compensation`), so the reduction is done here once.

Conventions (``docs/iso230.md`` states the formulas of ISO 230-2:2014):

* deviation ``x_ij = P_ij - P_i``: actual minus commanded, exactly the recording's
  ``deviation`` column (um for a linear axis, arcsec for a rotary one);
* direction ``up`` (the standard's ↑) is ``+1`` in the recording: the target was
  approached while moving towards larger targets; ``down`` (↓) is ``-1``;
* ``s`` is the estimator of the unidirectional standard uncertainty of positioning
  (sample standard deviation, ``n - 1`` in the denominator); it needs at least two
  approaches.  Where it is undefined the target is left out of every figure that
  uses ``s`` (R, A) and the result's ``warnings`` say so.

Undefined figures are ``None`` in :meth:`Iso230Result.to_json` (JSON has no NaN)
and ``nan`` in the numpy arrays.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from station.recording import Recording

#: Targets whose commanded positions differ by less than this fraction of the
#: travel (max target - min target) are the same target.  The value is the
#: project's convention (foundation issue); it absorbs the float noise of
#: recordings written by instrument software without merging real targets.
TARGET_TOLERANCE_FRACTION_OF_RANGE = 1e-6

#: ISO 230-2:2014 bands the mean deviation by ± 2s (coverage factor k = 2),
#: hence R_i = 4 s_i and A = max(x̄ + 2s) - min(x̄ - 2s).
COVERAGE_FACTOR = 2.0

#: ISO 230-2:2014 standard test cycle: five approaches to each target in each
#: direction.  Fewer are accepted here but reported.
STANDARD_APPROACHES_PER_DIRECTION = 5

#: deviation units of each axis kind (contract ``discovery.md`` section 1)
DEVIATION_UNIT = {"linear": "um", "rotary": "arcsec"}
#: position units of each axis kind
POSITION_UNIT = {"linear": "mm", "rotary": "deg"}


@dataclass(frozen=True)
class PerTargetStatistics:
    """Per-target, per-direction statistics as arrays of shape (m,) for m targets.

    Kept as arrays (not a list of objects) because the figures of merit are
    max/min reductions over targets and the compensation tables interpolate them.
    Entries that cannot be computed are ``nan`` (mean without any approach,
    ``s`` with fewer than two).
    """

    target: np.ndarray
    n_up: np.ndarray
    n_down: np.ndarray
    mean_up: np.ndarray
    mean_down: np.ndarray
    s_up: np.ndarray
    s_down: np.ndarray

    @property
    def bidirectional_mean(self) -> np.ndarray:
        """x̄_i = (x̄_i↑ + x̄_i↓) / 2; nan where a direction has no approach."""
        return 0.5 * (self.mean_up + self.mean_down)

    @property
    def reversal(self) -> np.ndarray:
        """B_i = x̄_i↑ - x̄_i↓ (positive when the up approach reads larger)."""
        return self.mean_up - self.mean_down

    def __len__(self) -> int:
        return int(self.target.size)


def group_targets(target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Group commanded positions into targets.

    Returns ``(group_of_row, target_of_group)``: the group index of every row and
    the target of every group (mean of its commanded positions), ascending.
    Neighbours in sorted order closer than
    ``TARGET_TOLERANCE_FRACTION_OF_RANGE * (max - min)`` join one group.
    """
    target = np.asarray(target, dtype=float)
    order = np.argsort(target, kind="stable")
    sorted_targets = target[order]
    span = float(sorted_targets[-1] - sorted_targets[0]) if target.size else 0.0
    tolerance = TARGET_TOLERANCE_FRACTION_OF_RANGE * span
    new_group = np.diff(sorted_targets) >= tolerance if span > 0 else np.zeros(max(target.size - 1, 0), bool)
    group_sorted = np.concatenate(([0], np.cumsum(new_group))) if target.size else np.zeros(0, int)
    group = np.empty_like(group_sorted)
    group[order] = group_sorted
    m = int(group_sorted[-1]) + 1 if target.size else 0
    target_of_group = np.bincount(group, weights=target, minlength=m) / np.bincount(group, minlength=m)
    return group, target_of_group


def _direction_stats(group: np.ndarray, deviation: np.ndarray, mask: np.ndarray, m: int):
    """n, mean and s (n-1) per group for the rows in ``mask``; nan where undefined."""
    g = group[mask]
    d = deviation[mask]
    n = np.bincount(g, minlength=m)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.bincount(g, weights=d, minlength=m) / n
        # two-pass sum of squares about the mean: no cancellation for large offsets
        ss = np.bincount(g, weights=(d - mean[g]) ** 2, minlength=m)
        s = np.sqrt(ss / (n - 1))
    mean = np.where(n > 0, mean, np.nan)
    s = np.where(n > 1, s, np.nan)
    return n, mean, s


def per_target_statistics(recording: Recording) -> PerTargetStatistics:
    """x̄_i↑, x̄_i↓, s_i↑, s_i↓ and the approach counts for every target."""
    group, target = group_targets(recording.target)
    m = target.size
    deviation = np.asarray(recording.deviation, dtype=float)
    direction = np.asarray(recording.direction)
    n_up, mean_up, s_up = _direction_stats(group, deviation, direction > 0, m)
    n_down, mean_down, s_down = _direction_stats(group, deviation, direction < 0, m)
    return PerTargetStatistics(target, n_up, n_down, mean_up, mean_down, s_up, s_down)


def _span(*arrays: np.ndarray) -> float:
    """max - min over the finite entries of all arrays; nan if there are none."""
    values = np.concatenate([np.ravel(a) for a in arrays])
    values = values[np.isfinite(values)]
    return float(values.max() - values.min()) if values.size else float("nan")


def _max(a: np.ndarray) -> float:
    a = a[np.isfinite(a)]
    return float(a.max()) if a.size else float("nan")


def _mean(a: np.ndarray) -> float:
    a = a[np.isfinite(a)]
    return float(a.mean()) if a.size else float("nan")


def _json_number(v: float) -> float | None:
    return None if v is None or not np.isfinite(v) else float(v)


@dataclass(frozen=True)
class Iso230Result:
    """The ISO 230-2:2014 figures of one axis, in deviation units (um or arcsec)."""

    kind: str
    unit: str
    position_unit: str
    stats: PerTargetStatistics
    B: float
    B_mean: float
    R_up: float
    R_down: float
    R: float
    E_up: float
    E_down: float
    E: float
    M: float
    A_up: float
    A_down: float
    A: float
    warnings: list[str] = field(default_factory=list)
    axis: str = ""
    source: str = ""

    FIGURES = ("B", "B_mean", "R_up", "R_down", "R", "E_up", "E_down", "E", "M", "A_up", "A_down", "A")

    def figures(self) -> dict[str, float]:
        """The twelve figures as floats (nan where undefined)."""
        return {k: getattr(self, k) for k in self.FIGURES}

    def targets_json(self) -> list[dict[str, Any]]:
        st = self.stats
        rows = []
        reversal = st.reversal
        for i in range(len(st)):
            rows.append({
                "target": float(st.target[i]),
                "mean_up": _json_number(st.mean_up[i]),
                "mean_down": _json_number(st.mean_down[i]),
                "s_up": _json_number(st.s_up[i]),
                "s_down": _json_number(st.s_down[i]),
                "n_up": int(st.n_up[i]),
                "n_down": int(st.n_down[i]),
                "B_i": _json_number(reversal[i]),
            })
        return rows

    def to_json(self) -> dict[str, Any]:
        """The contract's JSON object: exactly the figures, ``targets``, ``unit``,
        ``kind`` and ``warnings``; undefined numbers are ``null``."""
        out: dict[str, Any] = {k: _json_number(v) for k, v in self.figures().items()}
        out["targets"] = self.targets_json()
        out["unit"] = self.unit
        out["kind"] = self.kind
        out["warnings"] = list(self.warnings)
        return out


def _fmt_targets(target: np.ndarray, mask: np.ndarray) -> str:
    return ", ".join(f"{t:g}" for t in target[mask])


def analyse(recording: Recording) -> Iso230Result:
    """Evaluate a recording per ISO 230-2:2014 (formulas in ``docs/iso230.md``)."""
    kind = recording.kind
    st = per_target_statistics(recording)
    warnings: list[str] = []
    k = COVERAGE_FACTOR

    no_up = st.n_up == 0
    no_down = st.n_down == 0
    for missing, word, sign in ((no_up, "up", "+1"), (no_down, "down", "-1")):
        if missing.any():
            warnings.append(f"no {word} ({sign}) approach at target(s) {_fmt_targets(st.target, missing)}: "
                            f"left out of B, B_mean, M, R and of every {word}-direction figure")
    single_up = st.n_up == 1
    single_down = st.n_down == 1
    for single, word in ((single_up, "up"), (single_down, "down")):
        if single.any():
            warnings.append(f"only one {word} approach at target(s) {_fmt_targets(st.target, single)}: "
                            f"s_{word} is undefined there; left out of R_{word}, R, A_{word} and A")
    counts = np.concatenate([st.n_up[st.n_up > 0], st.n_down[st.n_down > 0]])
    if counts.size and counts.min() != counts.max():
        warnings.append(f"uneven number of approaches (from {int(counts.min())} to {int(counts.max())} "
                        "per target and direction); every statistic uses its own n")
    if counts.size and counts.min() < STANDARD_APPROACHES_PER_DIRECTION:
        warnings.append(f"fewer than the {STANDARD_APPROACHES_PER_DIRECTION} approaches per target and "
                        "direction of the ISO 230-2 standard test cycle; "
                        f"smallest count here is {int(counts.min())}")

    reversal = st.reversal  # nan where a direction is missing
    B = _max(np.abs(reversal))
    B_mean = _mean(reversal)

    R_i_up = 2 * k * st.s_up  # 4 s (nan where s undefined)
    R_i_down = 2 * k * st.s_down
    R_up = _max(R_i_up)
    R_down = _max(R_i_down)
    # R_i = max(2s↑ + 2s↓ + |B_i|, R_i↑, R_i↓) needs both s and B_i
    R_i = np.maximum(k * st.s_up + k * st.s_down + np.abs(reversal), np.maximum(R_i_up, R_i_down))
    R = _max(R_i)

    E_up = _span(st.mean_up)
    E_down = _span(st.mean_down)
    E = _span(st.mean_up, st.mean_down)
    M = _span(st.bidirectional_mean)

    # A needs s: the mean of a single approach has no 2s band and is left out
    upper_up = np.where(np.isfinite(st.s_up), st.mean_up + k * st.s_up, np.nan)
    lower_up = np.where(np.isfinite(st.s_up), st.mean_up - k * st.s_up, np.nan)
    upper_down = np.where(np.isfinite(st.s_down), st.mean_down + k * st.s_down, np.nan)
    lower_down = np.where(np.isfinite(st.s_down), st.mean_down - k * st.s_down, np.nan)
    A_up = _band(upper_up, lower_up)
    A_down = _band(upper_down, lower_down)
    A = _band(np.concatenate([upper_up, upper_down]), np.concatenate([lower_up, lower_down]))

    return Iso230Result(
        kind=kind,
        unit=DEVIATION_UNIT.get(kind, "um"),
        position_unit=POSITION_UNIT.get(kind, "mm"),
        stats=st,
        B=B, B_mean=B_mean, R_up=R_up, R_down=R_down, R=R,
        E_up=E_up, E_down=E_down, E=E, M=M, A_up=A_up, A_down=A_down, A=A,
        warnings=warnings,
        axis=recording.axis,
        source=recording.source,
    )


def _band(upper: np.ndarray, lower: np.ndarray) -> float:
    """max(upper) - min(lower) over finite entries; nan if either side is empty."""
    up = upper[np.isfinite(upper)]
    lo = lower[np.isfinite(lower)]
    if not up.size or not lo.size:
        return float("nan")
    return float(up.max() - lo.min())


def summary_lines(result: Iso230Result) -> list[str]:
    """The figures as short text lines (for the plot's text box and reports)."""
    u = result.unit

    def f(v: float) -> str:
        return "n/a" if not np.isfinite(v) else f"{v:.3f}"

    return [
        f"A = {f(result.A)} {u}  (A↑ {f(result.A_up)}, A↓ {f(result.A_down)})",
        f"E = {f(result.E)} {u}  (E↑ {f(result.E_up)}, E↓ {f(result.E_down)})",
        f"M = {f(result.M)} {u}",
        f"R = {f(result.R)} {u}  (R↑ {f(result.R_up)}, R↓ {f(result.R_down)})",
        f"B = {f(result.B)} {u}  (B̄ {f(result.B_mean)})",
    ]


def plot_result(result: Iso230Result, path) -> None:
    """Write a PNG: x̄↑ ± 2s and x̄↓ ± 2s against target, B_i, and the figures.

    Uses matplotlib's object API with the Agg canvas directly, so that no global
    backend is switched (the CLI may run inside other programs).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    st = result.stats
    k = COVERAGE_FACTOR
    fig = Figure(figsize=(9, 6.5), layout="constrained")
    FigureCanvasAgg(fig)
    ax_dev, ax_rev = fig.subplots(2, 1, sharex=True, height_ratios=(3, 1))
    for mean, s, label, colour, shift in (
        (st.mean_up, st.s_up, "up (+1): x̄↑ ± 2s", "tab:red", -1),
        (st.mean_down, st.s_down, "down (−1): x̄↓ ± 2s", "tab:blue", +1),
    ):
        ok = np.isfinite(mean)
        # a small horizontal shift keeps the two directions' error bars apart
        dx = shift * 0.004 * (np.ptp(st.target) if len(st) > 1 else 1.0)
        ax_dev.errorbar(st.target[ok] + dx, mean[ok], yerr=np.nan_to_num(k * s[ok]), fmt="o-",
                        color=colour, capsize=3, label=label, markersize=4)
    ax_dev.axhline(0.0, color="0.6", linewidth=0.8)
    ax_dev.set_ylabel(f"positional deviation / {result.unit}")
    title = "ISO 230-2:2014 positioning" + (f", axis {result.axis}" if result.axis else "")
    ax_dev.set_title(title)
    ax_dev.legend(loc="upper left", fontsize="small")
    ax_dev.text(0.99, 0.02, "\n".join(summary_lines(result)), transform=ax_dev.transAxes,
                ha="right", va="bottom", multialignment="left", fontsize="small", family="monospace",
                bbox={"boxstyle": "round", "facecolor": "white", "alpha": 0.85})
    reversal = st.reversal
    ok = np.isfinite(reversal)
    ax_rev.bar(st.target[ok], reversal[ok], width=0.6 * (np.min(np.diff(st.target)) if len(st) > 1 else 1.0),
               color="tab:purple")
    ax_rev.axhline(0.0, color="0.6", linewidth=0.8)
    ax_rev.set_ylabel(f"B_i / {result.unit}")
    ax_rev.set_xlabel(f"target / {result.position_unit}")
    fig.savefig(path, format="png", dpi=110)
