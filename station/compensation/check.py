"""Validation of compensation tables and segment models: say every problem, with where and how big.

Why: a compensation that is applied goes straight into the commanded position.  An
unsorted or duplicated position, a NaN, a gap between segments or a jump at a junction
moves the axis by that amount without warning.  :func:`check` lists every such
problem (not only the first), each with the position and/or source line and its
size, so the engineer can fix the file in one pass.

Severities: ``error`` (cannot be applied), ``warning`` (can be applied but something
is suspicious: a step larger than asked for, a jump at a rotary wrap), ``note``
(information, e.g. the segments were listed in descending order and were sorted).
``station compensation check`` exits non-zero on any error or warning.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from station.compensation.segments import DEFAULT_JUNCTION_TOLERANCE, SegmentModel, junctions
from station.compensation.table import FULL_TURN_DEG, CompensationTable


@dataclass(frozen=True)
class Problem:
    code: str
    severity: str  # "error" | "warning" | "note"
    message: str
    position: float | None = None
    line: int | None = None
    size: float | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"code": self.code, "severity": self.severity, "message": self.message,
                "position": self.position, "line": self.line, "size": self.size}

    def __str__(self) -> str:
        return f"{self.severity}: {self.message}"


def _where(line: int | None, position: float | None = None, unit: str = "") -> str:
    parts = []
    if line is not None:
        parts.append(f"line {line}")
    if position is not None and np.isfinite(position):
        parts.append(f"at {position:g} {unit}".rstrip())
    return ", ".join(parts)


def check_table(table: CompensationTable, max_step: float | None = None) -> list[Problem]:
    """Problems of a table: non-finite values, unsorted/duplicate positions, rotary span, steps."""
    problems: list[Problem] = []
    pos = table.position
    n = pos.size
    lines = table.line if table.line is not None and table.line.size == n else np.full(n, None, dtype=object)
    pu, eu = table.position_unit, table.error_unit

    def line_of(i):
        v = lines[i]
        return None if v is None else int(v)

    if n < 2:
        problems.append(Problem("too-few-positions", "error",
                                f"a table needs at least two positions, this one has {n}"))
    for i in np.flatnonzero(~np.isfinite(pos)):
        problems.append(Problem("non-finite", "error",
                                f"{_where(line_of(i))}: position is {float(pos[i])!r}".lstrip(": "),
                                line=line_of(i)))
    for name in table.columns:
        col = getattr(table, name)
        for i in np.flatnonzero(~np.isfinite(col)):
            problems.append(Problem("non-finite", "error",
                                    f"{_where(line_of(i), pos[i], pu)}: {name} is {float(col[i])!r}".lstrip(": "),
                                    position=float(pos[i]), line=line_of(i)))
    if not np.isfinite(table.backlash):
        problems.append(Problem("non-finite", "error", f"backlash is {table.backlash!r}"))

    finite = np.isfinite(pos)
    idx = np.flatnonzero(finite)
    step = np.diff(pos[idx])
    for k in np.flatnonzero(step < 0):
        i, j = idx[k], idx[k + 1]
        problems.append(Problem("unsorted", "error",
                                f"{_where(line_of(j))}: position {pos[j]:g} {pu} comes after {pos[i]:g} {pu} "
                                f"(positions must increase; it goes back by {pos[i] - pos[j]:g} {pu})".lstrip(": "),
                                position=float(pos[j]), line=line_of(j), size=float(pos[i] - pos[j])))
    for k in np.flatnonzero(step == 0):
        i, j = idx[k], idx[k + 1]
        problems.append(Problem("duplicate", "error",
                                f"{_where(line_of(j))}: position {pos[j]:g} {pu} repeats "
                                f"{'line ' + str(line_of(i)) if line_of(i) is not None else 'the previous row'}".lstrip(": "),
                                position=float(pos[j]), line=line_of(j), size=0.0))
    # a duplicate anywhere (not only neighbours) in an unsorted table
    if np.any(step < 0):
        values, counts = np.unique(pos[idx], return_counts=True)
        seen_adjacent = {float(pos[idx[k + 1]]) for k in np.flatnonzero(step == 0)}
        for v in values[counts > 1]:
            if float(v) not in seen_adjacent:
                rows = [line_of(i) for i in idx if pos[i] == v]
                problems.append(Problem("duplicate", "error",
                                        f"position {v:g} {pu} appears {len(rows)} times"
                                        + (f" (lines {', '.join(str(r) for r in rows)})" if rows[0] is not None else ""),
                                        position=float(v), line=rows[1], size=0.0))

    if table.kind == "rotary" and idx.size >= 2 and not np.any(step <= 0):
        span = float(pos[idx[-1]] - pos[idx[0]])
        if span > FULL_TURN_DEG:
            problems.append(Problem("rotary-span", "error",
                                    f"a rotary table spans at most one turn; this one spans {span:g} deg",
                                    size=span - FULL_TURN_DEG))
        elif span == FULL_TURN_DEG:
            for name in table.columns:
                col = getattr(table, name)
                jump = float(col[idx[-1]] - col[idx[0]])
                if jump != 0 and np.isfinite(jump):
                    problems.append(Problem("wrap-jump", "warning",
                                            f"{name} at {pos[idx[-1]]:g} deg differs from {pos[idx[0]]:g} deg "
                                            f"(the same angle) by {jump:g} {eu}",
                                            position=float(pos[idx[-1]]), line=line_of(idx[-1]), size=jump))

    if max_step is not None and idx.size >= 2 and not np.any(step <= 0):
        for name in table.columns:
            col = getattr(table, name)[idx]
            d = np.diff(col)
            for k in np.flatnonzero(np.abs(d) > max_step):
                j = idx[k + 1]
                problems.append(Problem("max-step", "warning",
                                        f"{_where(line_of(j), pos[j], pu)}: {name} changes by {d[k]:g} {eu} "
                                        f"from the previous position (more than --max-step {max_step:g})".lstrip(": "),
                                        position=float(pos[j]), line=line_of(j), size=float(d[k])))
    return problems


def check_segments(model: SegmentModel, tolerance: float = DEFAULT_JUNCTION_TOLERANCE,
                   max_step: float | None = None) -> list[Problem]:
    """Problems of a segment list: non-finite numbers, empty segments, order, gaps, overlaps, jumps."""
    problems: list[Problem] = []
    if len(model) == 0:
        return [Problem("empty", "error", "no segments")]
    bad = False
    for s in model.segments:
        for name in ("x_from", "x_to", "slope", "intercept"):
            v = getattr(s, name)
            if not np.isfinite(v):
                bad = True
                problems.append(Problem("non-finite", "error",
                                        f"{_where(s.line)}: {name} is {v!r}".lstrip(": "), line=s.line))
        if np.isfinite(s.x_from) and np.isfinite(s.x_to) and s.x_to <= s.x_from:
            bad = True
            problems.append(Problem("empty-segment", "error",
                                    f"{_where(s.line)}: segment [{s.x_from:g}, {s.x_to:g}] is empty or reversed "
                                    "(x_to must exceed x_from)".lstrip(": "),
                                    position=float(s.x_from), line=s.line, size=float(s.x_to - s.x_from)))
    if bad:
        return problems  # junctions of non-finite or reversed segments mean nothing

    arrays = model.arrays()
    x_from = arrays["x_from"]
    if len(model) > 1 and not model.is_ascending():
        if np.all(np.diff(x_from) < 0):
            order = "in descending x"
        else:
            order = "not in ascending x"
        problems.append(Problem("order", "note",
                                f"segments are listed {order}; they were sorted by x_from before checking"))

    for j in junctions(model):
        left, right, gap = j["left"], j["right"], j["gap"]
        lines = f"lines {left.line} and {right.line}: " if left.line is not None else ""
        if gap > tolerance:
            problems.append(Problem("gap", "error",
                                    f"{lines}gap of {gap:g} between x = {left.x_to:g} and x = {right.x_from:g}: "
                                    "no compensation defined there",
                                    position=float(left.x_to), line=right.line, size=float(gap)))
        elif gap < -tolerance:
            problems.append(Problem("overlap", "error",
                                    f"{lines}segments overlap by {-gap:g} on [{right.x_from:g}, {left.x_to:g}]: "
                                    "two values for the same position",
                                    position=float(right.x_from), line=right.line, size=float(-gap)))
        elif abs(j["jump"]) > tolerance:
            x = j["position"]
            y_left = float(left.value(left.x_to))
            y_right = float(right.value(right.x_from))
            problems.append(Problem("discontinuity", "error",
                                    f"{lines}jump of {j['jump']:+.4f} at x = {x:g} "
                                    f"(left segment ends at {y_left:.4f}, right segment starts at {y_right:.4f})",
                                    position=float(x), line=right.line, size=float(j["jump"])))
    if max_step is not None:
        for s in model.sorted().segments:
            change = s.slope * (s.x_to - s.x_from)
            if abs(change) > max_step:
                problems.append(Problem("max-step", "warning",
                                        f"{_where(s.line)}: segment [{s.x_from:g}, {s.x_to:g}] changes by "
                                        f"{change:g} (more than --max-step {max_step:g})".lstrip(": "),
                                        position=float(s.x_from), line=s.line, size=float(change)))
    return problems


def check(obj: CompensationTable | SegmentModel, max_step: float | None = None,
          tolerance: float = DEFAULT_JUNCTION_TOLERANCE) -> list[Problem]:
    """Every problem of a table or a segment model (see the module docstring for severities)."""
    if isinstance(obj, CompensationTable):
        return check_table(obj, max_step=max_step)
    if isinstance(obj, SegmentModel):
        return check_segments(obj, tolerance=tolerance, max_step=max_step)
    raise TypeError(f"check() takes a CompensationTable or a SegmentModel, not {type(obj).__name__}")


def failing(problems: list[Problem]) -> list[Problem]:
    """The problems that make ``station compensation check`` exit non-zero (errors, warnings)."""
    return [p for p in problems if p.severity in ("error", "warning")]
