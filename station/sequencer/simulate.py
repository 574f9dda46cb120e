"""Plans checked without hardware: drive a plan by answering its messages from a
scripted world, and record what it asked for (in the manner of Bluesky's
``simulators.py``: ``summarize_plan``, ``check_limits``; our own code).

No engine, no event loop, no driver: a plan is a generator of
:mod:`station.sequencer.messages`, so :func:`summarize_plan` sends it the answers a
:class:`SimWorld` gives -- axes that reach their targets at once, a grating that reads
Z where it is, a camera that returns a small synthetic image, a vision stage that
reports what the test's ``measure(pose)`` says is seen at the pose the frame was
taken at -- and records every move (from where, to where, which way it arrived), wait,
settle, frame (the pose, whether an axis was still moving, whether it had settled),
note, checkpoint and progress, and the plan's return value.

:func:`check_limits` runs the same and refuses a plan that commands an axis outside
its travel, naming each offending move; call it before a new or changed plan meets
the machine (the drive's own soft limits fault the axis *after* the move was sent).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import Any, Callable, Generator, Mapping

import numpy as np

from drivers.interfaces import EncoderReading, EncoderStatus, Frame
from station.sequencer import messages as m


@dataclass(frozen=True)
class MoveRecord:
    """One Move message: ``index`` is its place among all the plan's messages."""

    index: int
    axis: str
    start: float
    target: float
    wait: bool
    velocity: float | None
    acceleration: float | None

    @property
    def direction(self) -> int:
        """+1 moving positive, -1 negative, 0 a move to where the axis already is."""
        return (self.target > self.start) - (self.target < self.start)


@dataclass(frozen=True)
class FrameRecord:
    """One Capture: the axes' positions, the axes whose moves were not yet collected by
    a Wait, whether a Settle came after the last move, the direction each axis last
    arrived in (+1/-1; absent: not moved in this plan), the last checkpoint's label."""

    index: int
    pose: Mapping[str, float]
    moving: tuple[str, ...]
    settled: bool
    arrived: Mapping[str, int]
    label: str


@dataclass
class PlanSummary:
    messages: list[m.Msg] = field(default_factory=list)
    moves: list[MoveRecord] = field(default_factory=list)
    frames: list[FrameRecord] = field(default_factory=list)
    waits: list[tuple[str, ...]] = field(default_factory=list)
    settles_s: list[float] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    checkpoints: list[str] = field(default_factory=list)
    progress: list[tuple[int, int, str]] = field(default_factory=list)
    encoder_reads: int = 0
    #: the plan's return value
    result: Any = None

    def moves_of(self, axis: str) -> list[MoveRecord]:
        return [mv for mv in self.moves if mv.axis == axis]

    def span(self, axis: str) -> tuple[float, float] | None:
        """Lowest and highest position ``axis`` was commanded to (None: never moved)."""
        targets = [mv.target for mv in self.moves_of(axis)]
        return (min(targets), max(targets)) if targets else None

    def describe(self) -> str:
        """A short human-readable account (for a test's failure message or a CLI)."""
        lines = [f"{len(self.messages)} messages: {len(self.moves)} moves, {len(self.frames)} frames, "
                 f"{len(self.waits)} waits, {len(self.settles_s)} settles, {self.encoder_reads} grating reads"]
        for axis in sorted({mv.axis for mv in self.moves}):
            lo, hi = self.span(axis)
            lines.append(f"  {axis}: {len(self.moves_of(axis))} moves within {lo:.4f} .. {hi:.4f}")
        return "\n".join(lines)


class SimWorld:
    """The fake world a simulated plan meets.

    ``start``: where the axes are (default 0). ``measure(pose)``: what the vision stage
    reports for a frame taken at ``pose`` (a dict of axis positions); default nothing.
    ``read_encoder(pose)``: the grating's reading (default: Z exactly). Axes reach a
    move's target at once; the frames are small synthetic images (``image_shape``)."""

    def __init__(self, start: Mapping[str, float] | None = None, *,
                 measure: Callable[[Mapping[str, float]], Any] | None = None,
                 read_encoder: Callable[[Mapping[str, float]], Any] | None = None,
                 image_shape: tuple[int, int] = (8, 8)):
        self.position: dict[str, float] = {"Z": 0.0, "C": 0.0, **dict(start or {})}
        self._measure = measure
        self._read_encoder = read_encoder
        self.image_shape = image_shape
        self._sequence = itertools.count(1)
        #: the pose each synthetic image was taken at, by the image's identity
        self._pose_of_image: dict[int, tuple[np.ndarray, dict[str, float]]] = {}

    def move(self, axis: str, position: float) -> None:
        self.position[axis] = float(position)

    def encoder(self) -> Any:
        pose = dict(self.position)
        if self._read_encoder is not None:
            return self._read_encoder(pose)
        return EncoderReading(pose.get("Z", 0.0), 0.0, EncoderStatus(True, False, False, False))

    def capture(self) -> Frame:
        seq = next(self._sequence)
        image = np.full(self.image_shape, seq % 256, dtype=np.uint8)
        self._pose_of_image[id(image)] = (image, dict(self.position))  # the image kept: ids stay unique
        return Frame(image=image, timestamp=float(seq), sequence=seq)

    def measure(self, image: Any) -> Any:
        known = self._pose_of_image.get(id(image))
        if known is None:
            raise ValueError("Measure of an image this world did not capture")
        return [] if self._measure is None else self._measure(dict(known[1]))

    def measure_surface(self, image: Any, blur_px: float | None = None, hole_places=None) -> Any:
        """The defects of a captured frame: none (a plan's world has a clean wall).
        ``blur_px``, ``hole_places``: what the plan gives the detection (not used here)."""
        if self._pose_of_image.get(id(image)) is None:
            raise ValueError("MeasureSurface of an image this world did not capture")
        return []


def summarize_plan(plan: Generator[m.Msg, Any, Any], world: SimWorld | None = None, *,
                   max_messages: int = 1_000_000) -> PlanSummary:
    """Run ``plan`` to its end against ``world`` (default: a :class:`SimWorld` at 0)
    and return what it did.  An exception of the plan propagates, as it would fault
    the engine; a message of an unknown kind is a TypeError, as in the engine."""
    world = world or SimWorld()
    out = PlanSummary()
    pending: set[str] = set()  # axes whose moves no Wait has collected yet
    settled = True
    arrived: dict[str, int] = {}
    label = ""
    answer: Any = None
    for index in itertools.count():
        if index >= max_messages:
            plan.close()
            raise RuntimeError(f"plan still running after {max_messages} messages")
        try:
            msg = plan.send(answer)
        except StopIteration as done:
            out.result = done.value
            return out
        out.messages.append(msg)
        answer = None
        if isinstance(msg, m.Move):
            start = world.position.get(msg.axis, 0.0)
            rec = MoveRecord(index, msg.axis, start, float(msg.position), msg.wait, msg.velocity, msg.acceleration)
            out.moves.append(rec)
            world.move(msg.axis, msg.position)
            if rec.direction:
                arrived[msg.axis] = rec.direction
            if msg.wait:
                pending.discard(msg.axis)
            else:
                pending.add(msg.axis)
            settled = False
        elif isinstance(msg, m.Wait):
            axes = tuple(msg.axes) or tuple(sorted(pending))
            out.waits.append(axes)
            pending.difference_update(axes)
        elif isinstance(msg, m.Settle):
            out.settles_s.append(float(msg.seconds))
            settled = True
        elif isinstance(msg, m.ReadAxis):
            answer = world.position.get(msg.axis, 0.0)
        elif isinstance(msg, m.ReadEncoder):
            out.encoder_reads += 1
            answer = world.encoder()
        elif isinstance(msg, m.Capture):
            out.frames.append(FrameRecord(index, dict(world.position), tuple(sorted(pending)), settled,
                                          dict(arrived), label))
            answer = world.capture()
        elif isinstance(msg, m.Measure):
            answer = world.measure(msg.image)
        elif isinstance(msg, m.MeasureSurface):
            answer = world.measure_surface(msg.image, blur_px=msg.blur_px, hole_places=msg.hole_places)
        elif isinstance(msg, m.Checkpoint):
            label = msg.label
            out.checkpoints.append(msg.label)
        elif isinstance(msg, m.Progress):
            out.progress.append((msg.done, msg.total, msg.text))
        elif isinstance(msg, m.Note):
            out.notes.append(msg.text)
        elif isinstance(msg, (m.Emit, m.Enable, m.Home)):
            pass  # a document for the plan's owner, or homing: nothing the world answers
        else:
            plan.close()
            raise TypeError(f"unknown message {msg!r}")
    raise AssertionError("unreachable")


@dataclass(frozen=True)
class LimitViolation:
    move: MoveRecord
    low: float
    high: float

    def __str__(self) -> str:
        return (f"message {self.move.index}: {self.move.axis} to {self.move.target:.4f}, "
                f"outside its travel {self.low:g} .. {self.high:g}")


class PlanOutOfLimits(ValueError):
    """A plan commands an axis outside its travel; ``violations`` names each move."""

    def __init__(self, violations: list[LimitViolation], summary: PlanSummary):
        shown = "; ".join(str(v) for v in violations[:5])
        more = f" (and {len(violations) - 5} more)" if len(violations) > 5 else ""
        super().__init__(f"{len(violations)} move(s) outside the travel: {shown}{more}")
        self.violations = violations
        self.summary = summary


def check_limits(plan: Generator[m.Msg, Any, Any], limits: Mapping[str, tuple[float, float]],
                 world: SimWorld | None = None) -> PlanSummary:
    """Run ``plan`` as :func:`summarize_plan` does and refuse it (:class:`PlanOutOfLimits`)
    if any move of an axis named in ``limits`` (``{"Z": (lo, hi)}``, the axis' unit) goes
    outside ``lo .. hi`` or is not a finite number. Axes not named (the endless C table)
    are not checked. Returns the summary of a plan within its limits."""
    summary = summarize_plan(plan, world)
    bad = []
    for mv in summary.moves:
        if mv.axis not in limits:
            continue
        lo, hi = limits[mv.axis]
        if not (math.isfinite(mv.target) and lo <= mv.target <= hi):
            bad.append(LimitViolation(mv, lo, hi))
    if bad:
        raise PlanOutOfLimits(bad, summary)
    return summary
