"""Cycle time: what an inspection costs the machine, and the least the same plan could cost.

The engine writes a ledger of every step it carries out (a move started, a wait for
an axis, a settle, a frame, a vision call, the plan's own computing, a read), each
with its wall time and, for moves, where from, where to and at what speed.  Two
figures come from it (docs/inspection.md, Cycle time):

* **machine time**: on hardware, the wall time of the steps as measured.  Under a
  twin whose motion runs ``time_scale`` times faster than real time, the same ledger
  is replayed on a machine clock: each axis is busy for its move's trapezoid at the
  commanded speed and acceleration (:mod:`station.motion`, the profile the drive
  follows), a wait ends when its axis is done (plus half a status poll, on average,
  before the station sees it) and costs its measured overhead beyond that; a frame
  costs the real sensor's exposure and readout (the twin's rendering is not the
  camera's time); the rest (vision, reads, the plan's computing) is real software
  time, measured.
* **lower bound** of the same plan: the same frames at the same poses, reached by
  minimum-time moves of both axes at once under their velocity and acceleration
  limits, each arriving in the positive direction (the plan's backlash rule: past the
  target by the approach distance and back when it lies below), the settle after
  motion and, per pose, the exposures with the sensor's readout between frames.
  Vision and communication are taken as free (they could overlap the motion).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterable, Mapping

from drivers.interfaces import CameraTiming
from station.motion import AxisLimits, approach_time_s, move_time_s

#: ledger step kinds and the breakdown each one counts in
BREAKDOWN_OF = {"move": "moves_s", "wait": "moves_s", "settle": "settle_s", "frame": "frames_s",
                "vision": "vision_s", "plan": "other_s", "read": "other_s"}
BREAKDOWN_KEYS = ("moves_s", "settle_s", "frames_s", "vision_s", "other_s")


@dataclass(frozen=True)
class Step:
    """One step of a run as the engine carried it out.

    ``kind``: move (a move started: ``axis``, ``start``, ``target``, ``velocity``,
    ``acceleration``), wait (until ``axis`` is in position), settle (``seconds``),
    frame, vision, plan (the plan's own computing between messages), read."""

    kind: str
    wall_s: float
    axis: str | None = None
    start: float | None = None
    target: float | None = None
    velocity: float | None = None
    acceleration: float | None = None
    seconds: float | None = None

    def __post_init__(self):
        if self.kind not in BREAKDOWN_OF:
            raise ValueError(f"unknown ledger step kind {self.kind!r}")


@dataclass
class CycleLedger:
    """The steps of one run, in order."""

    steps: list[Step] = field(default_factory=list)

    def add(self, step: Step) -> None:
        self.steps.append(step)


@dataclass(frozen=True)
class CycleTime:
    """A time in s and how it divides (``BREAKDOWN_KEYS``); ``basis`` says how it
    was obtained: measured, modelled (replayed under a twin's time scale), bound."""

    total_s: float
    breakdown: Mapping[str, float]
    basis: str


def _profile_s(step: Step) -> float:
    """The drive's time for a started move (its trapezoid), 0 when not known."""
    if None in (step.start, step.target, step.velocity, step.acceleration):
        return 0.0
    if not (step.velocity > 0 and step.acceleration > 0):
        return 0.0
    return move_time_s(step.target - step.start, AxisLimits(step.velocity, step.acceleration))


def machine_time(steps: Iterable[Step], *, time_scale: float | None = None, camera: CameraTiming | None = None,
                 poll_s: Mapping[str, float] | None = None) -> CycleTime:
    """The machine time of a run from its ledger.

    ``time_scale`` None: the steps' wall times are the machine's (real hardware).
    Otherwise the motion ran that many times faster than real time: the ledger is
    replayed (module docstring). ``camera``: the real sensor's timing, which replaces
    a frame's wall time in a replay; ``poll_s``: each axis' status poll period."""
    steps = list(steps)
    br = {k: 0.0 for k in BREAKDOWN_KEYS}
    if time_scale is None:
        for st in steps:
            br[BREAKDOWN_OF[st.kind]] += st.wall_s
        return CycleTime(sum(br.values()), br, "measured")
    if not time_scale > 0:
        raise ValueError(f"time_scale must be positive, not {time_scale!r}")
    poll_s = poll_s or {}
    t = 0.0
    busy: dict[str, float] = {}
    for st in steps:
        if st.kind == "move":
            dt = st.wall_s
            busy[st.axis] = t + dt + _profile_s(st)
        elif st.kind == "wait":
            remaining = max(0.0, busy.get(st.axis, t) - t)
            # the wall time the twin's motion took is remaining / time_scale; the rest is
            # the link's overhead, which is as real here as on the machine
            overhead = max(0.0, st.wall_s - remaining / time_scale)
            # at real speed the station sees the end of a move at its next status poll,
            # half a period late on average; the wall time holds that part of it only
            # as far as the motion was not scaled away (all of it at time scale 1)
            seen_late = 0.5 * poll_s.get(st.axis, 0.0) * (1.0 - 1.0 / time_scale) if remaining > 0 else 0.0
            dt = remaining + seen_late + overhead
        elif st.kind == "frame":
            dt = camera.frame_s if camera is not None else st.wall_s
        elif st.kind == "settle":
            dt = st.seconds if st.seconds is not None else st.wall_s
        else:
            dt = st.wall_s
        t += dt
        br[BREAKDOWN_OF[st.kind]] += dt
    return CycleTime(t, br, "modelled")


def frame_poses(steps: Iterable[Step]) -> tuple[dict[str, float], list[tuple[dict[str, float], int]]]:
    """Where the axes started, and the poses (commanded positions) at which frames
    were taken, in order, with the number of frames at each; consecutive frames at
    one pose (whatever moved in between) are one entry."""
    steps = list(steps)
    start: dict[str, float] = {}
    for st in steps:
        if st.kind == "move" and st.axis not in start and st.start is not None:
            start[st.axis] = st.start
    at = dict(start)
    poses: list[tuple[dict[str, float], int]] = []
    for st in steps:
        if st.kind == "move" and st.target is not None:
            at[st.axis] = st.target
        elif st.kind == "frame":
            # back at the same pose (a move away and back): the same pose, no move needed
            if poses and poses[-1][0] == at:
                poses[-1] = (poses[-1][0], poses[-1][1] + 1)
            else:
                poses.append((dict(at), 1))
    return start, poses


def lower_bound(steps: Iterable[Step], *, limits: Mapping[str, AxisLimits], approach: Mapping[str, float],
                settle_s: float, camera: CameraTiming) -> CycleTime:
    """The least machine time of the same plan (module docstring): its frames at its
    poses, minimum-time moves of all axes at once, the settle after motion, exposures
    with the readout between frames."""
    start, poses = frame_poses(steps)
    br = {k: 0.0 for k in BREAKDOWN_KEYS}
    prev = dict(start)
    for pose, n in poses:
        t_move = 0.0
        for ax, q in pose.items():
            p = prev.get(ax, q)
            if q == p:
                continue
            if ax not in limits:
                raise ValueError(f"no motion limits for axis {ax!r}")
            t_move = max(t_move, approach_time_s(p, q, limits[ax], approach.get(ax, 0.0)))
        br["moves_s"] += t_move
        if t_move > 0:
            br["settle_s"] += settle_s
        # the camera must be still while it exposes; between two exposures the sensor
        # reads the first out (a global shutter overlaps the two where it can)
        br["frames_s"] += camera.exposure_s + (n - 1) * max(camera.exposure_s, camera.readout_s)
        prev = pose
    return CycleTime(sum(br.values()), br, "bound")


def cycle_summary(machine: CycleTime, bound: CycleTime | None) -> dict:
    """``{"machine_s", "lower_bound_s", "ratio", "breakdown"}`` (the bench's and the
    record's form)."""
    out = {"machine_s": machine.total_s, "basis": machine.basis,
           "breakdown": {k: machine.breakdown.get(k, 0.0) for k in BREAKDOWN_KEYS}}
    if bound is not None:
        out["lower_bound_s"] = bound.total_s
        # no bound (a plan without frames): no ratio; never NaN, which JSON cannot carry
        out["ratio"] = machine.total_s / bound.total_s if bound.total_s > 0 else None
        out["lower_bound_breakdown"] = {k: bound.breakdown.get(k, 0.0) for k in BREAKDOWN_KEYS}
    return out
