"""The Modbus axis driver byte by byte, against docs/register-map.md (PyMeasure's
``expected_protocol`` manner, with ``drivers.testing``).

Every frame is written here from the documents, not from the driver: addresses,
bits and fault codes are plain numbers copied from docs/register-map.md (as in
test_modbus_raw.py, which checks the *twin* against the same page), the MBAP header
and the RTU CRC-16 are built by this module's own code from the Modbus specification
(Modbus Application Protocol V1.1b3; Modbus over Serial Line V1.02, 6.2.2). The
driver's end-to-end behaviour against the twins is test_modbus_driver.py's.
"""

from __future__ import annotations

import struct

import pytest

from drivers.interfaces import DeviceTimeout, DriveFault, FollowingError, ProtocolError
from drivers.modbus_axis import ModbusLinearAxis, ModbusRotaryAxis
from drivers.testing import HANG_UP, RECONNECT, SILENCE, ProtocolMismatch, expected_protocol


# ---------------------------------------------------------------- docs/register-map.md
CONTROL_WORD, STATUS_WORD, FIRMWARE_ID, TARGET_POSITION = 0, 1, 7, 8
WATCHDOG_COUNTER, WATCHDOG_TIMEOUT_MS, FOLLOWING_ERROR_LIMIT = 14, 15, 16
ENABLE, START_MOVE, STOP, FAULT_RESET = 0x01, 0x02, 0x04, 0x10
READY, ENABLED, MOVING, IN_POSITION, HOMED, FAULT, FOLLOWING_ERROR, ESTOP = (1 << b for b in range(8))
Z_DEVICE, C_DEVICE = 1, 2
Z_MM_PER_COUNT = 1e-4  # 0.1 um
C_DEG_PER_COUNT = 1e-4

# ---------------------------------------------------------------- Modbus spec, our own code


def crc16_modbus(frame: bytes) -> bytes:
    """CRC-16/MODBUS, bit by bit as the serial-line spec describes it (preset 0xFFFF,
    reflected polynomial 0xA001), low byte first on the wire."""
    crc = 0xFFFF
    for byte in frame:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return bytes([crc & 0xFF, crc >> 8])


def test_crc_matches_the_specs_worked_example():
    # Modbus over Serial Line V1.02, 6.2.2: read of 1 register at 0x0000 from device 1
    # -> 01 03 00 00 00 01 84 0A (the CRC 0x0A84, low byte first)
    assert crc16_modbus(bytes.fromhex("010300000001")) == bytes.fromhex("840A")


def read_req(address: int, count: int) -> bytes:
    return struct.pack(">BHH", 3, address, count)


def read_rsp(values: list[int]) -> bytes:
    return struct.pack(">BB", 3, 2 * len(values)) + struct.pack(f">{len(values)}H", *values)


def write_req(address: int, values: list[int]) -> bytes:
    return struct.pack(">BHHB", 16, address, len(values), 2 * len(values)) + struct.pack(f">{len(values)}H", *values)


def write_rsp(address: int, count: int) -> bytes:
    return struct.pack(">BHH", 16, address, count)


def exception_rsp(function: int, code: int) -> bytes:
    return bytes([function | 0x80, code])


def i32(value: int) -> list[int]:
    u = value & 0xFFFFFFFF
    return [u >> 16, u & 0xFFFF]  # high word first (register-map.md)


def status_regs(word: int, position_counts: int = 0, velocity_counts: int = 0, fault: int = 0) -> list[int]:
    """Registers 1..6: status word, position (2), velocity (2), fault code."""
    return [word] + i32(position_counts) + i32(velocity_counts) + [fault]


class Tcp:
    """MBAP framing with the transaction ids a client must use: one more per request."""

    def __init__(self, unit: int, first_tid: int = 1):
        self.unit, self.tid = unit, first_tid

    def __call__(self, request_pdu: bytes, reply_pdu, tid: int | None = None):
        t = self.tid if tid is None else tid
        self.tid += 1

        def mbap(pdu: bytes, tid=t) -> bytes:
            return struct.pack(">HHHB", tid, 0, len(pdu) + 1, self.unit) + pdu

        return mbap(request_pdu), (mbap(reply_pdu) if isinstance(reply_pdu, bytes) else reply_pdu)


class Rtu:
    def __init__(self, unit: int):
        self.unit = unit

    def frame(self, pdu: bytes) -> bytes:
        body = bytes([self.unit]) + pdu
        return body + crc16_modbus(body)

    def __call__(self, request_pdu: bytes, reply_pdu):
        return self.frame(request_pdu), (self.frame(reply_pdu) if isinstance(reply_pdu, bytes) else reply_pdu)


def z_axis(address, **kw):
    params = dict(name="Z", device_id=Z_DEVICE, unit_per_count=Z_MM_PER_COUNT, default_velocity=20.0,
                  default_acceleration=200.0, timeout_s=0.2, poll_s=0.001,
                  # 60 s watchdog, 25 s heartbeat: no heartbeat frame falls inside a test
                  watchdog_timeout_ms=60000, heartbeat_period_s=25.0)
    params.update(kw)
    if isinstance(address, str):
        return ModbusLinearAxis.rtu(address, **params)
    return ModbusLinearAxis.tcp(*address, **params)


# ---------------------------------------------------------------- the documented sequence


def connect_exchanges(x, following_error_counts: int | None = 5000):
    out = [x(read_req(FIRMWARE_ID, 1), read_rsp([0x0102]))]
    if following_error_counts is not None:
        out.append(x(write_req(FOLLOWING_ERROR_LIMIT, i32(following_error_counts)), write_rsp(FOLLOWING_ERROR_LIMIT, 2)))
    out += [x(write_req(WATCHDOG_COUNTER, [1]), write_rsp(WATCHDOG_COUNTER, 1)),  # heartbeat first,
            x(write_req(WATCHDOG_TIMEOUT_MS, [60000]), write_rsp(WATCHDOG_TIMEOUT_MS, 1))]  # then arm the watchdog
    return out


def move_exchanges(x):
    """Enable, then a move to 12.3456 mm at 20 mm/s and 200 mm/s^2, polled until in position."""
    idle = READY | ENABLED | IN_POSITION | HOMED
    return [
        x(write_req(CONTROL_WORD, [ENABLE]), write_rsp(CONTROL_WORD, 1)),
        # the move is refused unless the drive says it is enabled and faultless
        x(read_req(STATUS_WORD, 6), read_rsp(status_regs(idle))),
        # 123456 counts of 0.1 um; 200000 counts/s; 2000000 counts/s^2; one FC16 over 8..13
        x(write_req(TARGET_POSITION, [0x0001, 0xE240, 0x0003, 0x0D40, 0x001E, 0x8480]), write_rsp(TARGET_POSITION, 6)),
        x(write_req(CONTROL_WORD, [ENABLE | START_MOVE]), write_rsp(CONTROL_WORD, 1)),
        # status polled: moving, moving, then in position at the target
        x(read_req(STATUS_WORD, 6), read_rsp(status_regs(READY | ENABLED | MOVING | HOMED, 40000, 200000))),
        x(read_req(STATUS_WORD, 6), read_rsp(status_regs(READY | ENABLED | MOVING | HOMED, 110000, 90000))),
        x(read_req(STATUS_WORD, 6), read_rsp(status_regs(idle, 123456))),
    ]


async def enable_and_move(axis):
    await axis.enable()
    await axis.move_to(12.3456, velocity=20.0, acceleration=200.0)
    return await axis.wait_in_position(2.0)


@pytest.mark.asyncio
async def test_tcp_connect_enable_move_and_poll_until_in_position():
    x = Tcp(Z_DEVICE)
    script = connect_exchanges(x) + move_exchanges(x)
    async with expected_protocol(lambda a: z_axis(a, following_error_limit=0.5), script, connect=True) as axis:
        assert axis.firmware_id == 0x0102
        st = await enable_and_move(axis)
        assert st.in_position and not st.moving
        assert st.position == pytest.approx(12.3456, abs=1e-12)


@pytest.mark.asyncio
async def test_rtu_connect_enable_move_and_poll_until_in_position():
    x = Rtu(Z_DEVICE)
    script = connect_exchanges(x, None) + move_exchanges(x)
    async with expected_protocol(z_axis, script, rtu=True, connect=True) as axis:
        st = await enable_and_move(axis)
        assert st.position == pytest.approx(12.3456, abs=1e-12)


@pytest.mark.asyncio
async def test_rotary_axis_negative_target_on_its_own_device_id():
    x = Tcp(C_DEVICE)
    script = [
        x(read_req(STATUS_WORD, 6), read_rsp(status_regs(READY | ENABLED | IN_POSITION))),
        # -90.5 deg = -905000 counts: two's complement 0xFFF2 0x30D8, high word first
        x(write_req(TARGET_POSITION, [0xFFF2, 0x30D8, 0x0009, 0x3B48, 0x0098, 0x9680]), write_rsp(TARGET_POSITION, 6)),
        x(write_req(CONTROL_WORD, [START_MOVE]), write_rsp(CONTROL_WORD, 1)),
    ]

    def c_axis(address):
        return ModbusRotaryAxis.tcp(*address, name="C", device_id=C_DEVICE, unit_per_count=C_DEG_PER_COUNT,
                                    default_velocity=60.5, default_acceleration=1000.0, timeout_s=0.2,
                                    watchdog_timeout_ms=0)

    async with expected_protocol(c_axis, script) as axis:
        # defaults: 605000 counts/s = 0x0009 0x3B48, 10000000 counts/s^2 = 0x0098 0x9680
        await axis.move_to(-90.5)


# ---------------------------------------------------------------- faults in the status word


@pytest.mark.parametrize("framing", ["tcp", "rtu"])
@pytest.mark.asyncio
async def test_drive_fault_word_becomes_drive_fault_with_its_code(framing):
    x = Tcp(Z_DEVICE) if framing == "tcp" else Rtu(Z_DEVICE)
    script = [
        # overcurrent (0x0020): FAULT set, ENABLED dropped (a fault disables the drive)
        x(read_req(STATUS_WORD, 6), read_rsp(status_regs(HOMED | FAULT, 50000, 0, 0x0020))),
    ]
    async with expected_protocol(z_axis, script, rtu=framing == "rtu") as axis:
        with pytest.raises(DriveFault) as info:
            await axis.wait_in_position(1.0)
        assert info.value.code == 0x0020 and "overcurrent" in str(info.value)


@pytest.mark.asyncio
async def test_following_error_bit_becomes_following_error():
    x = Tcp(Z_DEVICE)
    script = [x(read_req(STATUS_WORD, 6),
                read_rsp(status_regs(HOMED | FAULT | FOLLOWING_ERROR, 31000, 0, 0x0010)))]
    async with expected_protocol(z_axis, script) as axis:
        with pytest.raises(FollowingError) as info:
            await axis.move_to(5.0)  # the status read before the move sees the fault; nothing is written
        assert info.value.code == 0x0010


@pytest.mark.asyncio
async def test_estop_word_becomes_drive_fault_and_no_move_is_sent():
    x = Tcp(Z_DEVICE)
    script = [x(read_req(STATUS_WORD, 6), read_rsp(status_regs(ESTOP | FAULT, 0, 0, 0x0012)))]
    async with expected_protocol(z_axis, script) as axis:
        with pytest.raises(DriveFault, match="emergency stop"):
            await axis.move_to(5.0)


@pytest.mark.asyncio
async def test_fault_reset_is_written_without_enable():
    x = Tcp(Z_DEVICE)
    script = [x(write_req(CONTROL_WORD, [ENABLE]), write_rsp(CONTROL_WORD, 1)),
              x(write_req(CONTROL_WORD, [FAULT_RESET]), write_rsp(CONTROL_WORD, 1)),
              x(write_req(CONTROL_WORD, [STOP]), write_rsp(CONTROL_WORD, 1))]  # ENABLE stays off afterwards
    async with expected_protocol(z_axis, script) as axis:
        await axis.enable()
        await axis.reset_fault()
        await axis.stop()


# ---------------------------------------------------------------- exception responses


@pytest.mark.parametrize("framing", ["tcp", "rtu"])
@pytest.mark.asyncio
async def test_exception_response_is_a_protocol_error_and_the_link_stays(framing):
    x = Tcp(Z_DEVICE) if framing == "tcp" else Rtu(Z_DEVICE)
    script = [
        # illegal data address (2): e.g. a drive whose map ends before 14
        x(write_req(WATCHDOG_COUNTER, [1]), exception_rsp(16, 2)),
        # the same connection answers the next request (no reconnect on a valid exception frame)
        x(write_req(CONTROL_WORD, [ENABLE]), write_rsp(CONTROL_WORD, 1)),
    ]
    async with expected_protocol(z_axis, script, rtu=framing == "rtu") as axis:
        with pytest.raises(ProtocolError, match="exception code 2"):
            await axis.write_registers(WATCHDOG_COUNTER, [1])
        await axis.enable()


# ---------------------------------------------------------------- silence and corrupt replies


@pytest.mark.parametrize("framing", ["tcp", "rtu"])
@pytest.mark.asyncio
async def test_no_answer_is_a_timeout_then_a_fresh_connection(framing):
    x = Tcp(Z_DEVICE) if framing == "tcp" else Rtu(Z_DEVICE)
    script = [x(read_req(STATUS_WORD, 6), SILENCE), RECONNECT]
    if framing == "tcp":
        x = Tcp(Z_DEVICE)  # a new connection is a new client: its ids start again
    script.append(x(read_req(STATUS_WORD, 6), read_rsp(status_regs(READY))))
    async with expected_protocol(lambda a: z_axis(a, timeout_s=0.1), script, rtu=framing == "rtu") as axis:
        with pytest.raises(DeviceTimeout):
            await axis.status()
        assert (await axis.status()).ready


@pytest.mark.asyncio
async def test_rtu_bad_crc_is_refused_the_link_dropped_and_the_retry_answered():
    x = Rtu(Z_DEVICE)
    request, good = x(read_req(STATUS_WORD, 6), read_rsp(status_regs(READY | ENABLED, 123456)))
    bad = good[:-2] + bytes([good[-2] ^ 0xFF, good[-1]])  # one CRC byte wrong
    script = [(request, bad), RECONNECT, (request, good)]
    async with expected_protocol(z_axis, script, rtu=True) as axis:
        with pytest.raises(ProtocolError, match="not a valid frame"):
            await axis.status()
        # the sequencer repeats a read (an idempotent step): the fresh link gets the good frame
        assert (await axis.status()).position == pytest.approx(12.3456, abs=1e-12)


@pytest.mark.asyncio
async def test_rtu_reply_split_across_reads_is_assembled():
    x = Rtu(Z_DEVICE)
    request, reply = x(read_req(FIRMWARE_ID, 1), read_rsp([0x0102]))
    async with expected_protocol(z_axis, [(request, [reply[:3], reply[3:]])], rtu=True) as axis:
        assert await axis.read_registers(FIRMWARE_ID, 1) == [0x0102]


@pytest.mark.asyncio
async def test_tcp_reply_with_a_stale_transaction_id_is_not_taken():
    x = Tcp(Z_DEVICE)
    request, _ = x(read_req(STATUS_WORD, 6), b"")
    stale = struct.pack(">HHHB", 0x0777, 0, 14, Z_DEVICE) + read_rsp(status_regs(READY | ENABLED | IN_POSITION))
    x2 = Tcp(Z_DEVICE)
    script = [(request, stale), RECONNECT, x2(read_req(STATUS_WORD, 6), read_rsp(status_regs(READY)))]
    async with expected_protocol(lambda a: z_axis(a, timeout_s=0.1), script) as axis:
        with pytest.raises((ProtocolError, DeviceTimeout)):
            await axis.status()
        st = await axis.status()
        assert st.ready and not st.enabled  # the second answer, not the stale one


@pytest.mark.asyncio
async def test_hang_up_is_communication_lost():
    from drivers.interfaces import CommunicationLost

    x = Tcp(Z_DEVICE)
    script = [x(read_req(STATUS_WORD, 6), HANG_UP)]
    async with expected_protocol(z_axis, script) as axis:
        with pytest.raises(CommunicationLost):
            await axis.status()


# ---------------------------------------------------------------- the kit fails when it must


@pytest.mark.asyncio
async def test_kit_refuses_a_frame_that_differs_by_one_byte():
    x = Tcp(Z_DEVICE)
    # the script says target 123457 counts; the driver sends 123456
    script = [x(read_req(STATUS_WORD, 6), read_rsp(status_regs(READY | ENABLED))),
              x(write_req(TARGET_POSITION, [0x0001, 0xE241, 0x0003, 0x0D40, 0x001E, 0x8480]), write_rsp(8, 6))]
    with pytest.raises(ProtocolMismatch, match="step 1: expected"):
        async with expected_protocol(z_axis, script) as axis:
            await axis.move_to(12.3456)


@pytest.mark.asyncio
async def test_kit_refuses_an_extra_frame_and_a_missing_one():
    x = Tcp(Z_DEVICE)
    with pytest.raises(ProtocolMismatch, match="extra frame"):
        async with expected_protocol(z_axis, [x(write_req(CONTROL_WORD, [ENABLE]), write_rsp(0, 1))]) as axis:
            await axis.enable()
            await axis.stop()
    x = Tcp(Z_DEVICE)
    with pytest.raises(ProtocolMismatch, match="never made"):
        async with expected_protocol(z_axis, [x(write_req(CONTROL_WORD, [ENABLE]), write_rsp(0, 1)),
                                              x(write_req(CONTROL_WORD, [STOP]), write_rsp(0, 1))]) as axis:
            await axis.enable()
