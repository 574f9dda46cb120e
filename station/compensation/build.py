"""Compensation tables from an ISO 230-2 recording.

Why via ISO 230-2: the per-target means x̄_i↑, x̄_i↓ are the standard's best estimate
of the systematic error at each target (repeatability averages out over the runs),
and using the same reduction as ``station iso230`` keeps the table consistent with the
acceptance report the engineer already has.
"""

from __future__ import annotations

import numpy as np

from station.compensation.table import CompensationTable
from station.iso230 import PerTargetStatistics, per_target_statistics
from station.recording import Recording

BUILD_MODES = ("bidirectional", "averaged")


def table_from_statistics(stats: PerTargetStatistics, kind: str, mode: str = "bidirectional",
                          axis: str = "", source: str = "<memory>") -> CompensationTable:
    """``bidirectional``: columns x̄_i↑ and x̄_i↓.  ``averaged``: x̄_i = (x̄_i↑ + x̄_i↓)/2 and
    backlash = B̄ = mean_i(x̄_i↑ − x̄_i↓), the ISO 230-2 mean reversal value.

    Every target needs both directions: a table with a hole would interpolate across
    it without saying so, so the targets lacking one are named and the build refused.
    """
    if mode not in BUILD_MODES:
        raise ValueError(f"mode must be one of {', '.join(BUILD_MODES)}, not {mode!r}")
    missing_up = stats.target[stats.n_up == 0]
    missing_down = stats.target[stats.n_down == 0]
    if missing_up.size or missing_down.size:
        parts = []
        if missing_up.size:
            parts.append("no up (+1) approach at " + ", ".join(f"{t:g}" for t in missing_up))
        if missing_down.size:
            parts.append("no down (-1) approach at " + ", ".join(f"{t:g}" for t in missing_down))
        raise ValueError("cannot build a compensation table: " + "; ".join(parts))
    if stats.target.size < 2:
        raise ValueError("cannot build a compensation table from a single target")
    notes = (f"built from {source} via ISO 230-2 per-target means ({mode})",)
    if mode == "bidirectional":
        return CompensationTable.bidirectional(kind, stats.target.copy(), stats.mean_up.copy(),
                                               stats.mean_down.copy(), axis=axis, source=source, notes=notes)
    backlash = float(np.mean(stats.reversal))
    return CompensationTable.averaged(kind, stats.target.copy(), stats.bidirectional_mean, backlash=backlash,
                                      axis=axis, source=source, notes=notes)


def table_from_recording(recording: Recording, mode: str = "bidirectional") -> CompensationTable:
    """Build a table from a recording (see :func:`table_from_statistics`)."""
    return table_from_statistics(per_target_statistics(recording), recording.kind, mode,
                                 axis=recording.axis, source=recording.source)
