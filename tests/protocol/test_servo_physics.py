"""The drive's physics without any protocol: trapezoidal profile, homing, jam, watchdog, world hook."""

from __future__ import annotations

import math

import pytest

from drivers.interfaces.register_map import FaultCode
from station.motion import TrapezoidalMove
from sim.servo.physics import ServoAxisConfig, ServoAxisPhysics


class ManualClock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


def test_trapezoid_reaches_vmax_and_ends_exactly():
    m = TrapezoidalMove(start=0.0, target=100.0, vmax=20.0, amax=100.0, t0=5.0)
    assert m.t_accel == pytest.approx(0.2)
    # 2 ramps cover 0.5*100*0.2^2*2 = 4 mm; 96 mm cruise at 20 mm/s
    assert m.duration == pytest.approx(0.4 + 96.0 / 20.0)
    assert m.position(5.0) == 0.0
    assert m.position(5.0 + m.duration) == 100.0
    assert m.velocity(5.0 + 1.0) == pytest.approx(20.0)
    assert m.position(5.0 + m.duration / 2) == pytest.approx(50.0)
    assert not m.done(5.0 + m.duration - 1e-6) and m.done(5.0 + m.duration)


def test_triangular_profile_for_a_short_move_and_negative_direction():
    m = TrapezoidalMove(start=1.0, target=0.0, vmax=50.0, amax=100.0)
    assert m.t_cruise == 0.0
    assert m.v_peak == pytest.approx(math.sqrt(100.0 * 1.0))  # v^2 = a * d for two equal ramps
    assert m.direction == -1
    assert m.velocity(m.t_accel) == pytest.approx(-m.v_peak)
    samples = [m.position(t * m.duration / 50) for t in range(51)]
    assert all(b <= a for a, b in zip(samples, samples[1:]))  # monotonic towards the target
    assert samples[-1] == 0.0


def test_null_move_is_done_at_once():
    m = TrapezoidalMove(3.0, 3.0, 10.0, 10.0, t0=1.0)
    assert m.duration == 0.0 and m.done(1.0) and m.position(7.0) == 3.0 and m.direction == 0


def _physics(**cfg):
    clock = ManualClock()
    p = ServoAxisPhysics(ServoAxisConfig(**cfg), clock=clock)
    return p, clock


def test_move_only_when_enabled_and_within_limits():
    p, clock = _physics(min_position=0.0, max_position=50.0)
    assert not p.start_move(10.0, 10.0, 100.0)  # disabled: ignored
    p.enable(True)
    assert p.start_move(10.0, 10.0, 100.0)
    assert p.snapshot().moving
    clock.t += 5.0
    s = p.snapshot()
    assert not s.moving and s.in_position and s.motor_position == 10.0 and p.direction == 1
    assert not p.start_move(60.0, 10.0, 100.0)
    s = p.snapshot()
    assert s.fault_code == FaultCode.POSITION_LIMIT and not s.enabled and s.motor_position == 10.0


def test_homing_sets_homed_on_arrival():
    p, clock = _physics(initial_position=7.0, homing_velocity=5.0)
    p.enable(True)
    assert p.snapshot().motor_position == 7.0 and not p.snapshot().homed
    p.home()
    clock.t += 0.1
    assert not p.snapshot().homed
    clock.t += 10.0
    s = p.snapshot()
    assert s.homed and s.motor_position == 0.0 and s.in_position


def test_time_scale_speeds_up_moves():
    clock = ManualClock()
    p = ServoAxisPhysics(ServoAxisConfig(), clock=clock, time_scale=10.0)
    p.enable(True)
    p.start_move(10.0, 10.0, 1000.0)  # ~1.01 s of drive time
    clock.t += 0.2  # 2 s of drive time
    assert p.snapshot().motor_position == 10.0


def test_jammed_axis_ends_in_following_error_and_recovers_after_reset():
    p, clock = _physics(following_error_limit=0.5)
    p.enable(True)
    p.set_stuck(True)
    p.start_move(10.0, 10.0, 1000.0)
    clock.t += 2.0
    s = p.snapshot()
    assert s.fault_code == FaultCode.FOLLOWING_ERROR and not s.enabled and not s.moving
    assert s.motor_position == 0.0
    p.set_stuck(False)
    assert p.reset_fault()
    p.enable(True)
    p.start_move(10.0, 10.0, 1000.0)
    clock.t += 2.0
    assert p.snapshot().motor_position == 10.0


def test_watchdog_faults_a_silent_master_and_heartbeats_keep_it_alive():
    p, clock = _physics()
    p.set_watchdog_timeout(0.5)
    p.enable(True)
    for _ in range(5):
        clock.t += 0.3
        p.heartbeat()
    assert p.snapshot().fault_code == FaultCode.NONE
    clock.t += 0.6
    assert p.snapshot().fault_code == FaultCode.WATCHDOG_EXPIRED
    p.heartbeat()  # too late: the fault stays until reset
    assert p.snapshot().fault_code == FaultCode.WATCHDOG_EXPIRED


def test_estop_blocks_reset_until_released():
    p, _ = _physics()
    p.enable(True)
    p.inject_fault(FaultCode.ESTOP)
    assert p.snapshot().estop and not p.reset_fault()
    p.release_estop()
    assert p.reset_fault() and p.snapshot().fault_code == 0


def test_world_offset_moves_the_carriage_not_the_motor():
    p, clock = _physics()
    calls = []

    def offset(motor, direction, t):
        calls.append((motor, direction))
        return 0.001 * motor + 0.002 * direction  # 1000 ppm scale + 4 um backlash, in mm

    p.actual_offset = offset
    p.enable(True)
    p.start_move(20.0, 10.0, 1000.0)
    clock.t += 5.0
    assert p.motor_position() == 20.0
    assert p.carriage_position() == pytest.approx(20.0 + 0.02 + 0.002)
    assert calls[-1] == (20.0, 1)


def test_offset_from_an_error_curve_converts_um_to_mm_and_uses_direction():
    from sim.servo.physics import offset_from_curve
    from station.effects import Backlash, ErrorCurve, Scale

    curve = ErrorCurve.table([0.0, 100.0], [0.0, 10.0], kind="linear", effects=[Backlash(reversal=4.0), Scale(ppm=0.0)])
    p, clock = _physics()
    p.actual_offset = offset_from_curve(curve)
    p.enable(True)
    p.start_move(50.0, 10.0, 1000.0)
    clock.t += 10.0
    # baseline 5 um at 50 mm, backlash +2 um approaching upwards: 7 um = 0.007 mm
    assert p.carriage_position() == pytest.approx(50.007)
    p.start_move(40.0, 10.0, 1000.0)
    clock.t += 10.0
    assert p.carriage_position() == pytest.approx(40.0 + 0.004 - 0.002)


def test_a_wound_up_rotary_table_homes_to_the_nearest_mark_and_its_count_is_set_there():
    # an endless scan wound the table up 20 turns and a bit: homing does not unwind them
    p, clock = _physics(kind="rotary", initial_position=7200.0 + 3.0, homing_velocity=30.0)
    p.enable(True)
    p.home()
    clock.t += 1.0  # 3 deg at 30 deg/s (and its ramps): not 7203 deg (240 s)
    s = p.snapshot()
    assert s.homed and s.in_position and s.motor_position == 0.0
    # from just below a mark it goes up to it
    p2, clock2 = _physics(kind="rotary", initial_position=-718.0, homing_velocity=30.0)
    p2.enable(True)
    p2.home()
    clock2.t += 1.0
    assert p2.snapshot().homed and p2.snapshot().motor_position == 0.0
    # a linear axis has one mark
    p3, clock3 = _physics(initial_position=361.0, homing_velocity=30.0)
    p3.enable(True)
    p3.home()
    clock3.t += 1.0
    assert not p3.snapshot().homed
