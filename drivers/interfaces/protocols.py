"""Small device protocols: what a caller needs of a device, one verb each.

In the manner of Bluesky's ``bluesky.protocols`` (``Movable``, ``Locatable``,
``Stoppable``, ``Readable``), written for our asynchronous axes: a route that shows
where an axis is needs only :class:`Locatable`, an abort needs only
:class:`Stoppable`, and a test double or another vendor's drive satisfies them by
having the methods, without inheriting from :class:`drivers.interfaces.ServoAxis`.
All are ``runtime_checkable``, so ``isinstance(ax, Stoppable)`` works (it checks that
the members exist, not their signatures).

The unit is data (:attr:`Movable.units`), not a class a caller has to know: "mm" for
a linear axis, "deg" for a rotary one.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal, Protocol, runtime_checkable

#: the units an axis moves in: mm (linear), deg (rotary)
Units = Literal["mm", "deg"]
#: every value :data:`Units` admits (for run-time checks)
UNITS: tuple[str, ...] = ("mm", "deg")


@dataclass(frozen=True)
class Location:
    """Where a movable device is: ``setpoint``, the last target commanded (None before
    the first move and after a stop, when the axis rests short of it by design), and
    ``readback``, where its own encoder says it is (both in the device's units)."""

    setpoint: float | None
    readback: float


@runtime_checkable
class Movable(Protocol):
    """A device sent to an absolute target in its ``units``."""

    #: "mm" or "deg"
    units: str

    async def move_to(self, position: float, velocity: float | None = None,
                      acceleration: float | None = None) -> None:
        """Start the move; returns once the device accepted it."""
        ...


@runtime_checkable
class Locatable(Protocol):
    """A device that says where it was sent and where it is."""

    @property
    def setpoint(self) -> float | None:
        """The last target commanded (None before a move and after a stop)."""
        ...

    async def locate(self) -> Location:
        """The setpoint and a fresh readback."""
        ...


@runtime_checkable
class Stoppable(Protocol):
    """A device whose motion can be stopped."""

    async def stop(self) -> None:
        ...


@runtime_checkable
class Readable(Protocol):
    """A device read on request: one snapshot (an axis' :class:`AxisStatus`, an
    encoder's :class:`EncoderReading`)."""

    name: str

    async def read(self) -> Any:
        ...
