"""The small steps a plan yields, Bluesky-style.

A plan is a generator: it yields one message at a time, the engine carries it out
and sends the result back (``result = yield Move(...)``). Plans hold no device
handles and do no I/O of their own, so the engine alone decides about pausing,
aborting, retrying and faults, and a plan can be tested by feeding it results.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Msg:
    """Base of all messages."""

    #: retried on a transient driver error (the step is idempotent)
    retryable = True


@dataclass(frozen=True)
class Move(Msg):
    """Absolute move of one axis ("Z" mm or "C" deg); returns when the move is
    started. ``wait`` also waits until it is in position (the common case); without
    it the move runs on while the plan goes on (both axes at once), and a
    :class:`Wait` collects it. ``velocity``/``acceleration``: the axis' defaults when
    None."""

    axis: str
    position: float
    wait: bool = True
    velocity: float | None = None
    acceleration: float | None = None


@dataclass(frozen=True)
class Wait(Msg):
    """Wait until each of ``axes`` has finished the move it was last given (all
    axes with a move under way when empty)."""

    axes: tuple[str, ...] = ()


@dataclass(frozen=True)
class Settle(Msg):
    """Let vibration die out after a move (seconds of the station's clock)."""

    seconds: float


@dataclass(frozen=True)
class ReadEncoder(Msg):
    """The grating's reading of Z (an ``EncoderReading``)."""


@dataclass(frozen=True)
class ReadAxis(Msg):
    """A drive's reported position of ``axis``."""

    axis: str


@dataclass(frozen=True)
class Capture(Msg):
    """One camera frame (a ``drivers.interfaces.Frame``)."""


@dataclass(frozen=True)
class Measure(Msg):
    """Run the vision stage on a frame's image; returns its hole measurements."""

    image: Any


@dataclass(frozen=True)
class MeasureSurface(Msg):
    """Run the surface inspection on a frame's image; returns its defects
    (``station.vision.defects.Defect``, image px and mm). ``blur_px``: the camera's blur
    (Gaussian sigma, px) as the bore scan read it at the holes' edges; None: the frame's
    defect detection reads it itself (from a hole in the frame, else each mark's own).
    ``hole_places``: where the part's holes may show in the frame, as (x_px, y_px,
    reach_px) each (the bore scan found them); a dark disc at none of them is a mark of
    the wall (a large pore), not a hole. None: every dark disc of a hole's size is a hole."""

    image: Any
    blur_px: float | None = None
    hole_places: tuple[tuple[float, float, float], ...] | None = None


@dataclass(frozen=True)
class Checkpoint(Msg):
    """A place where a pause or a controlled stop may take effect."""

    label: str = ""


@dataclass(frozen=True)
class Progress(Msg):
    """Tell the world how far the plan is (``done`` of ``total`` steps)."""

    done: int
    total: int
    text: str = ""


@dataclass(frozen=True)
class Note(Msg):
    """Something worth recording in the event log."""

    text: str


@dataclass(frozen=True)
class Enable(Msg):
    """Enable (or disable) an axis' drive."""

    axis: str
    on: bool = True


@dataclass(frozen=True)
class Home(Msg):
    """Start an axis' homing (its reference run); a :class:`Wait` collects it."""

    axis: str


@dataclass(frozen=True)
class Emit(Msg):
    """Hand something the plan observed (``name``, ``body``: a frame's observation) to
    the plan's owner, which registers a command for it (the inspection service turns
    frames into documents); without one the engine only notes the event."""

    name: str
    body: Any = None
    retryable = False
