"""A throwaway PostgreSQL cluster for the tests: ``initdb`` and ``pg_ctl`` in a temporary
folder, listening on 127.0.0.1 at a free port (and a Unix socket inside that folder),
gone when the test run ends.

Debian's PostgreSQL 15 server (``/usr/lib/postgresql/15/bin``; ``make test`` installs
it where missing). ``initdb`` refuses to run as root: under root the cluster belongs to
the ``postgres`` system user that Debian's package creates, and the server is started
as that user (``runuser``).

Every test database is a copy of one template migrated once (``CREATE DATABASE ...
TEMPLATE``: a file copy, a few tens of ms), so a test starts on the newest schema
without running Alembic again; the store's own migration then finds nothing to do.
"""

from __future__ import annotations

import hashlib
import os
import pwd
import shutil
import socket
import subprocess
import tempfile
import threading
import time
from pathlib import Path

#: where Debian puts the server's programs (they are not on PATH)
PG_BIN_DIRS = [Path(f"/usr/lib/postgresql/{v}/bin") for v in (17, 16, 15)]
SYSTEM_USER = "postgres"
SUPERUSER = "postgres"
#: the migrated database every test database is copied from
TEMPLATE = "station_template"


def pg_bin() -> Path:
    for d in PG_BIN_DIRS:
        if (d / "initdb").is_file():
            return d
    found = shutil.which("initdb")
    if found:
        return Path(found).resolve().parent
    raise RuntimeError("PostgreSQL's server programs (initdb, pg_ctl) are not installed: "
                       "`make test` installs Debian's postgresql; or apt-get install postgresql")


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class PgCluster:
    """One PostgreSQL server of our own; :meth:`url` names a database on it."""

    def __init__(self, root: Path) -> None:
        self.root = Path(root)
        self.data = self.root / "pgdata"
        self.sockets = self.root / "sock"
        self.port = _free_port()
        self.bin = pg_bin()
        self._as_root = os.geteuid() == 0
        self._made: set[str] = set()
        self._lock = threading.Lock()

    # -- life ----------------------------------------------------------------------------

    def _run(self, *args: str, timeout: float = 120.0) -> subprocess.CompletedProcess:
        cmd = list(args)
        if self._as_root:
            cmd = ["runuser", "-u", SYSTEM_USER, "--", *cmd]
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=self.root)
        if r.returncode != 0:
            raise RuntimeError(f"{' '.join(args)} failed ({r.returncode}):\n{r.stdout}\n{r.stderr}")
        return r

    def start(self) -> PgCluster:
        self.root.mkdir(parents=True, exist_ok=True)
        self.sockets.mkdir(exist_ok=True)
        if self._as_root:
            pw = pwd.getpwnam(SYSTEM_USER)
            for p in (self.root, self.sockets):
                os.chown(p, pw.pw_uid, pw.pw_gid)
            # the system user must be able to reach the folder (tmp folders are 0700)
            for parent in self.root.parents:
                if parent == Path("/"):
                    break
                try:
                    mode = parent.stat().st_mode
                    if not mode & 0o001:
                        os.chmod(parent, mode | 0o001)
                except PermissionError:
                    break
        self._run(str(self.bin / "initdb"), "-D", str(self.data), "-U", SUPERUSER, "--auth=trust",
                  "-E", "UTF8", "--locale=C.UTF-8" if _has_locale("C.UTF-8") else "--locale=C", "--no-sync")
        # a test server: durability of the *server* across its own crash is not under
        # test (the stations are killed, never PostgreSQL), so it does not fsync
        opts = (f"-c listen_addresses=127.0.0.1 -c port={self.port} -c unix_socket_directories={self.sockets} "
                "-c fsync=off -c synchronous_commit=off -c full_page_writes=off -c max_connections=300 "
                "-c shared_buffers=64MB")
        self._run(str(self.bin / "pg_ctl"), "-D", str(self.data), "-o", opts, "-l", str(self.root / "server.log"),
                  "-w", "-t", "60", "start")
        return self

    def stop(self) -> None:
        log = self.root / "server.log"
        if log.exists():  # kept for a person wondering what the server said
            shutil.copyfile(log, Path(tempfile.gettempdir()) / "station-tests-postgresql.log")
        if (self.data / "postmaster.pid").exists():
            try:
                self._run(str(self.bin / "pg_ctl"), "-D", str(self.data), "-m", "immediate", "-w", "-t", "30", "stop")
            except (RuntimeError, subprocess.TimeoutExpired):
                pass
        shutil.rmtree(self.root, ignore_errors=True)

    # -- databases -----------------------------------------------------------------------

    def url(self, database: str = "postgres") -> str:
        return f"postgresql+psycopg://{SUPERUSER}@127.0.0.1:{self.port}/{database}"

    def _admin(self, sql: str) -> None:
        import psycopg

        with psycopg.connect(host="127.0.0.1", port=self.port, user=SUPERUSER, dbname="postgres",
                             autocommit=True, connect_timeout=10) as conn:
            conn.execute(sql)

    def make_template(self) -> None:
        """The template database at the newest schema (the store's own migration)."""
        from station.store.migrate import upgrade_to_head

        self._admin(f'CREATE DATABASE "{TEMPLATE}"')
        upgrade_to_head(self.url(TEMPLATE))

    def database(self, name: str, *, empty: bool = False) -> str:
        """The URL of database ``name``, made on first use from the migrated template
        (``empty``: from template0, with no schema at all)."""
        with self._lock:
            if name not in self._made:
                self._admin(f'CREATE DATABASE "{name}" TEMPLATE "{"template0" if empty else TEMPLATE}"')
                self._made.add(name)
        return self.url(name)

    def database_for(self, data_dir: str | Path, *, empty: bool = False) -> str:
        """One database per data folder, as one SQLite file per data folder."""
        key = hashlib.sha1(str(Path(data_dir).resolve()).encode()).hexdigest()[:16]
        return self.database(f"t_{key}", empty=empty)

    def wait_ready(self, timeout: float = 30.0) -> None:
        deadline = time.monotonic() + timeout
        while True:
            try:
                self._admin("SELECT 1")
                return
            except Exception:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.2)


def _has_locale(name: str) -> bool:
    r = subprocess.run(["locale", "-a"], capture_output=True, text=True)
    return name.lower().replace("-", "") in r.stdout.lower().replace("-", "")
