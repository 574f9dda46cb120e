"""The axes' public face: the small protocols, ``ServoAxis`` (its setpoint, its
movable core ``set``), the move logic, and ``drivers.testing``'s instant mock axis
that the station's unit tests drive instead of a drive."""

from __future__ import annotations

import asyncio
import math

import pytest

from drivers.interfaces import (
    DeviceTimeout,
    DriveFault,
    DriverError,
    FollowingError,
    LinearAxis,
    Locatable,
    Location,
    Movable,
    MoveLogic,
    Readable,
    RotaryAxis,
    ServoAxis,
    Stoppable,
)
from drivers.modbus_axis import ModbusLinearAxis, ModbusRotaryAxis
from drivers.testing import InstantMockAxis, InstantMockLinearAxis, InstantMockRotaryAxis
from station.motion import AxisLimits, move_time_s


def run(coro):
    return asyncio.run(coro)


# ---------------------------------------------------------------- protocols


def test_axes_satisfy_the_small_protocols_and_carry_their_units_as_data():
    z = ModbusLinearAxis.tcp("127.0.0.1", 1, name="Z", device_id=1, unit_per_count=1e-4,
                             default_velocity=20.0, default_acceleration=200.0)
    c = ModbusRotaryAxis.tcp("127.0.0.1", 1, name="C", device_id=2, unit_per_count=1e-4,
                             default_velocity=30.0, default_acceleration=300.0)
    for ax in (z, c, InstantMockLinearAxis("Z"), InstantMockRotaryAxis("C")):
        for proto in (Movable, Locatable, Stoppable, Readable):
            assert isinstance(ax, proto), (ax, proto)
        assert ax.setpoint is None  # nothing commanded yet
    assert (z.units, c.units) == ("mm", "deg") and z.unit == "mm"  # ``unit``: the former name
    assert isinstance(InstantMockLinearAxis("Z"), LinearAxis) and isinstance(InstantMockRotaryAxis("C"), RotaryAxis)
    # a plain object with only ``stop`` is Stoppable and nothing more
    class OnlyStops:
        async def stop(self):
            pass
    assert isinstance(OnlyStops(), Stoppable) and not isinstance(OnlyStops(), Movable)


def test_setpoint_is_read_only():
    ax = InstantMockLinearAxis("Z")
    with pytest.raises(AttributeError):
        ax.setpoint = 3.0


# ---------------------------------------------------------------- move logic


@pytest.mark.parametrize("distance", [0.0, 0.5, 5.0, 100.0, -30.0])
def test_move_logic_time_is_the_stations_trapezoid(distance):
    # drivers may not import station: the same rest-to-rest time, written twice, must agree
    v, a = 50.0, 500.0
    assert MoveLogic.duration_s(distance, v, a) == pytest.approx(move_time_s(distance, AxisLimits(v, a)), abs=1e-12)


def test_move_logic_timeout_defaults_checks_and_fallback():
    logic = MoveLogic(default_velocity=50.0, default_acceleration=500.0, velocity_limit=60.0, acceleration_limit=600.0)
    # 100 mm at 50 mm/s, 500 mm/s^2: 2.1 s; twice that plus 5 s
    assert logic.timeout_s(100.0) == pytest.approx(2 * 2.1 + 5.0)
    assert logic.timeout_s(100.0, velocity=25.0) == pytest.approx(2 * (100 / 25 + 25 / 500) + 5.0)
    assert logic.timeout_s(100.0, velocity=0.01) == 60.0  # capped
    assert logic.timeout_s(None) == 60.0
    assert MoveLogic().timeout_s(100.0) == 60.0  # profile unknown
    logic.check_move(10.0)
    for bad in (dict(target=math.nan), dict(target=1.0, velocity=61.0), dict(target=1.0, acceleration=-1.0)):
        with pytest.raises(ValueError):
            logic.check_move(**bad)


# ---------------------------------------------------------------- ServoAxis.set, locate


def test_set_moves_waits_and_takes_its_timeout_from_the_move_logic():
    async def go():
        z = InstantMockLinearAxis("Z", position=10.0, default_velocity=50.0, default_acceleration=500.0)
        await z.enable()
        st = await z.set(110.0)
        loc = await z.locate()
        with pytest.raises(ValueError):
            await z.set(math.inf)
        return z, st, loc

    z, st, loc = run(go())
    assert st.position == 110.0 and st.in_position and z.setpoint == 110.0
    assert loc == Location(setpoint=110.0, readback=110.0)
    (wait,) = z.calls_to("wait_in_position")
    assert wait.args[0] == pytest.approx(2 * 2.1 + 5.0)  # 100 mm from the reported 10 mm
    assert [c.args for c in z.calls_to("move_to")] == [(110.0, None, None)]  # the refused move was not sent


# ---------------------------------------------------------------- the instant mock axis


def test_mock_moves_at_once_records_calls_and_keeps_state_like_a_drive():
    async def go():
        c = InstantMockRotaryAxis("C")
        with pytest.raises(DriverError, match="not enabled"):
            await c.move_to(5.0)
        await c.enable()
        await c.home()
        homed = (await c.status()).homed, c.setpoint
        await c.move_to(30.0, 90.0, acceleration=720.0)
        at = await c.read_position()
        await c.stop()
        return c, homed, at

    c, homed, at = run(go())
    assert homed == (True, 0.0) and at == 30.0 and c.setpoint is None  # a stop forgets the target
    assert [k.method for k in c.calls] == ["move_to", "enable", "home", "status", "move_to", "read_position", "stop"]
    assert c.calls_to("move_to")[-1].args == (30.0, 90.0, 720.0) and c.count("stop") == 1
    assert isinstance(c.calls[0].error, DriverError) and c.calls[0].ended is None


def test_mock_failures_are_injected_per_call_and_used_up():
    async def go():
        z = InstantMockLinearAxis("Z")
        await z.enable()
        z.fail("move_to", DeviceTimeout, times=2)
        z.fail("move_to", DriveFault(0x20, "motor overcurrent", "Z"))
        z.fail("status", FollowingError, times=None)
        errors = []
        for _ in range(4):
            try:
                await z.move_to(1.0)
            except DriverError as exc:
                errors.append(exc)
        with pytest.raises(FollowingError) as fe:
            await z.status()
        z.clear_failures("status")
        return z, errors, fe.value, await z.status()

    z, errors, fe, st = run(go())
    assert [type(e) for e in errors] == [DeviceTimeout, DeviceTimeout, DriveFault]  # the 4th call succeeded
    assert errors[2].code == 0x20 and "Z" in str(errors[0]) and fe.code == 0x0010
    assert z.position == 1.0 and st.position == 1.0
    with pytest.raises(TypeError):
        z.fail("move_to", RuntimeError("not a driver error"))
    with pytest.raises(TypeError):
        z.fail("move_to", DriveFault)  # its code is needed
    with pytest.raises(ValueError):
        z.fail("jog", DeviceTimeout)


def test_mock_latched_fault_until_reset_then_disabled():
    async def go():
        z = InstantMockLinearAxis("Z")
        await z.enable()
        z.trip(0x0010, "following error")
        st = await z.status()
        with pytest.raises(FollowingError):
            await z.move_to(1.0)
        await z.enable()  # ignored while the fault is active
        still = z.enabled
        await z.reset_fault()
        after = await z.status()
        return st, still, after

    st, still, after = run(go())
    assert st.fault and st.following_error and st.fault_code == 0x10 and not st.enabled and not st.ready
    assert still is False
    assert not after.fault and after.ready and not after.enabled


def test_mock_delay_hold_and_timeout():
    async def go():
        z = InstantMockLinearAxis("Z", delay_s=0.05)
        await z.enable()
        await z.move_to(5.0)
        during = await z.status()
        with pytest.raises(DeviceTimeout):
            await z.wait_in_position(0.01)
        done = await z.wait_in_position(1.0)
        z.hold()
        await z.move_to(7.0)
        waiter = asyncio.ensure_future(z.wait_in_position(5.0))
        await asyncio.sleep(0.1)  # twice the delay: a held move has not arrived
        held = waiter.done(), z.position
        z.release()
        released = await asyncio.wait_for(waiter, 1.0)
        z.hold()
        await z.move_to(9.0)
        waiter = asyncio.ensure_future(z.wait_in_position(5.0))
        await asyncio.sleep(0.01)
        await z.stop()  # a stop ends the held move where it is
        stopped = await asyncio.wait_for(waiter, 1.0)
        return during, done, held, released, stopped, z.setpoint

    during, done, held, released, stopped, setpoint = run(go())
    assert during.moving and during.position == 0.0 and not during.in_position
    assert done.position == 5.0 and done.in_position
    assert held == (False, 5.0) and released.position == 7.0
    assert stopped.position == 7.0 and not stopped.moving and setpoint is None


def test_mock_units_are_checked():
    assert InstantMockAxis("X", "deg").units == "deg" and InstantMockAxis("X").units == "mm"
    with pytest.raises(ValueError):
        InstantMockAxis("X", "inch")
    with pytest.raises(ValueError):
        InstantMockRotaryAxis("C", "mm")
    assert issubclass(InstantMockAxis, ServoAxis)
