"""The servo drive twin's protocol face: a pymodbus server whose registers drive the physics.

Built on pymodbus 3.16's current server API (``SimDevice``/``SimData``; the older
``ModbusServerContext``/``ModbusDeviceContext`` are deprecated there and only wrap
``SimDevice``).  ``SimDevice(action=...)`` calls an async hook on every register access
with the live register list, which is exactly where a twin belongs: before a read the
hook copies the physics into the status registers; on a write it hands the values to
the physics (commands, watchdog) and clears the self-clearing command bits.

Read-only registers are declared ``readonly`` so the server itself answers a write to
them with exception 2 (illegal data address), as a real drive does.

Faults (``sim.faults``) act where they would on a real line: DELAY and DRIVE_FAULT in
the hook, GARBAGE/CHECKSUM/DROP_CONNECTION on the byte stream (pymodbus'
``trace_packet`` hook sees every frame received and sent).
"""

from __future__ import annotations

import asyncio
import logging
import random

from pymodbus import FramerType
from pymodbus.constants import ExcCodes
from pymodbus.server import ModbusSerialServer, ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from drivers.interfaces import register_map as rm
from sim.faults import MODBUS_DRIVE_FAULTS, Fault, FaultKind, FaultSwitch
from sim.servo.physics import ServoAxisPhysics

log = logging.getLogger(__name__)

#: how long one server may take to shut down before the twin gives up on it
SHUTDOWN_TIMEOUT_S = 5.0

#: registers the master may write (everything else is read-only)
_WRITABLE = {
    rm.CONTROL_WORD,
    rm.TARGET_POSITION,
    rm.TARGET_POSITION + 1,
    rm.PROFILE_VELOCITY,
    rm.PROFILE_VELOCITY + 1,
    rm.PROFILE_ACCELERATION,
    rm.PROFILE_ACCELERATION + 1,
    rm.WATCHDOG_COUNTER,
    rm.WATCHDOG_TIMEOUT_MS,
    rm.FOLLOWING_ERROR_LIMIT,
    rm.FOLLOWING_ERROR_LIMIT + 1,
}
_SELF_CLEARING = int(rm.ControlBit.START_MOVE | rm.ControlBit.STOP | rm.ControlBit.HOME | rm.ControlBit.FAULT_RESET)


def _build_simdata() -> list[SimData]:
    """One SimData per register, read-only where the map says so."""
    out = []
    for addr in range(rm.REGISTER_COUNT):
        value = rm.TWIN_FIRMWARE_ID if addr == rm.FIRMWARE_ID else 0
        out.append(SimData(addr, values=value, datatype=DataType.REGISTERS, readonly=addr not in _WRITABLE))
    return out


class ModbusDriveTwin:
    """One servo drive on Modbus: physics + register face + faults.

    Serves TCP on ``host:port`` (port 0: a free port, see :attr:`port` after start) and,
    optionally, RTU on a serial path (``rtu_port``: e.g. one end of a pty pair).
    """

    def __init__(
        self,
        physics: ServoAxisPhysics,
        *,
        device_id: int = 1,
        unit_per_count: float = 1e-4,
        faults: FaultSwitch | None = None,
        name: str | None = None,
        seed: int = 0,
    ):
        self.physics = physics
        self.device_id = int(device_id)
        self.unit_per_count = float(unit_per_count)
        self.name = name or physics.config.name
        self.faults = faults or FaultSwitch(MODBUS_DRIVE_FAULTS, name=f"drive {self.name}")
        self.faults.add_listener(self._on_fault_change)
        self._rng = random.Random(seed)  # reproducible garbage
        self.device = SimDevice(id=self.device_id, simdata=_build_simdata(), action=self._action)
        self._servers: list = []
        self._loop: asyncio.AbstractEventLoop | None = None
        self.host: str | None = None
        self.port: int | None = None
        self.rtu_port: str | None = None

    # ------------------------------------------------------------------ scaling

    def _counts(self, value: float) -> int:
        return int(round(value / self.unit_per_count))

    # ------------------------------------------------------------------ register hook

    def _refresh(self, registers: list[int]) -> None:
        """Copy the physics into the read-only registers."""
        s = self.physics.snapshot()
        sb = rm.StatusBit
        word = 0
        word |= sb.READY if s.ready else 0
        word |= sb.ENABLED if s.enabled else 0
        word |= sb.MOVING if s.moving else 0
        word |= sb.IN_POSITION if s.in_position else 0
        word |= sb.HOMED if s.homed else 0
        word |= sb.FAULT if s.fault else 0
        word |= sb.FOLLOWING_ERROR if s.fault_code == rm.FaultCode.FOLLOWING_ERROR else 0
        word |= sb.ESTOP if s.estop else 0
        registers[rm.STATUS_WORD] = int(word)
        registers[rm.ACTUAL_POSITION : rm.ACTUAL_POSITION + 2] = rm.int32_to_regs(self._counts(s.motor_position))
        registers[rm.ACTUAL_VELOCITY : rm.ACTUAL_VELOCITY + 2] = rm.int32_to_regs(self._counts(s.velocity))
        registers[rm.FAULT_CODE] = s.fault_code & 0xFFFF
        registers[rm.WATCHDOG_TIMEOUT_MS] = int(round(self.physics.watchdog_timeout_s * 1000.0))

    def _apply_write(self, registers: list[int], address: int, values: list[int]) -> None:
        """Hand a write to the physics; ``values`` is modified in place (self-clearing bits)."""
        merged = list(registers)
        merged[address : address + len(values)] = values
        written = range(address, address + len(values))
        if rm.FOLLOWING_ERROR_LIMIT in written or rm.FOLLOWING_ERROR_LIMIT + 1 in written:
            limit = rm.regs_to_uint32(merged[rm.FOLLOWING_ERROR_LIMIT], merged[rm.FOLLOWING_ERROR_LIMIT + 1])
            self.physics.config.following_error_limit = max(1, limit) * self.unit_per_count
        if rm.WATCHDOG_TIMEOUT_MS in written:
            self.physics.set_watchdog_timeout(merged[rm.WATCHDOG_TIMEOUT_MS] / 1000.0)
        if rm.WATCHDOG_COUNTER in written and merged[rm.WATCHDOG_COUNTER] != registers[rm.WATCHDOG_COUNTER]:
            self.physics.heartbeat()  # only a *changed* counter proves the master is alive
        if rm.CONTROL_WORD in written:
            cw = merged[rm.CONTROL_WORD]
            cb = rm.ControlBit
            if cw & cb.FAULT_RESET:
                self.physics.reset_fault()
            self.physics.enable(bool(cw & cb.ENABLE))
            if cw & cb.STOP:
                self.physics.stop()
            elif cw & cb.HOME:
                self.physics.home()
            elif cw & cb.START_MOVE:
                target = rm.regs_to_int32(merged[rm.TARGET_POSITION], merged[rm.TARGET_POSITION + 1])
                v = rm.regs_to_uint32(merged[rm.PROFILE_VELOCITY], merged[rm.PROFILE_VELOCITY + 1])
                a = rm.regs_to_uint32(merged[rm.PROFILE_ACCELERATION], merged[rm.PROFILE_ACCELERATION + 1])
                u = self.unit_per_count
                self.physics.start_move(target * u, v * u, a * u)
            values[rm.CONTROL_WORD - address] = cw & ~_SELF_CLEARING & 0xFFFF

    async def _action(self, function_code, start_address, address, count, registers, set_values):
        delay = self.faults.get(FaultKind.DELAY)
        if delay is not None and delay.delay_s > 0:
            await asyncio.sleep(delay.delay_s)
        if start_address != 0:  # the block is built from address 0; anything else is a bug
            return ExcCodes.DEVICE_FAILURE
        if set_values:
            self._apply_write(registers, address, list(set_values))
            cw_index = rm.CONTROL_WORD - address
            if 0 <= cw_index < len(set_values):
                set_values[cw_index] = set_values[cw_index] & ~_SELF_CLEARING & 0xFFFF
        self._refresh(registers)
        return None

    # ------------------------------------------------------------------ faults

    def _on_fault_change(self, kind: FaultKind, fault: Fault | None) -> None:
        if kind is FaultKind.DRIVE_FAULT:
            if fault is not None:
                self.physics.inject_fault(fault.code or rm.FaultCode.OVERCURRENT)
            else:
                self.physics.release_estop()  # the cause is gone; the master still resets the fault
        elif kind is FaultKind.STUCK_AXIS:
            self.physics.set_stuck(fault is not None)
        elif kind is FaultKind.DROP_CONNECTION and fault is not None and self._loop is not None:
            self._loop.call_soon_threadsafe(self._close_connections)

    def _close_connections(self) -> None:
        for server in self._servers:
            for conn in list(getattr(server, "active_connections", {}).values()):
                conn.close()

    def _trace_packet(self, rtu: bool):
        def trace(sending: bool, data: bytes) -> bytes:
            if not sending:
                if self.faults.is_active(FaultKind.DROP_CONNECTION):
                    if not rtu:
                        self._close_connections()
                    return b""  # the request never reaches the drive
                return data
            if not data:
                return data
            if self.faults.is_active(FaultKind.GARBAGE):
                return bytes(self._rng.randrange(256) for _ in range(len(data)))
            if self.faults.is_active(FaultKind.CHECKSUM):
                corrupt = bytearray(data)
                if rtu:
                    corrupt[-1] ^= 0xFF  # CRC-16 no longer matches
                else:
                    corrupt[2] ^= 0x5A  # MBAP protocol id must be 0: TCP's only integrity check
                return bytes(corrupt)
            return data

        return trace

    # ------------------------------------------------------------------ serving

    async def start(self, host: str = "127.0.0.1", port: int = 0, rtu_port: str | None = None, baudrate: int = 115200):
        """Start serving; returns ``(host, port)`` actually bound."""
        self._loop = asyncio.get_running_loop()
        tcp = ModbusTcpServer(self.device, address=(host, port), trace_packet=self._trace_packet(False))
        await tcp.serve_forever(background=True)
        self._servers.append(tcp)
        self.host, self.port = tcp.transport.sockets[0].getsockname()[:2]
        if rtu_port is not None:
            rtu = ModbusSerialServer(
                self.device, framer=FramerType.RTU, port=rtu_port, baudrate=baudrate, trace_packet=self._trace_packet(True)
            )
            await rtu.serve_forever(background=True)
            self._servers.append(rtu)
            self.rtu_port = rtu_port
        log.info("drive %s (device %d) on %s:%d", self.name, self.device_id, self.host, self.port)
        return self.host, self.port

    async def stop(self) -> None:
        servers, self._servers = self._servers, []
        for server in servers:
            try:
                # bounded: a connection whose handler is still sleeping in an injected
                # delay must not hold the station's shutdown (a CI teardown once hung 300 s)
                await asyncio.wait_for(server.shutdown(), SHUTDOWN_TIMEOUT_S)
            except TimeoutError:
                log.warning("drive %s: a server did not stop within %.0f s", self.name, SHUTDOWN_TIMEOUT_S)
            except Exception:  # noqa: BLE001 - shutting down: report, never raise
                log.exception("drive %s: error while stopping a server", self.name)
