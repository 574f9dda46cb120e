"""A test kit for drivers: a scripted device that checks every byte a driver sends.

In the manner of PyMeasure's ``expected_protocol`` (a driver tested by exact frames
taken from the manual), written for our asynchronous, socket-based drivers: the
device is a small asyncio server on 127.0.0.1 that holds a script of
``(bytes the driver must send, what the device answers)`` exchanges.  The driver is
built by the test against the device's address, exactly as it is built against a
real drive or a twin, so the bytes cross a real socket and the driver's own client
library (pymodbus) frames them: nothing of the driver is patched.

Any difference fails the test: a frame other than the script's next one, a frame
after the script's end (an extra request), an exchange the driver never made (a
missing request, found at the end), a connection the script did not announce.

The answer of an exchange is one of:

* ``bytes``: sent back whole;
* a ``list`` of ``bytes``: sent in pieces (a reply split across reads);
* :data:`SILENCE`: no answer at all (the driver's timeout);
* :data:`HANG_UP`: the device closes the connection instead of answering.

:data:`RECONNECT` as a script entry says "the driver opens a new connection here"
(the documented reaction of the Modbus driver to a timeout or a corrupt reply).

For Modbus RTU the device is reached through pyserial's ``socket://`` URL, which
pymodbus' serial client opens like a port; the bytes are the RTU frames with their
CRC, no MBAP.

Why here, beside the drivers, and not under tests/: the kit is the contract a new
driver (another drive vendor, an integrator's adapter) is tested against, as
PyMeasure ships ``pymeasure.test``; it imports nothing but the standard library (no
concrete driver, no pytest), so it costs the product nothing.  Frame builders (MBAP,
CRC) are deliberately *not* here: tests write their frames from the documents with
their own independent code, so the kit cannot agree with a driver by sharing a bug.
"""

from __future__ import annotations

import asyncio
import contextlib
from dataclasses import dataclass, field
from typing import Union


class _Marker:
    def __init__(self, name: str):
        self.name = name

    def __repr__(self) -> str:
        return self.name


#: the device does not answer this request
SILENCE = _Marker("SILENCE")
#: the device closes the connection instead of answering
HANG_UP = _Marker("HANG_UP")
#: script entry: the driver must open a (new) connection here
RECONNECT = _Marker("RECONNECT")

Answer = Union[bytes, list, _Marker]


class ProtocolMismatch(AssertionError):
    """The driver's bytes differ from the script (or the script was not used up)."""


def _hex(data: bytes) -> str:
    return data.hex(" ") if data else "(nothing)"


@dataclass
class ScriptedDevice:
    """A device on 127.0.0.1 that plays ``script`` and records what differs.

    ``script``: ``(expected bytes, answer)`` pairs and :data:`RECONNECT` markers.
    The first connection needs no marker.  ``frame_timeout_s``: how long a started
    frame may take to arrive whole before the device calls it short."""

    script: list
    frame_timeout_s: float = 1.0
    host: str = "127.0.0.1"
    port: int = 0
    #: every frame received, in order (for a test's own assertions)
    received: list[bytes] = field(default_factory=list)
    #: connections the driver opened
    connections: int = 0
    errors: list[str] = field(default_factory=list)

    def __post_init__(self):
        self._script = list(self.script)
        self._step = 0
        self._server: asyncio.AbstractServer | None = None
        self._handlers: set[asyncio.Task] = set()

    # ------------------------------------------------------------------ addresses

    @property
    def serial_url(self) -> str:
        """The device as a serial port for pyserial (``serial_for_url``): Modbus RTU."""
        return f"socket://{self.host}:{self.port}"

    # ------------------------------------------------------------------ lifecycle

    async def start(self) -> "ScriptedDevice":
        self._server = await asyncio.start_server(self._serve, self.host, self.port)
        self.port = self._server.sockets[0].getsockname()[1]
        return self

    async def stop(self) -> None:
        if self._server is not None:
            self._server.close()
        for task in list(self._handlers):
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
        if self._server is not None:
            with contextlib.suppress(Exception):
                await asyncio.wait_for(self._server.wait_closed(), 1.0)
            self._server = None

    async def __aenter__(self) -> "ScriptedDevice":
        return await self.start()

    async def __aexit__(self, *exc) -> None:
        await self.stop()

    # ------------------------------------------------------------------ checking

    @property
    def remaining(self) -> list:
        """The script entries not played yet."""
        return self._script[self._step:]

    def fail(self, text: str) -> None:
        self.errors.append(text)

    def assert_done(self) -> None:
        """Fail on any difference seen, or on exchanges the driver never made."""
        if self.errors:
            raise ProtocolMismatch("; ".join(self.errors))
        if self.remaining:
            rest = ", ".join(repr(e) if isinstance(e, _Marker) else _hex(e[0]) for e in self.remaining)
            raise ProtocolMismatch(f"{len(self.remaining)} expected exchange(s) never made: {rest}")

    # ------------------------------------------------------------------ serving

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        self._handlers.add(task)
        self.connections += 1
        try:
            if self.connections > 1:
                if self._step < len(self._script) and self._script[self._step] is RECONNECT:
                    self._step += 1
                else:
                    self.fail(f"unexpected connection #{self.connections} at script step {self._step}")
                    return
            elif self._step < len(self._script) and self._script[self._step] is RECONNECT:
                self._step += 1  # a RECONNECT before the first request is the first connection
            await self._play(reader, writer)
        except (ConnectionError, asyncio.IncompleteReadError):
            pass
        finally:
            self._handlers.discard(task)
            with contextlib.suppress(Exception):
                writer.close()

    async def _play(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        buf = b""
        while True:
            entry = self._script[self._step] if self._step < len(self._script) else None
            if entry is RECONNECT:
                # the driver must drop this link; bytes on it now are an error
                extra = await reader.read(4096)
                if extra:
                    self.fail(f"sent {_hex(extra)} on the old connection where the script expects a reconnect")
                return
            chunk = await reader.read(4096)
            if not chunk:
                if buf:
                    self.fail(f"connection closed after a partial frame {_hex(buf)}")
                return
            buf += chunk
            while buf:
                entry = self._script[self._step] if self._step < len(self._script) else None
                if entry is None:
                    self.received.append(buf)
                    self.fail(f"extra frame after the script's end: {_hex(buf)}")
                    return
                if entry is RECONNECT:
                    self.fail(f"sent {_hex(buf)} where the script expects a reconnect")
                    return
                expected, answer = entry
                if buf[:len(expected)] != expected[:len(buf)]:
                    self.received.append(buf)
                    self.fail(f"step {self._step}: expected {_hex(expected)}, got {_hex(buf[:len(expected)])}")
                    return
                if len(buf) < len(expected):
                    try:
                        more = await asyncio.wait_for(reader.read(4096), self.frame_timeout_s)
                    except asyncio.TimeoutError:
                        more = b""
                    if not more:
                        self.received.append(buf)
                        self.fail(f"step {self._step}: short frame {_hex(buf)}, expected {_hex(expected)}")
                        return
                    buf += more
                    continue
                frame, buf = buf[:len(expected)], buf[len(expected):]
                self.received.append(frame)
                self._step += 1
                if answer is HANG_UP:
                    return
                if answer is SILENCE:
                    continue
                for piece in (answer if isinstance(answer, list) else [answer]):
                    writer.write(piece)
                    await writer.drain()
                    if isinstance(answer, list):
                        await asyncio.sleep(0.002)  # let each piece arrive as its own read


@contextlib.asynccontextmanager
async def expected_protocol(make_driver, script: list, *, rtu: bool = False, connect: bool = False,
                            frame_timeout_s: float = 1.0):
    """Run a driver against :class:`ScriptedDevice` and check the whole script.

    ``make_driver(address)`` builds the driver: ``address`` is ``(host, port)`` for
    TCP, the ``socket://`` URL for RTU (``rtu=True``).  ``connect``: await the
    driver's ``connect()`` first (its frames are then the script's first).  On leaving
    the block the driver's ``close()`` is awaited and any difference, extra or
    missing frame fails with :class:`ProtocolMismatch`."""
    device = ScriptedDevice(script, frame_timeout_s=frame_timeout_s)
    await device.start()
    driver = None
    try:
        driver = make_driver(device.serial_url if rtu else (device.host, device.port))
        try:
            if connect:
                await driver.connect()
            yield driver
        except BaseException as exc:
            # the driver's error is often only the echo of a frame the device refused
            if device.errors:
                raise ProtocolMismatch("; ".join(device.errors)) from exc
            raise
        # let the last reply's bytes and any stray request reach the device
        await asyncio.sleep(0.02)
    finally:
        if driver is not None and hasattr(driver, "close"):
            with contextlib.suppress(Exception):
                await driver.close()
        await device.stop()
    device.assert_done()
