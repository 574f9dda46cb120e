"""Piecewise-linear compensation models: ``y = slope·x + intercept`` on ``[x_from, x_to]``.

Why a separate model: papers (the seed paper's Eq. 16) and some controllers publish
compensation as segment lists rather than tables.  Such a list can be applied only if
its segments tile the travel and meet at every junction; a jump at a junction would
be a step in the commanded position.  :func:`station.compensation.check.check_segments`
says where that fails; :func:`segments_to_table` refuses to sample a model that fails.

``y`` is the error (actual − commanded) in deviation units unless the file says
``# quantity: correction``; then ``y`` is the correction and the table gets ``−y``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from station.compensation.table import CompensationTable, TableError

QUANTITIES = ("error", "correction")

#: Default tolerance for "two segments meet" and "the junction has no jump", in the
#: model's units.  It allows for coefficients stored as binary floats, not for
#: coefficients printed with few decimals: raise it (``--tolerance``) for those.
DEFAULT_JUNCTION_TOLERANCE = 1e-6


@dataclass(frozen=True)
class Segment:
    x_from: float
    x_to: float
    slope: float
    intercept: float
    #: 1-based line in the source file, if read from one
    line: int | None = None

    def value(self, x) -> np.ndarray:
        return self.slope * np.asarray(x, dtype=float) + self.intercept


@dataclass(frozen=True)
class SegmentModel:
    """Segments in the order given (the file's order, which may not be ascending)."""

    segments: tuple[Segment, ...]
    kind: str = "linear"
    quantity: str = "error"
    source: str = "<memory>"
    metadata: dict[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.quantity not in QUANTITIES:
            raise ValueError(f"quantity must be 'error' or 'correction', not {self.quantity!r}")

    def __len__(self) -> int:
        return len(self.segments)

    def sorted(self) -> "SegmentModel":
        """The same segments ascending by ``x_from`` (ties by ``x_to``)."""
        order = sorted(self.segments, key=lambda s: (s.x_from, s.x_to))
        return SegmentModel(tuple(order), self.kind, self.quantity, self.source, dict(self.metadata))

    def arrays(self) -> dict[str, np.ndarray]:
        """Columns as arrays (file order)."""
        return {name: np.array([getattr(s, name) for s in self.segments], dtype=float)
                for name in ("x_from", "x_to", "slope", "intercept")}

    def is_ascending(self) -> bool:
        x_from = self.arrays()["x_from"]
        return bool(np.all(np.diff(x_from) > 0))


def junctions(model: SegmentModel) -> list[dict]:
    """Every neighbouring pair after sorting: gap/overlap and the jump where they meet.

    Returns dicts with ``left``, ``right`` (segments), ``gap`` (``right.x_from −
    left.x_to``; negative is an overlap), ``position`` (the junction, mid-gap) and
    ``jump`` = right(right.x_from) − left(left.x_to), meaningful where the gap is ~0.
    """
    segs = model.sorted().segments
    out = []
    for left, right in zip(segs[:-1], segs[1:]):
        gap = right.x_from - left.x_to
        entry = {"left": left, "right": right, "gap": gap}
        x_j = 0.5 * (left.x_to + right.x_from)
        entry["position"] = x_j
        entry["jump"] = float(right.value(right.x_from) - left.value(left.x_to))
        out.append(entry)
    return out


def segments_to_table(model: SegmentModel, tolerance: float = DEFAULT_JUNCTION_TOLERANCE) -> CompensationTable:
    """Sample a continuous, gap-free model at its breakpoints (exact for a piecewise-linear model).

    Refuses (``TableError`` listing the problems) if any junction has a gap, an overlap
    or a jump beyond ``tolerance``: a table would silently smooth them away.
    """
    from station.compensation.check import check_segments

    problems = [p for p in check_segments(model, tolerance=tolerance) if p.severity != "note"]
    if problems:
        raise TableError("segments cannot become a table: " + "; ".join(p.message for p in problems))
    segs = model.sorted().segments
    position = np.array([segs[0].x_from] + [s.x_to for s in segs])
    # value at each breakpoint from the segment that starts there (the last from its end)
    y = np.array([s.value(s.x_from) for s in segs] + [segs[-1].value(segs[-1].x_to)], dtype=float)
    error = y if model.quantity == "error" else -y
    return CompensationTable.averaged(model.kind, position, error, backlash=0.0, source=model.source)


def table_to_segments(table: CompensationTable, direction: int = 0) -> SegmentModel:
    """One segment per neighbouring pair of table positions, for one approach direction.

    ``direction`` +1/−1 selects the up/down error (with an averaged table: the mean
    ± backlash/2); 0 the mean of both.  A segment list has a single value per position,
    so a bidirectional table needs one model per direction.
    """
    table.require_valid()
    x = table.position
    y = table.column_for(direction)
    slope = np.diff(y) / np.diff(x)
    intercept = y[:-1] - slope * x[:-1]
    segs = tuple(Segment(float(a), float(b), float(m), float(c))
                 for a, b, m, c in zip(x[:-1], x[1:], slope, intercept))
    return SegmentModel(segs, kind=table.kind, quantity="error", source=table.source)
