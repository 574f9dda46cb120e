"""The encoder driver against the encoder twin on a real pty, with every fault kind."""

from __future__ import annotations

import asyncio

import pytest
import pytest_asyncio

from drivers.encoder import SerialGratingEncoder
from drivers.interfaces import CommunicationLost, DeviceTimeout, DriveFault, ProtocolError
from sim.encoder import SerialEncoderTwin
from sim.faults import FaultKind

from .conftest import make_axis

pytestmark = pytest.mark.asyncio


@pytest.fixture
def world():
    """A settable true position (mm) standing in for the lead's world."""
    return {"z_mm": 42.123456}


@pytest.fixture
def head(world):
    twin = SerialEncoderTwin(lambda: world["z_mm"], resolution_um=0.05)
    twin.start()
    try:
        yield twin
    finally:
        twin.stop()


@pytest_asyncio.fixture
async def enc(head):
    e = SerialGratingEncoder(head.path, timeout_s=0.1, retries=1)
    try:
        await e.connect()
        yield e
    finally:
        await e.close()


async def test_reads_the_true_position_quantised(enc, world):
    assert enc.identity == "GRT-005 V1.3"
    reading = await enc.read()
    assert reading.position_mm == pytest.approx(42.12345, abs=1e-9)  # 0.05 um steps: 842469.12 -> 842469 counts
    world["z_mm"] = -0.000026  # -0.52 counts -> -1 count
    assert (await enc.read()).position_mm == pytest.approx(-0.00005)


@pytest.mark.parametrize(
    "kind, error",
    [
        (FaultKind.DROP_CONNECTION, DeviceTimeout),
        (FaultKind.GARBAGE, ProtocolError),
        (FaultKind.CHECKSUM, ProtocolError),
        (FaultKind.STUCK_AXIS, DriveFault),
        (FaultKind.DRIVE_FAULT, DriveFault),
    ],
)
async def test_each_fault_gives_its_typed_error_and_the_driver_recovers(enc, head, world, kind, error):
    head.faults.activate(kind)
    try:
        with pytest.raises(error):
            await enc.read()
    finally:
        head.faults.clear(kind)
    world["z_mm"] = 10.0
    assert (await enc.read()).position_mm == pytest.approx(10.0)


@pytest.mark.parametrize("delay_s", [0.25, 0.35])
async def test_delay_beyond_timeout_is_device_timeout(enc, head, delay_s):
    # 0.35 s: the late answer comes after a quiet spell of 2 x timeout, so only the
    # owed-line rule keeps it from being taken for the retry's answer. The horizon is
    # set well past the delay: the test checks that rule, not the machine's scheduling.
    enc.late_reply_s = 1.0
    head.faults.activate(FaultKind.DELAY, delay_s=delay_s)
    try:
        with pytest.raises(DeviceTimeout):
            await enc.read()
    finally:
        head.faults.clear()
    await asyncio.sleep(0.6)  # let the late replies arrive; they must be flushed, not taken as answers
    assert (await enc.read()).position_mm == pytest.approx(42.12345)


async def test_stuck_head_freezes_its_count(head, world):
    e = SerialGratingEncoder(head.path, timeout_s=0.1, strict=False)
    try:
        head.faults.activate(FaultKind.STUCK_AXIS)
        first = await e.read()
        world["z_mm"] = 1.0
        second = await e.read()
        assert second.position_mm == first.position_mm and second.status.signal_low
    finally:
        head.faults.clear()
        await e.close()


async def test_missing_port_is_communication_lost():
    e = SerialGratingEncoder("/dev/does-not-exist-ttyX", timeout_s=0.05)
    with pytest.raises(CommunicationLost):
        await e.read()


async def test_encoder_sees_the_world_offset_the_drive_does_not(twins):
    """The twin station wiring: drive reports the motor, the grating the carriage."""
    z = twins.physics["Z"]
    z.actual_offset = lambda motor_mm, direction, t: 0.002 + 1e-4 * motor_mm  # 2 um + 100 ppm, in mm
    axis = make_axis(twins, "Z")
    e = SerialGratingEncoder(twins.encoder.path, timeout_s=0.1)
    try:
        await axis.connect()
        await axis.enable()
        await axis.move_to(50.0)
        st = await axis.wait_in_position(5.0)
        reading = await e.read()
        assert st.position == pytest.approx(50.0)
        assert reading.position_mm == pytest.approx(50.0 + 0.002 + 0.005, abs=0.05e-3)
    finally:
        await e.close()
        await axis.close()
