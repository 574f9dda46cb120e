"""Fakes of the drivers' transports, for fuzzing a driver without a device or a twin.

* :class:`ByteTransport` -- a serial port (the encoder driver's ``transport``) that
  answers every query with given bytes;
* :class:`FakeModbusClient` -- pymodbus' asynchronous client face (what
  ``ModbusLinearAxis`` is given by its client factory), answering from a script.
"""

from __future__ import annotations


class ByteTransport:
    """A serial port that answers every query with the given bytes (in chunks)."""

    def __init__(self, data: bytes):
        self.data = data
        self.buf = b""

    def write(self, q):
        self.buf += self.data
        return len(q)

    def read(self, size=1):
        out, self.buf = self.buf[:size], self.buf[size:]
        return out

    @property
    def in_waiting(self):
        return len(self.buf)

    def reset_input_buffer(self):
        self.buf = b""

    def close(self):
        pass


class FakeResponse:
    """A pymodbus response: the function it answers, a read's registers, the address and
    count a write echoes, or an exception response (``isError``)."""

    def __init__(self, registers, error, function_code=3, address=0, count=0):
        self.registers = registers
        self._error = error
        self.function_code = function_code | (0x80 if error else 0)
        self.address = address
        self.count = count
        #: Modbus exception code 2, "illegal data address" (Modbus application protocol 1.1b3, 7)
        self.exception_code = 2

    def isError(self):
        return self._error


class FakeModbusClient:
    """pymodbus' client face, answering from a script: register lists of any length and
    value, error responses, replies to another request (a late one: a write's to a read,
    a read's to a write), pymodbus exceptions, None."""

    def __init__(self, script: list):
        self.script = list(script)
        self.connected = True

    async def connect(self):
        return True

    def close(self):
        pass

    def _next(self, function_code, address, count):
        from pymodbus.exceptions import ConnectionException, ModbusIOException

        item = self.script.pop(0) if self.script else ("regs", [0] * count)
        kind, value = item
        if kind == "regs":
            return FakeResponse(value, False, function_code, address, count)
        if kind == "stale":
            other = 16 if function_code == 3 else 3
            return FakeResponse(value, False, other, address + 1, len(value))
        if kind == "error":
            return FakeResponse([], True, function_code)
        if kind == "none":
            return None
        if kind == "io":
            raise ModbusIOException(str(value))
        raise ConnectionException(str(value))

    async def read_holding_registers(self, address, count=1, device_id=1):
        return self._next(3, address, count)

    async def write_registers(self, address, values, device_id=1):
        return self._next(16, address, len(values))
