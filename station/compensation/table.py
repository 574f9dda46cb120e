"""Compensation tables: the positioning ERROR of one axis against commanded position.

Why store the error and not the correction: the error is what was measured
(ISO 230-2 deviation = actual − commanded, um or arcsec) and what the effect
vocabulary and discovery speak about; the correction is only its negative.  Keeping
one quantity in the files avoids the classic sign slip between "table of errors" and
"table of corrections".  :meth:`CompensationTable.error_at` gives the error,
:meth:`CompensationTable.correction_at` the amount to ADD to the command
(``correction = −error``).

Two shapes, as controllers offer them:

* **bidirectional**: one error column per approach direction (``error_up`` for
  ``+1``, moving towards larger positions; ``error_down`` for ``−1``);
* **averaged**: one column ``error_mean`` plus a ``backlash`` value ``b`` in deviation
  units, the ISO 230-2 mean reversal B̄: the error approaching in direction ``s`` is
  ``error_mean + s·b/2`` -- the contract's ``backlash`` effect, so ``b`` means the
  same thing everywhere in the station.

Interpolation is linear between positions.  A linear axis holds the end values flat
outside the table; a rotary axis is periodic: positions are taken modulo 360° and
the last entry joins the first + 360°.

A table is built as given (a file may be unsorted or hold NaN); :func:`check`
(``station.compensation.check``) names such problems, and the interpolators refuse a
table that has them rather than interpolate nonsense.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: one turn of a rotary axis, in its position unit (degrees)
FULL_TURN_DEG = 360.0

#: deviation and position units per axis kind (contract ``discovery.md``)
ERROR_UNIT = {"linear": "um", "rotary": "arcsec"}
POSITION_UNIT = {"linear": "mm", "rotary": "deg"}

MODES = ("bidirectional", "averaged")


class TableError(ValueError):
    """A table that cannot be used as it is; the message lists the problems."""


@dataclass(frozen=True, eq=False)
class CompensationTable:
    """Error of one axis at a list of commanded positions.

    Positions in mm (linear) or degrees (rotary); errors in um or arcsec.
    Exactly one of the shapes is filled: ``error_up`` and ``error_down``
    (bidirectional) or ``error_mean`` (averaged, with ``backlash``).
    """

    kind: str
    position: np.ndarray
    error_up: np.ndarray | None = None
    error_down: np.ndarray | None = None
    error_mean: np.ndarray | None = None
    backlash: float = 0.0
    axis: str = ""
    #: 1-based source line of each row when read from a file (for messages)
    line: np.ndarray | None = None
    source: str = "<memory>"
    notes: tuple[str, ...] = field(default=())

    def __post_init__(self) -> None:
        if self.kind not in ERROR_UNIT:
            raise ValueError(f"axis kind must be 'linear' or 'rotary', not {self.kind!r}")
        as_array = lambda a: None if a is None else np.atleast_1d(np.asarray(a, dtype=float))  # noqa: E731
        object.__setattr__(self, "position", as_array(self.position))
        for name in ("error_up", "error_down", "error_mean"):
            object.__setattr__(self, name, as_array(getattr(self, name)))
        object.__setattr__(self, "backlash", float(self.backlash))
        bidirectional = self.error_up is not None or self.error_down is not None
        if bidirectional == (self.error_mean is not None):
            raise ValueError("give either error_up and error_down (bidirectional) or error_mean (averaged)")
        if bidirectional and (self.error_up is None or self.error_down is None):
            raise ValueError("a bidirectional table needs both error_up and error_down")
        if bidirectional and self.backlash != 0.0:
            raise ValueError("a bidirectional table carries its reversal in its two columns; backlash must be 0")
        for name in self.columns:
            if getattr(self, name).shape != self.position.shape:
                raise ValueError(f"{name} has {getattr(self, name).size} values for {self.position.size} positions")

    # ------------------------------------------------------------------ shape

    @classmethod
    def bidirectional(cls, kind, position, error_up, error_down, **kw) -> "CompensationTable":
        return cls(kind=kind, position=position, error_up=error_up, error_down=error_down, **kw)

    @classmethod
    def averaged(cls, kind, position, error_mean, backlash=0.0, **kw) -> "CompensationTable":
        return cls(kind=kind, position=position, error_mean=error_mean, backlash=backlash, **kw)

    @property
    def mode(self) -> str:
        return "averaged" if self.error_mean is not None else "bidirectional"

    @property
    def columns(self) -> tuple[str, ...]:
        """Names of the error columns this table carries."""
        return ("error_mean",) if self.mode == "averaged" else ("error_up", "error_down")

    @property
    def error_unit(self) -> str:
        return ERROR_UNIT[self.kind]

    @property
    def position_unit(self) -> str:
        return POSITION_UNIT[self.kind]

    def __len__(self) -> int:
        return int(self.position.size)

    def column_for(self, direction: int) -> np.ndarray:
        """The error at the table positions for one approach direction (+1, −1 or 0 = mean)."""
        if self.mode == "averaged":
            return self.error_mean + np.sign(direction) * self.backlash / 2.0
        if direction > 0:
            return self.error_up
        if direction < 0:
            return self.error_down
        return 0.5 * (self.error_up + self.error_down)

    def equals(self, other: "CompensationTable") -> bool:
        """Same kind, shape and exactly the same numbers (for round-trip checks)."""
        if not isinstance(other, CompensationTable) or (self.kind, self.mode) != (other.kind, other.mode):
            return False
        if self.backlash != other.backlash or not np.array_equal(self.position, other.position):
            return False
        return all(np.array_equal(getattr(self, c), getattr(other, c)) for c in self.columns)

    # ------------------------------------------------------------ evaluation

    def require_valid(self) -> None:
        from station.compensation.check import check_table  # local: check imports this module

        errors = [p for p in check_table(self) if p.severity == "error"]
        if errors:
            raise TableError("table cannot be interpolated: " + "; ".join(p.message for p in errors))

    def _interp(self, x: np.ndarray, values: np.ndarray) -> np.ndarray:
        pos = self.position
        if self.kind == "linear":
            return np.interp(x, pos, values)  # np.interp holds the end values flat
        # rotary: periodic with one turn.  Bring x into [pos0, pos0 + 360) and close the
        # table with the first entry one turn later (unless the table already ends there).
        x_wrapped = pos[0] + np.mod(x - pos[0], FULL_TURN_DEG)
        if pos[-1] - pos[0] < FULL_TURN_DEG:
            pos = np.append(pos, pos[0] + FULL_TURN_DEG)
            values = np.append(values, values[0])
        return np.interp(x_wrapped, pos, values)

    def error_at(self, x, direction=0) -> np.ndarray:
        """Error (actual − commanded, um or arcsec) at commanded position(s) ``x``.

        ``direction`` (scalar or array like ``x``): +1 approaching upwards, −1
        downwards, 0 unknown (the mean of both directions).
        """
        self.require_valid()
        x = np.asarray(x, dtype=float)
        direction = np.broadcast_to(np.sign(np.asarray(direction, dtype=float)), x.shape)
        if self.mode == "averaged":
            return self._interp(x, self.error_mean) + direction * self.backlash / 2.0
        up = self._interp(x, self.error_up)
        down = self._interp(x, self.error_down)
        return np.where(direction > 0, up, np.where(direction < 0, down, 0.5 * (up + down)))

    def correction_at(self, x, direction=0) -> np.ndarray:
        """Correction to ADD to the command at ``x`` (um or arcsec): ``−error_at(x)``.

        To first order: commanding ``x + c`` with ``c = −e(x)`` brings the axis to
        ``x + c + e(x + c) ≈ x``; the error varies slowly enough over ``c`` (micrometres)
        for the second-order term to be far below the table's own uncertainty.
        """
        return -self.error_at(x, direction)
