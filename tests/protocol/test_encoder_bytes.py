"""The encoder driver byte by byte (PyMeasure ``expected_protocol`` style).

A fake transport asserts the exact bytes the driver writes and feeds it scripted
replies -- whole, in pieces, behind noise, with a bad checksum, or not at all.
Frames are written out literally, checksums computed by hand in the comments, so a
change of the documented protocol breaks these tests.
"""

from __future__ import annotations

import asyncio

import pytest
import serial

from drivers.encoder import SerialGratingEncoder
from drivers.interfaces import CommunicationLost, DeviceTimeout, DriveFault, ProtocolError
from drivers.interfaces import encoder_protocol as ep

# a valid position frame: 246914 counts x 0.05 um = 12.3457 mm, status 01 = REFERENCED
GOOD_BODY = b"P+0000246914 S01 "


def xor(body: bytes) -> int:
    c = 0
    for b in body:
        c ^= b
    return c


GOOD = GOOD_BODY + b"*" + f"{xor(GOOD_BODY):02X}".encode() + b"\r\n"


class FakeSerial:
    """Scripted serial port: ``exchanges`` is a list of (expected write, [reply chunks])."""

    def __init__(self, exchanges, stale=b""):
        self.exchanges = list(exchanges)
        self.pending: list[bytes] = [stale] if stale else []
        self.written: list[bytes] = []
        self.resets = 0
        self.closed = False

    def write(self, data):
        assert self.exchanges, f"unexpected write {data!r}"
        expected, replies = self.exchanges.pop(0)
        assert data == expected
        self.written.append(data)
        if isinstance(replies, Exception):
            raise replies
        self.pending.extend(replies)
        return len(data)

    def read(self, size=1):
        if not self.pending:
            return b""  # like pyserial after its read timeout
        chunk = self.pending.pop(0)
        if len(chunk) > size:
            chunk, rest = chunk[:size], chunk[size:]
            self.pending.insert(0, rest)
        return chunk

    def reset_input_buffer(self):
        self.resets += 1
        self.pending.clear()

    def close(self):
        self.closed = True

    def assert_done(self):
        assert not self.exchanges, f"expected writes not made: {self.exchanges}"


def encoder(fake, **kw):
    return SerialGratingEncoder(transport=fake, timeout_s=0.05, retries=kw.pop("retries", 2), **kw)


def read(enc):
    return asyncio.run(enc.read())


def test_frame_layout_matches_the_document():
    assert ep.position_reply(246914, 0x01) == GOOD
    assert ep.position_reply(-5, 0x03) == b"P-0000000005 S03 *" + f"{xor(b'P-0000000005 S03 '):02X}".encode() + b"\r\n"
    assert ep.POSITION_QUERY == b"?P\r" and ep.IDENTITY_QUERY == b"?I\r"
    assert ep.error_reply(1) == b"E01 *" + f"{xor(b'E01 '):02X}".encode() + b"\r\n"


def test_documented_example_frames_are_exact():
    """The examples in docs/encoder-protocol.md, byte for byte (checksums included)."""
    assert GOOD == b"P+0000246914 S01 *25\r\n"
    assert ep.identity_reply("GRT-005", "V1.3") == b"I GRT-005 V1.3 *4A\r\n"
    assert ep.error_reply(1) == b"E01 *64\r\n"


def test_position_query_exact_bytes_and_scaling():
    fake = FakeSerial([(b"?P\r", [GOOD])])
    position_mm, timestamp, status = read(encoder(fake))
    assert position_mm == pytest.approx(246914 * 0.05e-3)  # counts * 0.05 um
    assert status.referenced and status.ok
    assert timestamp > 0
    fake.assert_done()


def test_identity_on_connect():
    body = b"I GRT-005 V1.3 "
    fake = FakeSerial([(b"?I\r", [body + b"*" + f"{xor(body):02X}".encode() + b"\r\n"])])
    enc = encoder(fake)
    asyncio.run(enc.connect())
    assert enc.identity == "GRT-005 V1.3"


def test_partial_frames_are_assembled():
    fake = FakeSerial([(b"?P\r", [GOOD[:3], GOOD[3:11], GOOD[11:-1], GOOD[-1:]])])
    assert read(encoder(fake)).position_mm == pytest.approx(12.3457)
    fake.assert_done()


def test_noise_before_the_frame_is_skipped():
    fake = FakeSerial([(b"?P\r", [b"\x00\xff\x13E9", GOOD])])  # 'E' inside the noise is a false start
    assert read(encoder(fake)).position_mm == pytest.approx(12.3457)
    fake.assert_done()


def test_stale_bytes_are_flushed_before_the_query():
    stale = b"P+0000000001 S01 *" + f"{xor(b'P+0000000001 S01 '):02X}".encode() + b"\r\n"
    fake = FakeSerial([(b"?P\r", [GOOD])], stale=stale)
    assert read(encoder(fake)).position_mm == pytest.approx(12.3457)
    assert fake.resets == 1


def test_checksum_error_is_retried_then_succeeds():
    bad = GOOD_BODY + b"*" + f"{xor(GOOD_BODY) ^ 0x01:02X}".encode() + b"\r\n"
    fake = FakeSerial([(b"?P\r", [bad]), (b"?P\r", [GOOD])])
    assert read(encoder(fake)).position_mm == pytest.approx(12.3457)
    fake.assert_done()


def test_persistent_checksum_errors_raise_protocol_error_after_bounded_retries():
    bad = GOOD_BODY + b"*00\r\n"
    fake = FakeSerial([(b"?P\r", [bad])] * 3)
    with pytest.raises(ProtocolError, match="checksum"):
        read(encoder(fake, retries=2))
    assert len(fake.written) == 3  # 1 + retries, no more
    fake.assert_done()


def test_garbage_line_raises_protocol_error():
    fake = FakeSerial([(b"?P\r", [b"\x8f\x02zz!!\r\n"])] * 2)
    with pytest.raises(ProtocolError):
        read(encoder(fake, retries=1))
    fake.assert_done()


def test_silence_raises_device_timeout():
    fake = FakeSerial([(b"?P\r", [])] * 2)
    with pytest.raises(DeviceTimeout, match="no reply"):
        read(encoder(fake, retries=1))
    fake.assert_done()


def test_half_frame_then_silence_is_a_timeout_naming_the_partial_reply():
    fake = FakeSerial([(b"?P\r", [GOOD[:9]])])
    with pytest.raises(DeviceTimeout, match="partial"):
        read(encoder(fake, retries=0))


def test_error_reply_is_a_protocol_error():
    e01 = b"E01 *" + f"{xor(b'E01 '):02X}".encode() + b"\r\n"
    fake = FakeSerial([(b"?P\r", [e01])])
    with pytest.raises(ProtocolError, match="error 01"):
        read(encoder(fake, retries=0))


def test_status_bits_raise_drive_fault_when_strict_and_pass_when_not():
    body = b"P+0000000100 S03 "  # referenced + signal low
    frame = body + b"*" + f"{xor(body):02X}".encode() + b"\r\n"
    with pytest.raises(DriveFault, match="signal low") as info:
        read(encoder(FakeSerial([(b"?P\r", [frame])])))
    assert info.value.code == 0x03
    reading = read(encoder(FakeSerial([(b"?P\r", [frame])]), strict=False))
    assert reading.status.signal_low and reading.position_mm == pytest.approx(0.005)


def test_serial_exception_is_communication_lost():
    fake = FakeSerial([(b"?P\r", serial.SerialException("device reports readiness to read but returned no data"))])
    with pytest.raises(CommunicationLost):
        read(encoder(fake))
