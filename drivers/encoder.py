"""The grating encoder on a serial line (pyserial): the Z carriage's true position.

Protocol: ``drivers.interfaces.encoder_protocol`` (docs/encoder-protocol.md), an ASCII
query/response with an XOR checksum.  A serial line delivers noise, half frames and
stale bytes, so the reader:

* discards stale input before each query (``reset_input_buffer``); after a timeout it
  counts the timed-out query's answer as owed and, before the next query, waits until
  that line has arrived and the line has been quiet, or until the late-reply horizon
  (the late answer must not be taken for the next query's: the protocol has no
  sequence number, so only an answer later than the horizon can still be misread);
* collects bytes until CR LF or a deadline; in a line with noise before a frame it
  finds the frame by its start letter (resync); a line that holds no valid frame is a
  :class:`ProtocolError` (checksum or layout), no line at all a :class:`DeviceTimeout`;
* repeats the query at most ``retries`` times, then raises the last error;
* turns an OS/serial error into :class:`CommunicationLost` and reopens the port on the
  next call.

Serial I/O is blocking, so it runs in a worker thread (``asyncio.to_thread``) under a
lock; every read is bounded by the deadline, so the thread never outlives the call by
more than one chunk timeout.
"""

from __future__ import annotations

import asyncio
import threading
import time
from typing import Protocol

import serial

from drivers.interfaces import (
    CommunicationLost,
    DeviceTimeout,
    DriveFault,
    EncoderReading,
    EncoderStatus,
    PositionEncoder,
    ProtocolError,
)
from drivers.interfaces import encoder_protocol as ep

#: each blocking read waits at most this long; the deadline loop re-checks in between
READ_CHUNK_TIMEOUT_S = 0.01


class SerialTransport(Protocol):
    """What the driver needs from a port: pyserial's ``Serial`` has it, so has a test fake."""

    def write(self, data: bytes) -> int | None: ...
    def read(self, size: int = 1) -> bytes: ...
    # optional: ``in_waiting`` (bytes ready), used to read a reply in one go
    def reset_input_buffer(self) -> None: ...
    def close(self) -> None: ...


def decode_status(raw: int) -> EncoderStatus:
    b = ep.EncoderStatusBit
    return EncoderStatus(
        referenced=bool(raw & b.REFERENCED),
        signal_low=bool(raw & b.SIGNAL_LOW),
        overspeed=bool(raw & b.OVERSPEED),
        hardware_error=bool(raw & b.HARDWARE_ERROR),
        raw=raw,
    )


def find_frame(line: bytes) -> ep.Reply:
    """The valid frame in one line (without CR LF), skipping noise before it.

    Raises ``ep.FrameError`` (the first candidate's error: usually the checksum) when the
    line holds no valid frame.
    """
    first_error: ep.FrameError | None = None
    for i, byte in enumerate(line):
        if byte in b"PIE":
            try:
                return ep.parse_frame(line[i:])
            except ep.FrameError as exc:
                first_error = first_error or exc
    raise first_error or ep.FrameError(f"no frame in {line[:ep.MAX_REPLY_BYTES]!r}")


class SerialGratingEncoder(PositionEncoder):
    """A grating read head answering ``?P`` with its count (``resolution_um`` per count)."""

    def __init__(
        self,
        port: str | None = None,
        *,
        baudrate: int = 115200,
        resolution_um: float = 0.05,
        timeout_s: float = 0.2,
        retries: int = 2,
        strict: bool = True,
        transport: SerialTransport | None = None,
        name: str = "encoder",
    ):
        if port is None and transport is None:
            raise ValueError("give a serial port path or a transport")
        if resolution_um <= 0:
            raise ValueError("resolution_um must be positive")
        self.port = port
        self.baudrate = int(baudrate)
        self.resolution_um = float(resolution_um)
        self.timeout_s = float(timeout_s)
        self.retries = int(retries)
        #: raise DriveFault when the head flags a problem (signal low, overspeed, hardware)
        self.strict = strict
        self.name = name
        self._transport: SerialTransport | None = transport
        self._owns_transport = transport is None
        self._lock = threading.Lock()
        self.identity: str | None = None
        #: answer lines still owed by timed-out queries: each may be on its way, and the
        #: protocol has no sequence number to tell it from the next query's. Before the
        #: next query the owed lines must have arrived and the line been quiet for
        #: ``quiet_s``, or ``late_reply_s`` have passed since the last timed-out query
        #: was sent (an answer later than that counts as lost).
        self._owed = 0
        self._owed_sent = 0.0
        self.quiet_s = 2.0 * self.timeout_s
        self.late_reply_s = 5.0 * self.timeout_s

    # ------------------------------------------------------------------ link

    def _open_sync(self) -> SerialTransport:
        if self._transport is not None:
            return self._transport
        try:
            self._transport = serial.Serial(
                self.port, baudrate=self.baudrate, timeout=READ_CHUNK_TIMEOUT_S, write_timeout=self.timeout_s
            )
        except (serial.SerialException, OSError) as exc:
            raise CommunicationLost(f"cannot open {self.port}: {exc}", self.name) from None
        return self._transport

    def _drop_sync(self) -> None:
        if self._transport is not None and self._owns_transport:
            try:
                self._transport.close()
            except Exception:  # noqa: BLE001 - the port is already broken
                pass
            self._transport = None

    async def connect(self) -> None:
        """Open the port and ask the head who it is (proves it answers)."""
        reply = await self._run(ep.IDENTITY_QUERY, "I")
        self.identity = reply.text

    async def close(self) -> None:
        await asyncio.to_thread(self._close_sync)

    def _close_sync(self) -> None:
        with self._lock:
            if self._transport is not None:
                try:
                    self._transport.close()
                except Exception:  # noqa: BLE001
                    pass
                self._transport = None

    # ------------------------------------------------------------------ framing

    def _read_line(self, t: SerialTransport, deadline: float) -> bytes:
        """Bytes up to CR LF (exclusive); DeviceTimeout at the deadline."""
        buf = b""
        while True:
            # one byte blocks until the reply starts (or the chunk timeout), then take what
            # has arrived: a fixed-size read would wait out the timeout on every short reply
            chunk = t.read(1)
            if chunk:
                waiting = getattr(t, "in_waiting", 0)
                if waiting:
                    chunk += t.read(min(waiting, ep.MAX_REPLY_BYTES))
                buf += chunk
                nl = buf.find(b"\n")
                if nl >= 0:
                    # bytes after the terminator belong to nothing we asked: dropped
                    return buf[:nl].rstrip(b"\r")
                if len(buf) > 2 * ep.MAX_REPLY_BYTES:
                    buf = buf[-ep.MAX_REPLY_BYTES :]  # a flood of noise: keep only a frame's worth
            if time.monotonic() >= deadline:
                what = f"partial reply {buf[-ep.MAX_REPLY_BYTES:]!r}" if buf else "no reply"
                raise DeviceTimeout(f"{what} within {self.timeout_s} s", self.name)

    def _discard_late_answers(self, t: SerialTransport) -> None:
        """Discard late answers to timed-out queries: wait until every owed line has
        arrived and the line has then been quiet for ``quiet_s``, at most until
        ``late_reply_s`` after the last timed-out query was sent. A late answer taken
        for the next query's would be a reading attributed to the wrong moment; a quiet
        spell alone is not proof, since a slow head answers after any fixed gap."""
        end = self._owed_sent + self.late_reply_s
        now = time.monotonic()
        quiet_until = now + self.quiet_s
        while now < end and (self._owed > 0 or now < quiet_until):
            chunk = t.read(1)
            if chunk:
                waiting = getattr(t, "in_waiting", 0)
                if waiting:
                    chunk += t.read(min(waiting, 4096))
                self._owed -= chunk.count(b"\n")
                quiet_until = time.monotonic() + self.quiet_s
            now = time.monotonic()
        self._owed = 0

    def _query_once(self, query: bytes, kind: str) -> tuple[ep.Reply, float]:
        t = self._open_sync()
        try:
            if self._owed > 0:
                self._discard_late_answers(t)
            t.reset_input_buffer()
            t_sent = time.monotonic()
            t.write(query)
            try:
                line = self._read_line(t, t_sent + self.timeout_s)
            except DeviceTimeout:
                self._owed += 1
                self._owed_sent = t_sent
                raise
            t_received = time.monotonic()
        except (serial.SerialException, OSError) as exc:
            self._drop_sync()
            raise CommunicationLost(f"serial I/O failed: {exc}", self.name) from None
        try:
            reply = find_frame(line)
        except ep.FrameError as exc:
            raise ProtocolError(str(exc), self.name) from None
        if reply.kind == "E":
            raise ProtocolError(f"the head answered error {reply.error_code:02X} to {query!r}", self.name)
        if reply.kind != kind:
            raise ProtocolError(f"expected a {kind!r} reply to {query!r}, got {reply.kind!r}", self.name)
        # the head latched its count between our write and its reply: the midpoint is the
        # best estimate of that instant (error at most half the round trip)
        return reply, 0.5 * (t_sent + t_received)

    def _query_sync(self, query: bytes, kind: str) -> tuple[ep.Reply, float]:
        with self._lock:
            last: Exception | None = None
            for _ in range(1 + self.retries):
                try:
                    return self._query_once(query, kind)
                except (DeviceTimeout, ProtocolError) as exc:
                    last = exc
            assert last is not None
            raise last

    async def _run(self, query: bytes, kind: str) -> ep.Reply:
        reply, _ = await asyncio.to_thread(self._query_sync, query, kind)
        return reply

    # ------------------------------------------------------------------ reading

    def counts_to_mm(self, counts: int) -> float:
        return counts * self.resolution_um / 1000.0  # um -> mm

    async def read(self) -> EncoderReading:
        reply, stamp = await asyncio.to_thread(self._query_sync, ep.POSITION_QUERY, "P")
        status = decode_status(reply.status)
        if self.strict and not status.ok:
            problems = [n for n, on in (("signal low", status.signal_low), ("overspeed", status.overspeed),
                                        ("hardware error", status.hardware_error)) if on]
            raise DriveFault(reply.status, "read head reports " + ", ".join(problems), self.name)
        return EncoderReading(self.counts_to_mm(reply.counts), stamp, status)
