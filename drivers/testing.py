"""A test kit for drivers: a scripted device that checks every byte a driver sends,
and an instant mock axis for the tests of everything above the drivers.

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

:class:`InstantMockAxis` (:class:`InstantMockLinearAxis` in mm,
:class:`InstantMockRotaryAxis` in deg) is the other half: a complete
:class:`~drivers.interfaces.ServoAxis` without a drive, in the manner of
ophyd-async's instant-move mock (the readback arrives at the setpoint at once). It
moves instantly or after ``delay_s``, can hold a move until released, records every
call, and fails a call with a given :class:`~drivers.interfaces.DriverError` when a
test says so (:meth:`InstantMockAxis.fail`), or latches a drive fault
(:meth:`InstantMockAxis.trip`): fault injection without monkeypatching.

Why here, beside the drivers, and not under tests/: the kit is the contract a new
driver (another drive vendor, an integrator's adapter) is tested against, as
PyMeasure ships ``pymeasure.test``; it imports nothing but the standard library and
``drivers.interfaces`` (no concrete driver, no pytest), so it costs the product
nothing.  Frame builders (MBAP, CRC) are deliberately *not* here: tests write their
frames from the documents with their own independent code, so the kit cannot agree
with a driver by sharing a bug.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from dataclasses import dataclass, field
from typing import Union

from drivers.interfaces import (
    UNITS,
    AxisStatus,
    DeviceTimeout,
    DriveFault,
    DriverError,
    FollowingError,
    LinearAxis,
    RotaryAxis,
    ServoAxis,
)


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


# =========================================================================== mock axis

#: the calls an :class:`InstantMockAxis` records and can be told to fail
AXIS_METHODS = ("connect", "close", "enable", "home", "move_to", "wait_in_position", "status",
                "read_position", "stop", "reset_fault")
#: FaultCode.FOLLOWING_ERROR of docs/register-map.md (the kit does not import the map)
_FOLLOWING_ERROR_CODE = 0x0010


@dataclass
class AxisCall:
    """One call an :class:`InstantMockAxis` received: its arguments (``args``, bound to
    the method's parameters in order), when it started and ended (``time.monotonic``;
    ``ended`` None while running or if it raised) and the error it raised, if any."""

    axis: str
    method: str
    args: tuple
    started: float
    ended: float | None = None
    error: BaseException | None = None


@dataclass
class _Move:
    start: float
    target: float
    arrives: float  # time.monotonic() of arrival (held moves: when released, at the earliest)


class InstantMockAxis(ServoAxis):
    """A servo axis that needs no drive: moves end at once (or after ``delay_s``).

    State as a real axis keeps it: ``enabled`` (a move is refused while off, as the
    Modbus driver refuses it), ``homed`` (after :meth:`home`, which moves to 0),
    ``position`` (the readback; a test may set it to place the axis), the
    :attr:`setpoint` (None after a stop). During a delayed or held move the status says
    ``moving`` and the readback stays at the start; it jumps to the target on arrival.

    For tests:

    * ``calls`` -- every :class:`AxisCall`, in order (``journal``: a list shared by
      several axes, to see their calls interleaved); :meth:`calls_to`, :meth:`count`;
    * :meth:`fail` -- the next call(s) of a method raise the given ``DriverError``;
    * :meth:`trip` -- a latched drive fault (status shows it, moves and waits raise
      it) until :meth:`reset_fault`, which leaves the axis disabled like a real drive;
    * :meth:`hold` / :meth:`release` -- moves do not arrive until released (an abort
      test's "the move never ends by itself"); :meth:`stop` ends a held move too.
    """

    def __init__(self, name: str = "Z", units: str | None = None, *, position: float = 0.0,
                 delay_s: float = 0.0, default_velocity: float | None = None,
                 default_acceleration: float | None = None, velocity_limit: float | None = None,
                 acceleration_limit: float | None = None, poll_s: float = 0.0,
                 journal: list[AxisCall] | None = None):
        fixed = type(self).units
        if units is None:
            units = fixed or "mm"
        if units not in UNITS:
            raise ValueError(f"units must be one of {UNITS}, not {units!r}")
        if fixed and units != fixed:
            raise ValueError(f"{type(self).__name__} moves in {fixed}, not {units}")
        if delay_s < 0:
            raise ValueError("delay_s must be >= 0")
        self.name = name
        self.units = units
        self.position = float(position)
        self.delay_s = float(delay_s)
        self.default_velocity = default_velocity
        self.default_acceleration = default_acceleration
        self.velocity_limit = velocity_limit
        self.acceleration_limit = acceleration_limit
        self.poll_s = float(poll_s)
        self.enabled = False
        self.homed = False
        self.connected = False
        self.fault_code = 0
        self.fault_text = ""
        self._setpoint = None
        self._move: _Move | None = None
        self._held = False
        self._wake: asyncio.Event | None = None  # set when a move ends or is released
        self._wake_loop: asyncio.AbstractEventLoop | None = None
        self._failures: dict[str, list[list]] = {}
        self.calls: list[AxisCall] = []
        self.journal = journal

    # ------------------------------------------------------------------ for tests

    def fail(self, method: str, error: DriverError | type[DriverError], *, times: int | None = 1) -> None:
        """The next ``times`` calls of ``method`` (every call when None, until
        :meth:`clear_failures`) raise ``error``: an instance, or a ``DriverError``
        class (built with a message naming the call; ``FollowingError`` with its
        code; a plain ``DriveFault`` needs an instance, for its code). Failures queue:
        a second ``fail`` acts after the first is used up."""
        if method not in AXIS_METHODS:
            raise ValueError(f"{method!r} is not an axis call ({', '.join(AXIS_METHODS)})")
        is_class = isinstance(error, type)
        if not (issubclass(error, DriverError) if is_class else isinstance(error, DriverError)):
            raise TypeError(f"an injected failure is a DriverError, not {error!r}")
        if is_class and issubclass(error, DriveFault) and not issubclass(error, FollowingError):
            raise TypeError("give a DriveFault as an instance, with its code: DriveFault(0x0020, 'overcurrent')")
        if times is not None and times < 1:
            raise ValueError("times must be >= 1 (or None: always)")
        self._failures.setdefault(method, []).append([error, times])

    def clear_failures(self, method: str | None = None) -> None:
        """Forget the failures set for ``method`` (all methods when None)."""
        if method is None:
            self._failures.clear()
        else:
            self._failures.pop(method, None)

    def trip(self, code: int, text: str = "injected drive fault") -> None:
        """Latch a drive fault, as a drive does: the axis stops where it is and is
        disabled; status reports it; ``home``, ``move_to`` and ``wait_in_position``
        raise it (``FollowingError`` for code 0x0010) until :meth:`reset_fault`."""
        if not code:
            raise ValueError("a drive fault has a non-zero code")
        self._end_move(arrived=False)
        self.fault_code, self.fault_text = int(code), text
        self.enabled = False

    def hold(self) -> None:
        """From now on moves do not arrive until :meth:`release` (or :meth:`stop`)."""
        self._held = True

    def release(self) -> None:
        """Let held moves arrive (after what is left of ``delay_s``)."""
        self._held = False
        self._poke()

    def calls_to(self, method: str) -> list[AxisCall]:
        """The calls of ``method`` received so far."""
        return [c for c in self.calls if c.method == method]

    def count(self, method: str) -> int:
        return len(self.calls_to(method))

    # ------------------------------------------------------------------ bookkeeping

    def _record(self, method: str, *args) -> AxisCall:
        call = AxisCall(self.name, method, args, time.monotonic())
        self.calls.append(call)
        if self.journal is not None:
            self.journal.append(call)
        queue = self._failures.get(method)
        if queue:
            entry = queue[0]
            error, times = entry
            if times is not None:
                entry[1] -= 1
                if entry[1] <= 0:
                    queue.pop(0)
            if isinstance(error, type):
                error = (error(_FOLLOWING_ERROR_CODE, "injected following error", self.name)
                         if issubclass(error, FollowingError) else error(f"{method}: injected failure", self.name))
            call.error = error
            raise error
        return call

    @staticmethod
    def _done(call: AxisCall, value=None):
        call.ended = time.monotonic()
        return value

    def _raise_fault(self, call: AxisCall) -> None:
        if self.fault_code:
            cls = FollowingError if self.fault_code == _FOLLOWING_ERROR_CODE else DriveFault
            call.error = cls(self.fault_code, self.fault_text, self.name)
            raise call.error

    def _poke(self) -> None:
        """Wake every wait in progress (they look again at the move)."""
        ev, self._wake = self._wake, None
        if ev is not None:
            ev.set()

    def _wake_event(self) -> asyncio.Event:
        loop = asyncio.get_running_loop()
        if self._wake is None or self._wake_loop is not loop:  # an axis may outlive a loop
            self._wake, self._wake_loop = asyncio.Event(), loop
        return self._wake

    def _advance(self) -> None:
        """Let a move whose time has come arrive."""
        mv = self._move
        if mv is not None and not self._held and time.monotonic() >= mv.arrives:
            self._end_move(arrived=True)

    def _end_move(self, *, arrived: bool) -> None:
        mv, self._move = self._move, None
        if mv is not None and arrived:
            self.position = mv.target
        self._poke()

    def _start_move(self, target: float) -> None:
        self._end_move(arrived=False)  # a new target replaces the old one
        self._move = _Move(self.position, float(target), time.monotonic() + self.delay_s)
        self._setpoint = float(target)
        self._advance()

    @property
    def moving(self) -> bool:
        self._advance()
        return self._move is not None

    def snapshot(self) -> AxisStatus:
        """The status now (what :meth:`status` returns, without recording a call)."""
        moving = self.moving
        fault = bool(self.fault_code)
        return AxisStatus(
            ready=not fault, enabled=self.enabled, moving=moving,
            in_position=self.enabled and not moving and not fault,
            homed=self.homed, fault=fault, following_error=self.fault_code == _FOLLOWING_ERROR_CODE,
            estop=False, fault_code=self.fault_code, position=self.position, velocity=0.0,
        )

    # ------------------------------------------------------------------ the axis

    async def connect(self) -> None:
        call = self._record("connect")
        self.connected = True
        self._done(call)

    async def close(self) -> None:
        call = self._record("close")
        self.connected = False
        self._done(call)

    async def enable(self, on: bool = True) -> None:
        call = self._record("enable", on)
        # a drive ignores ENABLE while a fault is active
        self.enabled = bool(on) and not self.fault_code
        self._done(call)

    async def home(self) -> None:
        call = self._record("home")
        self._raise_fault(call)
        if not self.enabled:
            call.error = DriverError("homing refused: drive not enabled", self.name)
            raise call.error
        self._start_move(0.0)
        self.homed = True
        self._done(call)

    async def move_to(self, position: float, velocity: float | None = None,
                      acceleration: float | None = None) -> None:
        call = self._record("move_to", position, velocity, acceleration)
        self._raise_fault(call)
        if not self.enabled:
            call.error = DriverError("move refused: drive not enabled", self.name)
            raise call.error
        self._start_move(position)
        self._done(call)

    async def wait_in_position(self, timeout: float) -> AxisStatus:
        call = self._record("wait_in_position", timeout)
        deadline = time.monotonic() + timeout
        while True:
            self._raise_fault(call)
            if not self.moving:
                return self._done(call, self.snapshot())
            now = time.monotonic()
            if now >= deadline:
                call.error = DeviceTimeout(f"not in position after {timeout} s (at {self.position:.6f} "
                                           f"{self.units}, moving=True)", self.name)
                raise call.error
            wake_at = deadline if self._held else min(deadline, self._move.arrives)
            wake = self._wake_event()
            with contextlib.suppress(asyncio.TimeoutError):
                await asyncio.wait_for(wake.wait(), max(0.0, wake_at - now))

    async def status(self) -> AxisStatus:
        call = self._record("status")
        return self._done(call, self.snapshot())

    async def read_position(self) -> float:
        call = self._record("read_position")
        self._advance()
        return self._done(call, self.position)

    async def stop(self) -> None:
        call = self._record("stop")
        self._setpoint = None  # the axis rests short of the target by design
        self._end_move(arrived=False)
        self._done(call)

    async def reset_fault(self) -> None:
        call = self._record("reset_fault")
        # a fault leaves the axis disabled; the caller enables it again deliberately
        self.fault_code, self.fault_text = 0, ""
        self.enabled = False
        self._done(call)


class InstantMockLinearAxis(InstantMockAxis, LinearAxis):
    """An :class:`InstantMockAxis` in mm (a ``LinearAxis``: the Z stage's place)."""


class InstantMockRotaryAxis(InstantMockAxis, RotaryAxis):
    """An :class:`InstantMockAxis` in deg (a ``RotaryAxis``: the C table's place)."""
