"""A servo drive on Modbus (TCP or RTU): the Z stage and the C table.

One class serves both axes; they differ only in unit, scaling (``unit_per_count``:
e.g. 1e-4 mm = 0.1 um per count for Z, 1e-4 deg per count for C) and device id.
The register map is ``drivers.interfaces.register_map`` (docs/register-map.md): a
declaration of fields (address, width, signedness, scale) that decodes the status
snapshot and encodes a move, so no register is split or joined by hand here.

Uses pymodbus 3.x's current async client API (checked against 3.16):
``AsyncModbusTcpClient(host, port=, timeout=, retries=, reconnect_delay=)``,
``AsyncModbusSerialClient(port, baudrate=, ...)`` and
``read_holding_registers(address, count=, device_id=)`` /
``write_registers(address, values, device_id=)`` (``device_id`` replaced ``slave``).

Error policy: every request is bounded by ``timeout_s``; after a timeout or a
malformed reply the link is closed, and the next call reconnects.  Closing a serial
port does not stop a late answer, though: the drive's reply to a request that timed
out still comes down the line (RTU has no transaction id), and would be taken for the
reply to the next request.  So a reply must answer its request (function, address,
count); one that answers an earlier request is dropped, the line is let go quiet (this
request's own reply then falls on no request and is dropped too), and a read, or a
write of values, is sent once more; a command (a self-clearing bit) is not, since it
may have acted.  Requests, the heartbeat's too, take the link one at a time, so no
request is sent on a link another is about to close.  pymodbus' own background
reconnection is switched off (``reconnect_delay=0``) so that the driver alone
decides when to reconnect.  Repeating a lost connect is the caller's: the sequencer's
retries while it runs, ``Station.connect`` at start.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from typing import Awaitable, Callable

from pymodbus.client import AsyncModbusSerialClient, AsyncModbusTcpClient
from pymodbus.exceptions import ConnectionException, ModbusException, ModbusIOException

from drivers.interfaces import (
    AxisStatus,
    CommunicationLost,
    DeviceTimeout,
    DriveFault,
    DriverError,
    FollowingError,
    LinearAxis,
    MoveInterrupted,
    ProtocolError,
    RotaryAxis,
    ServoAxis,
)
from drivers.interfaces import register_map as rm

log = logging.getLogger(__name__)


class _NoFrameDump(logging.Filter):
    """Cuts pymodbus' frame dump off its error records. When pymodbus does not log at
    DEBUG it keeps its last 20 frames (class-wide: every Modbus link of the process, the
    twins' too) and appends them to every error and critical message as ``>>>>> send:
    ...`` lines, so a one-line error takes 21 lines, and its frames are mostly other
    links' than the one that failed. The record keeps its first line and says how many
    frames were cut; pymodbus at DEBUG (``logging.getLogger("pymodbus").setLevel``)
    logs every frame as it goes instead."""

    MARK = "\n>>>>> "

    def filter(self, record: logging.LogRecord) -> bool:
        msg = record.msg
        if isinstance(msg, str) and self.MARK in msg:
            head, _, _ = msg.partition(self.MARK)
            n = msg.count(self.MARK)
            record.msg = f"{head} ({n} frame{'s' if n != 1 else ''} of pymodbus' process-wide dump cut: " \
                         f"log pymodbus at DEBUG for every frame)"
        return True


def _quiet_frame_dumps() -> None:
    """Puts ``_NoFrameDump`` on pymodbus' logger once per process."""
    target = logging.getLogger("pymodbus.logging")
    if not any(type(f).__name__ == _NoFrameDump.__name__ for f in target.filters):  # a module reloaded too
        target.addFilter(_NoFrameDump())


_quiet_frame_dumps()

#: how often wait_in_position polls the status word; 20 ms is well below a move's
#: duration and keeps the bus load at 50 requests/s per axis
DEFAULT_POLL_S = 0.02
#: polls in a row at rest short of the target before a move counts as interrupted
#: (10 x 20 ms: far longer than a drive takes to raise MOVING after START)
RESTING_SHORT_POLLS = 10
#: how often a request in flight checks its link (closed by the peer, corrupt reply)
LINK_WATCH_S = 0.005
#: bytes came back but no valid reply was made of them this long after: corrupt
CORRUPT_REPLY_GRACE_S = 0.05
#: after a late reply to an earlier request: the line counts as quiet once no byte came
#: for this long (over 3.5 characters, the RTU frame gap, down to 2400 baud)
QUIET_GAP_S = 0.02
#: the Modbus functions the driver uses, as a reply names them
FC_READ_HOLDING = 3
FC_WRITE_MULTIPLE = 16


def _describe_reply(response) -> str:
    """What a reply answers, for an error's message: its function and its registers'
    count, or the address and count a write echoes."""
    fc = getattr(response, "function_code", None)
    if fc == FC_WRITE_MULTIPLE:
        return f"function 16, a write of {getattr(response, 'count', '?')} @ {getattr(response, 'address', '?')}"
    return f"function {fc}, {len(getattr(response, 'registers', ()) or ())} registers"


class _CorruptReply(Exception):
    """Bytes arrived for the request in flight, but pymodbus made no reply of them."""


class ModbusServoAxis(ServoAxis):
    """Drives one servo axis over Modbus.  Build it with :meth:`tcp` or :meth:`rtu`."""

    def __init__(
        self,
        client_factory: Callable[[], AsyncModbusTcpClient | AsyncModbusSerialClient],
        *,
        name: str,
        device_id: int,
        unit_per_count: float,
        default_velocity: float,
        default_acceleration: float,
        timeout_s: float = 0.5,
        #: the drive stops the axis when no heartbeat came for this long: 1 s, ten
        #: heartbeats, so a loaded station PC (a garbage collection, a busy core) does
        #: not stop a healthy scan, while a dead controller still stops the axis in 1 s
        watchdog_timeout_ms: int = 1000,
        heartbeat_period_s: float = 0.1,
        following_error_limit: float | None = None,
        in_position_window: float | None = None,
        velocity_limit: float | None = None,
        acceleration_limit: float | None = None,
        poll_s: float = DEFAULT_POLL_S,
    ):
        if unit_per_count <= 0:
            raise ValueError("unit_per_count must be positive")
        if watchdog_timeout_ms and heartbeat_period_s * 1000.0 * 2 > watchdog_timeout_ms:
            # two heartbeats per watchdog period at least, or one late write faults the drive
            raise ValueError("heartbeat_period_s must be at most half the watchdog timeout")
        self._client_factory = client_factory
        self._client: AsyncModbusTcpClient | AsyncModbusSerialClient | None = None
        self._rx_since_send: float | None = None
        self._last_rx = 0.0  # when bytes last came in (the quiet wait after a stale reply)
        self._link_lock = asyncio.Lock()
        #: replies that answered an earlier request (late ones), dropped
        self.stale_replies = 0
        self.name = name
        self.device_id = int(device_id)
        self.unit_per_count = float(unit_per_count)
        self.default_velocity = float(default_velocity)
        self.default_acceleration = float(default_acceleration)
        #: what the station may command for a scan (the integrator's limits); the
        #: defaults when the config names none
        self.velocity_limit = float(velocity_limit) if velocity_limit is not None else self.default_velocity
        self.acceleration_limit = (float(acceleration_limit) if acceleration_limit is not None
                                   else self.default_acceleration)
        if not (self.velocity_limit > 0 and self.acceleration_limit > 0 and poll_s > 0):
            raise ValueError("velocity_limit, acceleration_limit and poll_s must be positive")
        self.poll_s = float(poll_s)
        self.timeout_s = float(timeout_s)
        self.watchdog_timeout_ms = int(watchdog_timeout_ms)
        self.heartbeat_period_s = float(heartbeat_period_s)
        self.following_error_limit = following_error_limit
        #: tolerance of wait_in_position on the reported position (default: 2 counts)
        self.in_position_window = in_position_window if in_position_window is not None else 2 * unit_per_count
        self._control = 0  # shadow of the level bits of the control word (ENABLE)
        self._heartbeat_task: asyncio.Task | None = None
        self._heartbeat_counter = 0
        self._setpoint: float | None = None  # the public ``setpoint`` (ServoAxis)
        self.firmware_id: int | None = None
        #: the last error the background heartbeat met (None while it succeeds)
        self.heartbeat_error: DriverError | None = None

    # ------------------------------------------------------------------ factories

    @classmethod
    def tcp(cls, host: str, port: int, **kw) -> "ModbusServoAxis":
        timeout_s = kw.get("timeout_s", 0.5)

        def factory(trace_packet=None):
            # retries=0: the driver, not pymodbus, decides about repeating a request
            return AsyncModbusTcpClient(host, port=port, timeout=timeout_s, retries=0, reconnect_delay=0,
                                        trace_packet=trace_packet)

        factory.accepts_trace = True
        return cls(factory, **kw)

    @classmethod
    def rtu(cls, serial_port: str, baudrate: int = 115200, **kw) -> "ModbusServoAxis":
        timeout_s = kw.get("timeout_s", 0.5)

        def factory(trace_packet=None):
            return AsyncModbusSerialClient(
                serial_port, baudrate=baudrate, timeout=timeout_s, retries=0, reconnect_delay=0,
                trace_packet=trace_packet,
            )

        factory.accepts_trace = True
        return cls(factory, **kw)

    # ------------------------------------------------------------------ scaling

    def to_counts(self, position: float) -> int:
        return int(round(position / self.unit_per_count))

    def from_counts(self, counts: int) -> float:
        return counts * self.unit_per_count

    # ------------------------------------------------------------------ link

    async def _ensure_connected(self):
        if self._client is not None and self._client.connected:
            return self._client
        self._drop_client()
        if getattr(self._client_factory, "accepts_trace", False):
            client = self._client_factory(trace_packet=self._trace_packet)
        else:
            client = self._client_factory()
        self._rx_since_send = None
        try:
            ok = await asyncio.wait_for(client.connect(), self.timeout_s)
        except (asyncio.TimeoutError, OSError, ModbusException) as exc:
            client.close()
            reason = str(exc) or f"no connection within {self.timeout_s} s"
            raise CommunicationLost(f"cannot connect: {reason}", self.name) from None
        if not ok:
            client.close()
            raise CommunicationLost("cannot connect (refused or port missing)", self.name)
        self._client = client
        return client

    def _trace_packet(self, sending: bool, data: bytes) -> bytes:
        """pymodbus' hook on every frame sent and every chunk received: notes when bytes
        came back for the request in flight (a reply pymodbus then discards as corrupt
        leaves it waiting for its timeout; the watch in :meth:`_await_reply` does not)."""
        if sending:
            self._rx_since_send = None
        elif data:
            self._last_rx = time.monotonic()
            if self._rx_since_send is None:
                self._rx_since_send = self._last_rx
        return data

    async def _await_reply(self, client, call: Callable[[object], Awaitable]):
        """The request, watched: a link the peer closed, or bytes that arrived but made no
        reply (garbage, a bad checksum) end it at once, instead of after the full timeout
        -- during which the request would hold the link and starve the heartbeat until the
        drive's watchdog trips."""
        task = asyncio.ensure_future(call(client))
        grace = max(CORRUPT_REPLY_GRACE_S, 0.1 * self.timeout_s)
        try:
            while True:
                done, _ = await asyncio.wait({task}, timeout=LINK_WATCH_S)
                if done:
                    return task.result()
                if not client.connected:
                    raise ConnectionException("connection closed by the drive")
                rx = self._rx_since_send
                if rx is not None and time.monotonic() - rx > grace:
                    raise _CorruptReply("a reply arrived but was not a valid frame (garbage or bad checksum)")
        finally:
            if not task.done():
                task.cancel()
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await task

    def _drop_client(self, client=None) -> None:
        """Close ``client`` (default: the current one). A request that failed on an old
        client (the heartbeat's, timing out late) must not close the fresh client
        another request has opened since."""
        target = self._client if client is None else client
        if target is None:
            return
        with contextlib.suppress(Exception):
            target.close()
        if self._client is target:
            self._client = None

    async def _request(self, what: str, call: Callable[[object], Awaitable],
                       answers: Callable[[object], bool] | None = None, repeatable: bool = True):
        """Run one Modbus request with the driver's timeout and error mapping, holding
        the link.  ``answers`` tells whether a reply answers this request; one that does
        not is a late reply to an earlier request (see the module's error policy)."""
        async with self._link_lock:
            response = await self._exchange(what, call)
            if answers is None or answers(response):
                return response
            self.stale_replies += 1
            log.warning("%s: %s: dropped a reply to an earlier request (it came late)", self.name, what)
            await self._quiet()
            if not repeatable:
                raise ProtocolError(
                    f"{what}: the reply answered an earlier request ({_describe_reply(response)}); "
                    "not sent again, as it may have acted",
                    self.name,
                )
            response = await self._exchange(what, call)
            if answers(response):
                return response
            self._drop_client()
            raise ProtocolError(f"{what}: two replies running answered other requests (the last: "
                                f"{_describe_reply(response)})", self.name)

    async def _quiet(self) -> None:
        """Wait until this request's own reply has come and gone (it falls on no request
        and is dropped): bytes in after the stale reply, then a gap of ``QUIET_GAP_S``;
        at most ``timeout_s``."""
        start = time.monotonic()
        while time.monotonic() - start < self.timeout_s:
            await asyncio.sleep(QUIET_GAP_S / 2)
            if self._last_rx > start and time.monotonic() - self._last_rx >= QUIET_GAP_S:
                return

    async def _exchange(self, what: str, call: Callable[[object], Awaitable]):
        client = await self._ensure_connected()
        try:
            # a small margin over pymodbus' own timeout, so its error (more precise) wins
            response = await asyncio.wait_for(self._await_reply(client, call), self.timeout_s * 1.5)
        except _CorruptReply as exc:
            self._drop_client(client)
            raise ProtocolError(f"{what}: {exc}", self.name) from None
        except asyncio.TimeoutError:
            self._drop_client(client)
            raise DeviceTimeout(f"{what}: no reply within {self.timeout_s} s", self.name) from None
        except ConnectionException as exc:
            self._drop_client(client)
            raise CommunicationLost(f"{what}: {exc}", self.name) from None
        except ModbusIOException as exc:
            lost = not client.connected
            self._drop_client(client)
            if lost:
                raise CommunicationLost(f"{what}: connection lost ({exc})", self.name) from None
            if "No response" in str(exc):
                raise DeviceTimeout(f"{what}: no reply within {self.timeout_s} s", self.name) from None
            raise ProtocolError(f"{what}: {exc}", self.name) from None
        except ModbusException as exc:
            self._drop_client(client)
            raise ProtocolError(f"{what}: {exc}", self.name) from None
        except OSError as exc:
            self._drop_client(client)
            raise CommunicationLost(f"{what}: {exc}", self.name) from None
        if response is None:
            self._drop_client(client)
            raise CommunicationLost(f"{what}: connection closed", self.name)
        if response.isError():
            raise ProtocolError(
                f"{what}: Modbus exception code {getattr(response, 'exception_code', '?')}", self.name
            )
        return response

    async def read_registers(self, address: int, count: int) -> list[int]:
        r = await self._request(
            f"read {count} @ {address}",
            lambda c: c.read_holding_registers(address, count=count, device_id=self.device_id),
            answers=lambda r: (getattr(r, "function_code", None) == FC_READ_HOLDING
                               and len(getattr(r, "registers", ())) == count),
        )
        return list(r.registers)

    async def write_registers(self, address: int, values: list[int], command: bool = False) -> None:
        """Write ``values`` from ``address``; ``command``: the write sets a self-clearing
        command bit, so it is not sent twice (see the error policy)."""
        await self._request(
            f"write {len(values)} @ {address}",
            lambda c: c.write_registers(address, values, device_id=self.device_id),
            answers=lambda r: (getattr(r, "function_code", None) == FC_WRITE_MULTIPLE
                               and (getattr(r, "address", None), getattr(r, "count", None)) == (address, len(values))),
            repeatable=not command,
        )

    # ------------------------------------------------------------------ lifecycle

    async def connect(self) -> None:
        await self._ensure_connected()
        (self.firmware_id,) = await self.read_registers(rm.FIRMWARE_ID, 1)
        if self.following_error_limit is not None:
            limit_counts = max(1, self.to_counts(self.following_error_limit))
            limit = rm.REGISTERS.FOLLOWING_ERROR_LIMIT
            await self.write_registers(limit.address, limit.encode_raw(limit_counts))
        # heartbeat first, then arm the watchdog, so the drive never sees a stale counter
        await self._beat()
        await self.write_registers(rm.WATCHDOG_TIMEOUT_MS, [self.watchdog_timeout_ms])
        if self.watchdog_timeout_ms and (self._heartbeat_task is None or self._heartbeat_task.done()):
            self._heartbeat_task = asyncio.create_task(self._heartbeat_loop(), name=f"{self.name}-heartbeat")

    async def _beat(self) -> None:
        self._heartbeat_counter = (self._heartbeat_counter + 1) & 0xFFFF
        await self.write_registers(rm.WATCHDOG_COUNTER, [self._heartbeat_counter])

    async def _heartbeat_loop(self) -> None:
        """Change the watchdog register every period; the drive faults if this stops (by design)."""
        while True:
            await asyncio.sleep(self.heartbeat_period_s)
            try:
                await self._beat()
                self.heartbeat_error = None
            except DriverError as exc:  # keep beating: the link may come back
                self.heartbeat_error = exc
                log.debug("%s heartbeat failed: %s", self.name, exc)

    async def close(self) -> None:
        task, self._heartbeat_task = self._heartbeat_task, None
        if task is not None:
            task.cancel()
            # bounded: closing must not wait on a heartbeat stuck in a transport call
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await asyncio.wait_for(task, 5.0)
        self._drop_client()

    # ------------------------------------------------------------------ commands

    async def _command(self, bit: rm.ControlBit) -> None:
        # command bits are self-clearing in the drive: one write per command
        await self.write_registers(rm.CONTROL_WORD, [self._control | int(bit)], command=True)

    async def enable(self, on: bool = True) -> None:
        self._control = (self._control | rm.ControlBit.ENABLE) if on else (self._control & ~rm.ControlBit.ENABLE)
        await self.write_registers(rm.CONTROL_WORD, [int(self._control)])

    async def move_to(self, position: float, velocity: float | None = None,
                      acceleration: float | None = None) -> None:
        st = await self.status()
        self._raise_if_fault(st)
        if not st.enabled:
            raise DriverError("move refused: drive not enabled", self.name)
        v = self.default_velocity if velocity is None else float(velocity)
        a = self.default_acceleration if acceleration is None else float(acceleration)
        if not (v > 0 and a > 0):
            raise ValueError("velocity and acceleration must be positive")
        # target, velocity and acceleration are contiguous (8..13): one FC16 request; a
        # profile of 0 counts would mean "the drive's default", so at least 1 count
        move = rm.MOVE_BLOCK
        await self.write_registers(move.start, move.encode_raw({
            "TARGET_POSITION": self.to_counts(position),
            "PROFILE_VELOCITY": max(1, self.to_counts(v)),
            "PROFILE_ACCELERATION": max(1, self.to_counts(a)),
        }))
        self._setpoint = float(position)
        await self._command(rm.ControlBit.START_MOVE)

    async def stop(self) -> None:
        self._setpoint = None  # the axis stops short of the target by design
        await self._command(rm.ControlBit.STOP)

    async def home(self) -> None:
        st = await self.status()
        self._raise_if_fault(st)
        self._setpoint = 0.0
        await self._command(rm.ControlBit.HOME)

    async def reset_fault(self) -> None:
        # a fault leaves the axis disabled; the caller must enable it again deliberately
        self._control &= ~rm.ControlBit.ENABLE
        await self.write_registers(rm.CONTROL_WORD, [int(rm.ControlBit.FAULT_RESET)], command=True)

    # ------------------------------------------------------------------ reading

    async def status(self) -> AxisStatus:
        block = rm.STATUS_BLOCK
        v = block.decode(await self.read_registers(block.start, block.count), self.unit_per_count)
        word = v["STATUS_WORD"]
        sb = rm.StatusBit
        return AxisStatus(
            ready=bool(word & sb.READY),
            enabled=bool(word & sb.ENABLED),
            moving=bool(word & sb.MOVING),
            in_position=bool(word & sb.IN_POSITION),
            homed=bool(word & sb.HOMED),
            fault=bool(word & sb.FAULT),
            following_error=bool(word & sb.FOLLOWING_ERROR),
            estop=bool(word & sb.ESTOP),
            fault_code=v["FAULT_CODE"],
            position=v["ACTUAL_POSITION"],
            velocity=v["ACTUAL_VELOCITY"],
            status_word=word,
        )

    async def read_position(self) -> float:
        pos = rm.REGISTERS.ACTUAL_POSITION
        return pos.decode(await self.read_registers(pos.address, pos.count), self.unit_per_count)

    def _raise_if_fault(self, st: AxisStatus) -> None:
        if st.following_error or st.fault_code == rm.FaultCode.FOLLOWING_ERROR:
            raise FollowingError(st.fault_code, rm.FaultCode.describe(st.fault_code), self.name)
        if st.fault or st.estop:
            raise DriveFault(st.fault_code, rm.FaultCode.describe(st.fault_code), self.name)

    async def wait_in_position(self, timeout: float, poll_s: float | None = None) -> AxisStatus:
        poll_s = self.poll_s if poll_s is None else poll_s
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout
        resting_short = 0
        while True:
            st = await self.status()
            self._raise_if_fault(st)
            target = self._setpoint
            at_target = target is None or abs(st.position - target) <= self.in_position_window
            if st.in_position and not st.moving and at_target:
                return st
            # at rest, no fault, not at our target, on several polls in a row (not the
            # instant between the START write and the drive's MOVING bit): the move was
            # overridden or lost
            resting_short = resting_short + 1 if (not st.moving and not at_target) else 0
            if resting_short >= RESTING_SHORT_POLLS:
                raise MoveInterrupted(
                    f"at rest at {st.position:.6f} {self.units}, short of the target "
                    f"{target:.6f}, without a fault", self.name)
            if loop.time() >= deadline:
                raise DeviceTimeout(
                    f"not in position after {timeout} s (at {st.position:.6f} {self.units}, moving={st.moving})",
                    self.name,
                )
            await asyncio.sleep(poll_s)


class ModbusLinearAxis(ModbusServoAxis, LinearAxis):
    """The Z stage: positions in mm, ``unit_per_count`` in mm per count."""


class ModbusRotaryAxis(ModbusServoAxis, RotaryAxis):
    """The C table: positions in deg, ``unit_per_count`` in deg per count."""
