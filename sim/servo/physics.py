"""A servo drive's behaviour, without any protocol: enable, move, stop, home, faults, watchdog.

The protocol face (``sim.servo.modbus_face``) turns register reads and writes into calls
on this object; the world (the lead's error model) reads the *true* carriage position
from it.  Two positions exist on purpose:

* ``motor_position`` -- what the drive's own motor encoder measures and reports in its
  ACTUAL_POSITION register: the commanded trajectory (unless the axis is jammed);
* ``carriage_position`` -- where the carriage really is: motor position plus the
  geometric error of the axis, ``actual_offset(motor_position, direction, t)``.  This
  is what the grating encoder twin reads and what the camera twin should look from.

The state is evaluated lazily at the time of each query (no ticking task): the drive is
a pure function of "what was commanded when", which keeps it deterministic under a
time scale and a test clock.

Simplification (said here so nobody relies on it): on a fault the axis stops where it
is at that instant instead of decelerating on a quick-stop ramp.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass
from typing import Callable

from drivers.interfaces.register_map import FaultCode
from station.motion import TrapezoidalMove
from station.effects import ErrorCurve, k_for_kind

#: ``actual_offset(motor_position, direction, time_s) -> deviation`` in the axis unit (mm or deg)
OffsetHook = Callable[[float, int, float], float]


def zero_offset(motor_position: float, direction: int, time_s: float) -> float:
    """The default world: the carriage is exactly where the motor says."""
    return 0.0


def offset_from_curve(curve: ErrorCurve) -> OffsetHook:
    """An ``actual_offset`` hook from a ``station.effects.ErrorCurve`` (deviation in um or
    arcsec, converted to mm or deg by the contract's ``k``): the simplest world, one
    axis' positioning error.  The lead's world may compose richer hooks the same way.
    """
    k = k_for_kind(curve.kind)  # um per mm or arcsec per deg

    def hook(motor_position: float, direction: int, time_s: float) -> float:
        return float(curve.evaluate([motor_position], direction=[direction], time_s=[time_s])[0]) / k

    return hook


@dataclass
class ServoAxisConfig:
    """The drive's parameters (axis units: mm or deg; times in s)."""

    name: str = "Z"
    kind: str = "linear"  #: "linear" (mm) or "rotary" (deg)
    max_velocity: float = 50.0  #: unit/s, clamps the profile velocity
    max_acceleration: float = 500.0  #: unit/s^2
    default_velocity: float = 20.0  #: used when the master writes 0
    default_acceleration: float = 200.0
    homing_velocity: float = 10.0
    min_position: float | None = None  #: soft limits (None: unlimited, e.g. a rotary table)
    max_position: float | None = None
    following_error_limit: float = 0.5  #: unit; beyond it a jammed axis faults
    in_position_window: float = 0.0002  #: unit; |position - target| for IN_POSITION
    initial_position: float = 0.0  #: motor position at power-on (before homing)
    home_position: float = 0.0  #: position of the reference mark


@dataclass(frozen=True)
class DriveSnapshot:
    """Everything the status registers show, at one instant."""

    time_s: float
    motor_position: float
    velocity: float
    target: float
    enabled: bool
    moving: bool
    in_position: bool
    homed: bool
    fault_code: int
    estop: bool

    @property
    def fault(self) -> bool:
        return self.fault_code != FaultCode.NONE

    @property
    def ready(self) -> bool:
        return not self.fault and not self.estop


class ServoAxisPhysics:
    """One servo axis: commanded state, trajectory, homing, faults, watchdog.

    ``time_scale`` > 1 makes moves run faster than real time (for demos and tests);
    the communication watchdog always runs on real time, since it guards a real link.
    ``clock`` is injectable so tests can drive time by hand.
    """

    def __init__(
        self,
        config: ServoAxisConfig | None = None,
        *,
        time_scale: float = 1.0,
        clock: Callable[[], float] = time.monotonic,
        actual_offset: OffsetHook = zero_offset,
    ):
        if time_scale <= 0:
            raise ValueError("time_scale must be positive")
        self.config = config or ServoAxisConfig()
        self.time_scale = float(time_scale)
        self._clock = clock
        self._t0_real = clock()
        #: the world's hook: deviation of the carriage from the motor position (axis unit)
        self.actual_offset: OffsetHook = actual_offset
        #: called as fn(target, direction, time_s) when a move (or homing) starts: the
        #: world draws the approach's repeatability error there, once per approach
        self.move_listeners: list[Callable[[float, int, float], None]] = []
        self._lock = threading.RLock()
        self._enabled = False
        self._homed = False
        self._homing = False
        self._fault_code = int(FaultCode.NONE)
        self._estop = False
        self._move: TrapezoidalMove | None = None
        self._rest = float(self.config.initial_position)
        self._target = self._rest
        self._direction = 0
        self._stuck_at: float | None = None  # motor position the jam froze, or None
        self._stuck_since_s = 0.0
        self._watchdog_timeout_s = 0.0
        self._last_heartbeat_real = self._t0_real

    # ------------------------------------------------------------------ time

    def now(self) -> float:
        """The drive's time in s since power-on (scaled)."""
        return (self._clock() - self._t0_real) * self.time_scale

    def _sim_time_of_real(self, real: float) -> float:
        return (real - self._t0_real) * self.time_scale

    # ------------------------------------------------------------------ lazy evolution

    def _trajectory(self, t: float) -> float:
        return self._move.position(t) if self._move is not None else self._rest

    def _freeze(self, t: float, position: float | None = None) -> None:
        self._rest = self._trajectory(t) if position is None else position
        self._move = None
        self._homing = False

    def _fault(self, code: int, t: float, position: float | None = None) -> None:
        self._freeze(t, position)
        self._fault_code = int(code)
        self._enabled = False

    def _advance(self, t: float) -> None:
        """Apply everything that happened up to ``t``: watchdog, jam, end of move."""
        if self._enabled and self._watchdog_timeout_s > 0:
            expiry_real = self._last_heartbeat_real + self._watchdog_timeout_s
            if self._clock() > expiry_real:
                t_exp = min(t, max(self._sim_time_of_real(expiry_real), 0.0))
                self._fault(FaultCode.WATCHDOG_EXPIRED, t_exp, self._motor_at(t_exp))
        if self._move is not None and self._stuck_at is not None:
            t_fe = self._move.time_at_distance_from(
                self._stuck_at, self.config.following_error_limit, self._stuck_since_s
            )
            if t_fe is not None and t_fe <= t:
                self._fault(FaultCode.FOLLOWING_ERROR, t_fe, self._stuck_at)
        if self._move is not None and self._move.done(t):
            self._rest = self._move.target
            self._move = None
            if self._homing:
                self._homing = False
                self._homed = True
                # the count is set at the mark (a rotary table's mark repeats every turn)
                self._rest = self._target = float(self.config.home_position)

    def _motor_at(self, t: float) -> float:
        if self._stuck_at is not None:
            return self._stuck_at
        return self._trajectory(t)

    # ------------------------------------------------------------------ queries

    def motor_position(self, t: float | None = None) -> float:
        """What the drive's motor encoder reports (axis unit)."""
        with self._lock:
            t = self.now() if t is None else t
            self._advance(t)
            return self._motor_at(t)

    @property
    def direction(self) -> int:
        """Direction of the last move (+1, -1; 0 before any move): the effects' ``s``."""
        return self._direction

    def carriage_position(self, t: float | None = None) -> float:
        """The TRUE carriage position: motor position + the world's ``actual_offset``."""
        with self._lock:
            t = self.now() if t is None else t
            motor = self.motor_position(t)
            direction = self._direction
        return motor + float(self.actual_offset(motor, direction, t))

    def snapshot(self, t: float | None = None) -> DriveSnapshot:
        with self._lock:
            t = self.now() if t is None else t
            self._advance(t)
            motor = self._motor_at(t)
            moving = self._move is not None
            velocity = 0.0 if (not moving or self._stuck_at is not None) else self._move.velocity(t)
            in_position = (
                self._enabled and not moving and abs(motor - self._target) <= self.config.in_position_window
            )
            return DriveSnapshot(
                time_s=t,
                motor_position=motor,
                velocity=velocity,
                target=self._target,
                enabled=self._enabled,
                moving=moving,
                in_position=in_position,
                homed=self._homed,
                fault_code=self._fault_code,
                estop=self._estop,
            )

    # ------------------------------------------------------------------ commands

    def enable(self, on: bool) -> None:
        with self._lock:
            t = self.now()
            self._advance(t)
            if on and (self._fault_code or self._estop):
                return  # a faulted drive cannot be enabled: reset the fault first
            if on and not self._enabled:
                self._last_heartbeat_real = self._clock()  # the watchdog counts from enabling
            if not on and self._enabled:
                self._freeze(t, self._motor_at(t))
            self._enabled = bool(on)

    def _start(self, target: float, velocity: float, acceleration: float, t: float) -> None:
        c = self.config
        v = min(velocity if velocity > 0 else c.default_velocity, c.max_velocity)
        a = min(acceleration if acceleration > 0 else c.default_acceleration, c.max_acceleration)
        start = self._motor_at(t)
        if self._stuck_at is not None:
            self._stuck_since_s = t
        self._move = TrapezoidalMove(start, float(target), v, a, t)
        self._target = float(target)
        if self._move.direction:
            self._direction = self._move.direction
        for listener in self.move_listeners:
            listener(float(target), self._direction, t)

    def start_move(self, target: float, velocity: float = 0.0, acceleration: float = 0.0) -> bool:
        """Begin an absolute move; ignored (False) if disabled or faulted, faults outside the limits."""
        with self._lock:
            t = self.now()
            self._advance(t)
            if not self._enabled or self._fault_code:
                return False
            c = self.config
            if (c.min_position is not None and target < c.min_position) or (
                c.max_position is not None and target > c.max_position
            ):
                self._fault(FaultCode.POSITION_LIMIT, t)
                return False
            if not math.isfinite(target):
                return False
            self._homing = False
            self._start(target, velocity, acceleration, t)
            return True

    def stop(self) -> None:
        """Stop at once where the axis is (see the module docstring: no quick-stop ramp)."""
        with self._lock:
            t = self.now()
            self._advance(t)
            if self._move is not None:
                self._freeze(t, self._motor_at(t))
            self._target = self._rest

    def home(self) -> bool:
        """Move to the reference mark at the homing velocity; HOMED is set when it arrives.
        A rotary table's encoder has a mark every turn: it homes to the nearest one and
        its count is set to ``home_position`` there, as a drive's homing sets its actual
        position (a table wound up many turns by an endless scan does not unwind them)."""
        with self._lock:
            t = self.now()
            self._advance(t)
            if not self._enabled or self._fault_code:
                return False
            mark = self.config.home_position
            if self.config.kind == "rotary":
                mark += 360.0 * round((self._motor_at(t) - mark) / 360.0)
            self._start(mark, self.config.homing_velocity, 0.0, t)
            self._homing = True
            return True

    def reset_fault(self) -> bool:
        """Acknowledge the fault; refused (False) while its cause persists."""
        with self._lock:
            self._advance(self.now())
            if self._estop:
                return False
            self._fault_code = int(FaultCode.NONE)
            self._target = self._rest
            return True

    # ------------------------------------------------------------------ watchdog

    def heartbeat(self) -> None:
        with self._lock:
            self._advance(self.now())  # an already expired watchdog stays expired
            self._last_heartbeat_real = self._clock()

    def set_watchdog_timeout(self, timeout_s: float) -> None:
        with self._lock:
            self._advance(self.now())
            self._watchdog_timeout_s = max(0.0, float(timeout_s))
            self._last_heartbeat_real = self._clock()

    @property
    def watchdog_timeout_s(self) -> float:
        return self._watchdog_timeout_s

    # ------------------------------------------------------------------ injected faults

    def inject_fault(self, code: int) -> None:
        """The drive faults with ``code`` (ESTOP also opens the e-stop chain until cleared)."""
        with self._lock:
            t = self.now()
            self._advance(t)
            if int(code) == FaultCode.ESTOP:
                self._estop = True
            self._fault(code, t, self._motor_at(t))

    def release_estop(self) -> None:
        with self._lock:
            self._estop = False

    def set_stuck(self, stuck: bool) -> None:
        """Jam the motor where it is now (True) or free it (False)."""
        with self._lock:
            t = self.now()
            self._advance(t)
            if stuck and self._stuck_at is None:
                self._stuck_at = self._motor_at(t)
                self._stuck_since_s = t
            elif not stuck and self._stuck_at is not None:
                frozen = self._stuck_at
                self._stuck_at = None
                if self._move is not None:  # resume the interrupted move from where the jam held it
                    m = self._move
                    self._move = TrapezoidalMove(frozen, m.target, m.vmax, m.amax, t)
                else:
                    self._rest = frozen

    @property
    def stuck(self) -> bool:
        return self._stuck_at is not None
