"""A trapezoidal point-to-point move: the profile a servo drive's trajectory generator follows.

Separate from the drive (ophyd-async's ``SimMotorMoveLogic`` idea): a small immutable
object that answers "where, how fast, finished?" for any time, so the drive's state is
just "which move, started when" and never needs a ticking background task.

One physics, three uses: the drive twin (``sim.servo.physics``) moves by it; the
sequencer sizes each move's timeout by it; the cycle-time accounting
(``station.sequencer.cycle``) turns a plan's moves into machine time and its lower
bound by it.  Rest to rest at the limits, the trapezoid is also the minimum-time move
(bang-bang in acceleration, capped in speed), so the same formula is the bound.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field


@dataclass(frozen=True)
class TrapezoidalMove:
    """Move from ``start`` to ``target`` (axis unit) with speed ``vmax`` and acceleration
    ``amax`` (unit/s, unit/s^2), beginning at time ``t0`` (s, the drive's clock).

    Accelerate at ``amax`` to ``vmax``, cruise, decelerate at ``amax``; when the distance
    is too short to reach ``vmax`` the profile is triangular.
    """

    start: float
    target: float
    vmax: float
    amax: float
    t0: float = 0.0
    t_accel: float = field(init=False)
    t_cruise: float = field(init=False)
    v_peak: float = field(init=False)

    def __post_init__(self):
        if self.vmax <= 0 or self.amax <= 0:
            raise ValueError("vmax and amax must be positive")
        distance = abs(self.target - self.start)
        t_acc = self.vmax / self.amax
        if self.amax * t_acc * t_acc >= distance:  # the two ramps alone cover the distance
            t_acc = math.sqrt(distance / self.amax)
            t_cruise = 0.0
        else:
            t_cruise = (distance - self.amax * t_acc * t_acc) / self.vmax
        object.__setattr__(self, "t_accel", t_acc)
        object.__setattr__(self, "t_cruise", t_cruise)
        object.__setattr__(self, "v_peak", self.amax * t_acc)

    @property
    def direction(self) -> int:
        """+1 towards larger positions, -1 towards smaller, 0 for a null move (effects' ``s``)."""
        return (self.target > self.start) - (self.target < self.start)

    @property
    def duration(self) -> float:
        return 2.0 * self.t_accel + self.t_cruise

    def _travelled(self, tau: float) -> tuple[float, float]:
        """Distance covered and speed, ``tau`` seconds after the start (both >= 0)."""
        ta, tc, a, vp = self.t_accel, self.t_cruise, self.amax, self.v_peak
        if tau <= 0.0:
            return 0.0, 0.0
        if tau < ta:
            return 0.5 * a * tau * tau, a * tau
        d_acc = 0.5 * a * ta * ta
        if tau < ta + tc:
            return d_acc + vp * (tau - ta), vp
        if tau < self.duration:
            td = tau - ta - tc
            return d_acc + vp * tc + vp * td - 0.5 * a * td * td, vp - a * td
        return abs(self.target - self.start), 0.0

    @property
    def t_end(self) -> float:
        return self.t0 + self.duration

    def position(self, t: float) -> float:
        if t >= self.t_end:
            return self.target  # exactly, not start + rounded distance
        d, _ = self._travelled(t - self.t0)
        return self.start + self.direction * d

    def velocity(self, t: float) -> float:
        _, v = self._travelled(t - self.t0)
        return self.direction * v

    def done(self, t: float) -> bool:
        return t >= self.t_end

    def time_at_distance_from(self, point: float, distance: float, t_from: float) -> float | None:
        """First time after ``t_from`` the profile is ``distance`` away from ``point`` (bisection),
        or None if it never is; ``point`` must lie on the path behind the profile at ``t_from``.

        Used for "when did the following error exceed its limit" on a jammed axis.
        """
        f = lambda t: abs(self.position(t) - point) - distance  # noqa: E731
        lo, hi = max(self.t0, t_from), self.t0 + self.duration
        if hi < lo or f(hi) < 0:
            return None
        if f(lo) >= 0:
            return lo
        for _ in range(60):  # 2^-60 of a move's duration: far below any clock resolution
            mid = 0.5 * (lo + hi)
            if f(mid) >= 0:
                hi = mid
            else:
                lo = mid
        return hi


@dataclass(frozen=True)
class AxisLimits:
    """How fast an axis may move (its unit per s and per s^2): the velocity and
    acceleration the station commands and the minimum-time bound assumes."""

    velocity: float
    acceleration: float

    def __post_init__(self):
        for name in ("velocity", "acceleration"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"axis {name} limit must be a positive number, not {v!r}")


def move_time_s(distance: float, limits: AxisLimits) -> float:
    """Duration of a rest-to-rest move of ``distance`` (axis unit) at ``limits``: the
    trapezoid (triangle when short), which is also the minimum time for that move."""
    if distance == 0:
        return 0.0
    return TrapezoidalMove(0.0, abs(float(distance)), limits.velocity, limits.acceleration).duration


def approach_time_s(start: float, target: float, limits: AxisLimits, approach: float) -> float:
    """Minimum time to arrive at ``target`` moving in the positive direction (the
    unidirectional approach that takes up backlash the same way every time): straight
    there when ``target`` is above ``start``; else past it by ``approach`` and back up,
    two rest-to-rest moves (the reversal stops the axis in between)."""
    d = target - start
    if d >= 0:
        return move_time_s(d, limits)
    return move_time_s(-d + approach, limits) + move_time_s(approach, limits)
