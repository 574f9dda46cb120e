"""A `station serve` child process on 127.0.0.1, for the benches and the browser
tests: start it on a free port, wait until it is ready, stop it cleanly.

No import of ``station.cli`` here (the CLI imports the benches).
"""

from __future__ import annotations

import contextlib
import os
import socket
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

#: how long a simulated station may take to start (imports, twins, homing checks)
READY_TIMEOUT_S = 120.0


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def station_command() -> list[str]:
    exe = Path(sys.executable).with_name("station")
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "station.cli"]


@dataclass
class Served:
    proc: subprocess.Popen
    url: str
    data: Path

    @property
    def log_tail(self) -> str:
        try:
            return (self.data / "server.log").read_text(errors="replace")[-2000:]
        except OSError:
            return ""


def start(data: Path, *, time_scale: float, extra: list[str] | None = None,
          ready_timeout_s: float = READY_TIMEOUT_S, env: dict[str, str] | None = None) -> Served:
    """Start `station serve` on a free port with its log in ``data/server.log``; return
    once ``/readyz`` answers 200 (RuntimeError with the log's tail if it never does).
    ``env``: variables added to the server's environment."""
    import httpx

    port = free_port()
    cmd = station_command() + ["serve", "--host", "127.0.0.1", "--port", str(port), "--data", str(data),
                               "--time-scale", str(time_scale)] + list(extra or [])
    with open(data / "server.log", "w") as log:
        proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, cwd=data,
                                env={**os.environ, "PYTHONUNBUFFERED": "1", **(env or {})})
    served = Served(proc, f"http://127.0.0.1:{port}", data)
    deadline = time.monotonic() + ready_timeout_s
    try:
        while True:
            if proc.poll() is not None:
                raise RuntimeError(f"station serve exited ({proc.returncode}): {served.log_tail}")
            try:
                if httpx.get(f"{served.url}/readyz", timeout=2).status_code == 200:
                    return served
            except httpx.HTTPError:
                pass
            if time.monotonic() > deadline:
                raise RuntimeError(f"station serve did not become ready: {served.log_tail}")
            time.sleep(0.2)
    except BaseException:
        stop(proc)
        raise


def stop(proc: subprocess.Popen) -> None:
    """Stop a `station serve` child: SIGTERM (a clean shutdown closes the station and
    its twins), SIGKILL if it has not ended within 20 s."""
    if proc.poll() is not None:
        return
    proc.terminate()
    try:
        proc.wait(timeout=20)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(timeout=10)


@contextlib.contextmanager
def served(data: Path, *, time_scale: float, extra: list[str] | None = None,
           env: dict[str, str] | None = None) -> Iterator[Served]:
    s = start(data, time_scale=time_scale, extra=extra, env=env)
    try:
        yield s
    finally:
        stop(s.proc)
