"""How ``make test`` splits the suite: which test files are computation only (the
``compute`` marker, set in tests/conftest.py). A module of its own, not conftest, so
that tests can import it: under pytest's rootdir imports every ``conftest`` of the
suite is a module named ``conftest``, and which one an import finds depends on which
folders were collected."""

from __future__ import annotations

import functools
import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

#: the folders whose files may be computation only (the ``compute`` marker)
COMPUTE_DIRS = ("tests/unit/", "tests/sim/")
#: what a test file names when it runs anything in real time: an event loop, a socket
#: or a pty, a thread, a child process, a sleep, a server (a twin over TCP, the served
#: API), a database server. A file of ``COMPUTE_DIRS`` that names none of these is
#: computation only (rendering, fitting, models, files) and is marked ``compute``
REAL_TIME_WORDS = re.compile(r"asyncio|\bawait\b|socket|subprocess|Popen|threading|Thread\b|time\.sleep|pg_cluster"
                             r"|\bserve\(|loop_hold|\bpty\b|modbus|Modbus|uvicorn|TestClient")


@functools.cache
def is_compute_file(rel: str) -> bool:
    """Whether the test file ``rel`` (relative to the checkout) is computation only:
    ``make test`` runs these at a lower priority beside the real-time tests, where a
    starved core costs them time and nothing else (a real-time test's drive watchdog
    expires when the station's event loop does not turn for 1 s)."""
    if not rel.startswith(COMPUTE_DIRS):
        return False
    return REAL_TIME_WORDS.search((REPO / rel).read_text(encoding="utf-8")) is None
