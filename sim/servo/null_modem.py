"""A null-modem cable made of two pseudo-terminals, for Modbus RTU twins.

A pty has one named end (the slave) and one anonymous end (the master).  A serial
*server* and a serial *client* both want a named device to open, so two ptys are
joined master-to-master by a small copying thread: whatever the client writes to
``client_path`` comes out at ``server_path`` and back.  Bytes pass unchanged (raw mode).
"""

from __future__ import annotations

import os
import select
import threading
import tty

#: how long the copying thread blocks before checking for shutdown
_POLL_S = 0.05


class PtyNullModem:
    def __init__(self, name: str = "null-modem"):
        self.name = name
        self._fds: list[int] = []
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.server_path: str | None = None
        self.client_path: str | None = None

    def start(self) -> tuple[str, str]:
        """Open both ptys and start copying; returns ``(server_path, client_path)``."""
        ma, sa = os.openpty()
        mb, sb = os.openpty()
        for fd in (sa, sb):
            tty.setraw(fd)
        self._fds = [ma, sa, mb, sb]
        self._masters = (ma, mb)
        self.server_path, self.client_path = os.ttyname(sa), os.ttyname(sb)
        self._stop.clear()
        self._thread = threading.Thread(target=self._copy, name=self.name, daemon=True)
        self._thread.start()
        return self.server_path, self.client_path

    def _copy(self) -> None:
        ma, mb = self._masters
        peer = {ma: mb, mb: ma}
        while not self._stop.is_set():
            try:
                ready, _, _ = select.select([ma, mb], [], [], _POLL_S)
            except (OSError, ValueError):
                return
            for fd in ready:
                try:
                    data = os.read(fd, 4096)
                    os.write(peer[fd], data)
                except OSError:
                    # nobody has that end open right now (EIO); try again after a pause
                    self._stop.wait(_POLL_S)

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        for fd in self._fds:
            try:
                os.close(fd)
            except OSError:
                pass
        self._fds = []
