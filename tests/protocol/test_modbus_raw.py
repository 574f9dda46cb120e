"""An independent Modbus TCP client (MBAP + PDU built by hand) against the drive twin.

Addresses and bit positions are written here as plain numbers copied from
docs/register-map.md -- deliberately not imported from drivers.interfaces.register_map,
so that the document, the shared constants and the twin are checked against each other.
"""

from __future__ import annotations

import socket
import struct
import time

import pytest

# docs/register-map.md
CONTROL, STATUS, ACTUAL_POS, FAULT, FIRMWARE, TARGET, WD_COUNTER, WD_TIMEOUT = 0, 1, 2, 6, 7, 8, 14, 15
ENABLE, START, HOME = 0x01, 0x02, 0x08
ST_ENABLED, ST_MOVING, ST_IN_POS, ST_HOMED = 0x02, 0x04, 0x08, 0x10


class RawModbus:
    def __init__(self, host, port, unit):
        self.sock = socket.create_connection((host, port), timeout=2.0)
        self.unit = unit
        self.tid = 0

    def close(self):
        self.sock.close()

    def _recv_exact(self, n):
        buf = b""
        while len(buf) < n:
            chunk = self.sock.recv(n - len(buf))
            if not chunk:
                raise ConnectionError("closed by the server")
            buf += chunk
        return buf

    def transact(self, pdu: bytes) -> bytes:
        self.tid = (self.tid + 1) & 0xFFFF
        # MBAP: transaction id, protocol id 0, length (unit id + PDU), unit id
        self.sock.sendall(struct.pack(">HHHB", self.tid, 0, len(pdu) + 1, self.unit) + pdu)
        tid, proto, length, unit = struct.unpack(">HHHB", self._recv_exact(7))
        assert (tid, proto, unit) == (self.tid, 0, self.unit)
        return self._recv_exact(length - 1)

    def read(self, address, count):
        reply = self.transact(struct.pack(">BHH", 3, address, count))
        if reply[0] != 3:
            return ("exception", reply[0], reply[1])
        assert reply[1] == 2 * count
        return list(struct.unpack(f">{count}H", reply[2:]))

    def write(self, address, values):
        pdu = struct.pack(">BHHB", 16, address, len(values), 2 * len(values)) + struct.pack(f">{len(values)}H", *values)
        reply = self.transact(pdu)
        if reply[0] != 16:
            return ("exception", reply[0], reply[1])
        assert struct.unpack(">HH", reply[1:5]) == (address, len(values))
        return None


def int32(hi, lo):
    v = (hi << 16) | lo
    return v - (1 << 32) if v & 0x80000000 else v


@pytest.fixture
def raw_z(twins_thread):
    ep = twins_thread.station.endpoints()["Z"]
    client = RawModbus(ep["host"], ep["port"], ep["device_id"])
    try:
        yield client
    finally:
        client.close()


def wait_status(client, mask, timeout_s=5.0):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        status = client.read(STATUS, 1)[0]
        if status & mask == mask and not status & ST_MOVING:
            return status
        time.sleep(0.01)
    raise AssertionError(f"status never had {mask:#x}")


def test_identity_and_power_on_state(raw_z):
    assert raw_z.read(FIRMWARE, 1) == [0x0102]
    status, = raw_z.read(STATUS, 1)
    assert status & 0x01  # READY
    assert not status & (ST_ENABLED | ST_HOMED | 0x20)
    assert raw_z.read(WD_TIMEOUT, 1) == [0]  # watchdog off at power-on


def test_home_then_move_by_hand_written_frames(raw_z, twins_thread):
    assert raw_z.write(CONTROL, [ENABLE]) is None
    assert raw_z.write(CONTROL, [ENABLE | HOME]) is None
    assert raw_z.read(CONTROL, 1) == [ENABLE]  # command bits are self-clearing
    wait_status(raw_z, ST_ENABLED | ST_HOMED | ST_IN_POS)
    # target 12.3456 mm = 123456 counts of 0.1 um, high word first; 20 mm/s; 200 mm/s^2
    target = 123456
    velocity, accel = 200000, 2000000
    regs = [target >> 16, target & 0xFFFF, velocity >> 16, velocity & 0xFFFF, accel >> 16, accel & 0xFFFF]
    assert raw_z.write(TARGET, regs) is None
    assert raw_z.read(TARGET, 6) == regs
    assert raw_z.write(CONTROL, [ENABLE | START]) is None
    wait_status(raw_z, ST_IN_POS)
    hi, lo = raw_z.read(ACTUAL_POS, 2)
    assert int32(hi, lo) == target
    assert twins_thread.call(lambda: twins_thread.station.physics["Z"].motor_position()) == pytest.approx(12.3456)


def test_negative_target_uses_twos_complement(raw_z):
    raw_z.write(CONTROL, [ENABLE])
    counts = -15000  # -1.5 mm, inside the soft limit of -2 mm
    u = counts & 0xFFFFFFFF
    raw_z.write(TARGET, [u >> 16, u & 0xFFFF, 0, 0, 0, 0])  # 0 velocity/accel: the drive's defaults
    raw_z.write(CONTROL, [ENABLE | START])
    wait_status(raw_z, ST_IN_POS)
    assert int32(*raw_z.read(ACTUAL_POS, 2)) == counts


def test_read_only_and_missing_registers_answer_illegal_address(raw_z):
    assert raw_z.write(STATUS, [0xFFFF]) == ("exception", 0x90, 2)
    assert raw_z.write(ACTUAL_POS, [0, 1]) == ("exception", 0x90, 2)
    assert raw_z.read(18, 1) == ("exception", 0x83, 2)
    assert raw_z.read(0, 18) != ("exception", 0x83, 2)  # the whole map is readable in one request


def test_out_of_limit_target_faults_with_documented_code(raw_z):
    raw_z.write(CONTROL, [ENABLE])
    counts = 5_000_000  # 500 mm, beyond the 202 mm soft limit
    raw_z.write(TARGET, [counts >> 16, counts & 0xFFFF, 0, 0, 0, 0])
    raw_z.write(CONTROL, [ENABLE | START])
    status, = raw_z.read(STATUS, 1)
    assert status & 0x20 and not status & ST_ENABLED
    assert raw_z.read(FAULT, 1) == [0x0013]


def test_c_axis_answers_on_its_own_device_id(twins_thread):
    ep = twins_thread.station.endpoints()["C"]
    assert ep["device_id"] == 2
    c = RawModbus(ep["host"], ep["port"], 2)
    try:
        assert c.read(FIRMWARE, 1) == [0x0102]
    finally:
        c.close()
