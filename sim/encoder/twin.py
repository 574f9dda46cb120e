"""The grating encoder twin: a read head on a pseudo-terminal answering the documented protocol.

The driver opens :attr:`SerialEncoderTwin.path` (the pty's slave side) with pyserial,
exactly as it would open ``/dev/ttyUSB0``; the twin reads and writes the master side in
a thread.  It reports the TRUE carriage position, supplied by the world as a callable
``position_mm() -> float`` (default in ``sim.twins``: the Z physics'
``carriage_position``), quantised to the head's resolution -- so a test that compares
the encoder with the drive sees the geometric error the world put in.

Faults (``sim.faults``): DROP_CONNECTION (no answer), DELAY, GARBAGE (a noise line),
CHECKSUM (wrong checksum), STUCK_AXIS (count frozen, SIGNAL_LOW set), DRIVE_FAULT
(HARDWARE_ERROR set).
"""

from __future__ import annotations

import logging
import os
import random
import select
import threading
import time
import tty
from typing import Callable

from drivers.interfaces import encoder_protocol as ep
from sim.faults import ENCODER_FAULTS, FaultKind, FaultSwitch

log = logging.getLogger(__name__)

#: how long the serving thread blocks in select before checking for shutdown
_POLL_S = 0.05


class SerialEncoderTwin:
    """A read head on a pty.  ``start()`` returns the slave path the driver should open."""

    def __init__(
        self,
        position_mm: Callable[[], float],
        *,
        resolution_um: float = 0.05,
        faults: FaultSwitch | None = None,
        model: str = "GRT-005",
        version: str = "V1.3",
        referenced: bool = True,
        seed: int = 0,
        name: str = "encoder",
    ):
        #: the world's hook: the TRUE carriage position in mm, called once per query
        self.position_mm = position_mm
        self.resolution_um = float(resolution_um)
        self.faults = faults or FaultSwitch(ENCODER_FAULTS, name=name)
        self.model, self.version = model, version
        self.referenced = referenced
        self.name = name
        self._rng = random.Random(seed)
        self._master: int | None = None
        self._slave: int | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._frozen_counts: int | None = None
        self.path: str | None = None
        #: number of queries answered (for tests and the bench)
        self.queries = 0

    # ------------------------------------------------------------------ replies

    def counts(self) -> int:
        """The current count: true position quantised to the resolution (um -> counts)."""
        return int(round(self.position_mm() * 1000.0 / self.resolution_um))

    def _status_and_counts(self) -> tuple[int, int]:
        status = ep.EncoderStatusBit.REFERENCED if self.referenced else 0
        if self.faults.is_active(FaultKind.STUCK_AXIS):
            if self._frozen_counts is None:
                self._frozen_counts = self.counts()
            status |= ep.EncoderStatusBit.SIGNAL_LOW
            counts = self._frozen_counts
        else:
            self._frozen_counts = None
            counts = self.counts()
        if self.faults.is_active(FaultKind.DRIVE_FAULT):
            status |= ep.EncoderStatusBit.HARDWARE_ERROR
        return int(status), counts

    def reply_to(self, command: bytes) -> bytes | None:
        """The bytes answering one command (without its CR); None: stay silent."""
        if self.faults.is_active(FaultKind.DROP_CONNECTION):
            return None
        delay = self.faults.get(FaultKind.DELAY)
        if delay is not None and delay.delay_s > 0:
            time.sleep(delay.delay_s)
        self.queries += 1
        if self.faults.is_active(FaultKind.GARBAGE):
            noise = bytes(self._rng.randrange(256) for _ in range(20))
            return noise.replace(b"\n", b"#") + ep.TERMINATOR
        query = command + b"\r"
        if query == ep.POSITION_QUERY:
            status, counts = self._status_and_counts()
            frame = ep.position_reply(counts, status)
        elif query == ep.IDENTITY_QUERY:
            frame = ep.identity_reply(self.model, self.version)
        else:
            frame = ep.error_reply(ep.EncoderErrorCode.UNKNOWN_COMMAND)
        if self.faults.is_active(FaultKind.CHECKSUM):
            star = frame.rindex(b"*")
            wrong = (int(frame[star + 1 : star + 3], 16) ^ 0x5A) & 0xFF
            frame = frame[: star + 1] + f"{wrong:02X}".encode() + ep.TERMINATOR
        return frame

    # ------------------------------------------------------------------ serving

    def start(self) -> str:
        master, slave = os.openpty()
        tty.setraw(slave)  # no echo, no CR/LF translation: bytes pass as they are
        self._master, self._slave = master, slave
        self.path = os.ttyname(slave)
        self._stop.clear()
        self._thread = threading.Thread(target=self._serve, name=f"{self.name}-pty", daemon=True)
        self._thread.start()
        log.info("encoder twin on %s", self.path)
        return self.path

    def _serve(self) -> None:
        buf = b""
        master = self._master
        assert master is not None
        while not self._stop.is_set():
            try:
                ready, _, _ = select.select([master], [], [], _POLL_S)
                if not ready:
                    continue
                data = os.read(master, 1024)
            except OSError:
                if self._stop.is_set():
                    return
                time.sleep(_POLL_S)  # no reader on the slave side at the moment
                continue
            buf += data
            while b"\r" in buf:
                line, buf = buf.split(b"\r", 1)
                # a command is the last '?'-started token on the line: noise before it is skipped
                q = line.rfind(b"?")
                command = line[q:] if q >= 0 else line
                try:
                    reply = self.reply_to(command)
                except Exception:  # noqa: BLE001 - a broken world callable must not kill the head
                    log.exception("encoder twin: cannot answer %r", command)
                    reply = ep.error_reply(ep.EncoderErrorCode.BUSY)
                if reply:
                    try:
                        os.write(master, reply)
                    except OSError:
                        pass
            if len(buf) > 256:
                buf = buf[-16:]  # noise without CR: keep a command's worth

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        for fd in (self._master, self._slave):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._master = self._slave = None
