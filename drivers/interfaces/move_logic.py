"""The logic of one point-to-point move, apart from the device that makes it.

ophyd-async's ``StandardMovable`` leaves the device generic and gives the
per-device decisions to a small ``MovableLogic``: is this move valid, how long may it
take. :class:`MoveLogic` is that object for our servo axes; ``ServoAxis.set`` (move
and wait) asks it, and so may any caller that moves an axis on its own (a bench, a
check, a test).

The sequencer's engine keeps its own policy (``station.sequencer.engine.Timeouts``
over ``station.motion.move_time_s``, the station's one trapezoid): ``drivers`` may not
import ``station``, so the rest-to-rest time is written here again in its closed
form, and ``tests/unit/test_axis_interfaces.py`` checks that the two agree. The
defaults below are the engine's (twice the profile time plus 5 s, at most 60 s).
"""

from __future__ import annotations

import math
from dataclasses import dataclass


def _positive(value: float | None) -> bool:
    return isinstance(value, (int, float)) and math.isfinite(value) and value > 0


@dataclass(frozen=True)
class MoveLogic:
    """What an axis knows about its moves (its units per s and per s^2).

    ``default_velocity``/``default_acceleration``: the profile of a move that names
    none (None: the drive's own, unknown here); ``velocity_limit``/``acceleration_limit``:
    the most the station may command (None: not stated)."""

    default_velocity: float | None = None
    default_acceleration: float | None = None
    velocity_limit: float | None = None
    acceleration_limit: float | None = None
    #: a move's timeout is ``timeout_factor`` x its profile time + ``timeout_margin_s``
    #: (a loaded link, the drive's settling), never more than ``fallback_timeout_s``,
    #: which is also the timeout of a move whose profile is not known
    timeout_factor: float = 2.0
    timeout_margin_s: float = 5.0
    fallback_timeout_s: float = 60.0

    def profile(self, velocity: float | None = None,
                acceleration: float | None = None) -> tuple[float | None, float | None]:
        """The velocity and acceleration a move will run at: the given ones, else the defaults."""
        v = self.default_velocity if velocity is None else float(velocity)
        a = self.default_acceleration if acceleration is None else float(acceleration)
        return v, a

    def check_move(self, target: float, velocity: float | None = None,
                   acceleration: float | None = None) -> None:
        """Raise ``ValueError`` for a move no axis should be sent: a target that is not
        a finite number, a speed that is not positive or beyond the limits."""
        if not (isinstance(target, (int, float)) and math.isfinite(target)):
            raise ValueError(f"move target must be a finite number, not {target!r}")
        v, a = self.profile(velocity, acceleration)
        for what, value, limit in (("velocity", v, self.velocity_limit),
                                   ("acceleration", a, self.acceleration_limit)):
            if value is None:
                continue
            if not _positive(value):
                raise ValueError(f"move {what} must be positive, not {value!r}")
            if limit is not None and value > limit:
                raise ValueError(f"move {what} {value:g} exceeds the axis' limit {limit:g}")

    @staticmethod
    def duration_s(distance: float, velocity: float, acceleration: float) -> float:
        """Rest-to-rest time of a move of ``distance`` at ``velocity``, ``acceleration``:
        the trapezoid (accelerate, cruise, decelerate), a triangle when the ramps alone
        cover the distance (below v^2/a)."""
        d = abs(float(distance))
        if d == 0.0:
            return 0.0
        if not (_positive(velocity) and _positive(acceleration)):
            raise ValueError("velocity and acceleration must be positive")
        if d <= velocity * velocity / acceleration:
            return 2.0 * math.sqrt(d / acceleration)
        return d / velocity + velocity / acceleration

    def timeout_s(self, distance: float | None, velocity: float | None = None,
                  acceleration: float | None = None) -> float:
        """How long to wait for a move of ``distance`` (None: not known) at the given
        profile (None: the defaults)."""
        v, a = self.profile(velocity, acceleration)
        if distance is None or not (_positive(v) and _positive(a)):
            return self.fallback_timeout_s
        expected = self.duration_s(distance, v, a)
        return min(self.fallback_timeout_s, self.timeout_factor * expected + self.timeout_margin_s)
