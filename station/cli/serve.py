"""``station serve``: the MES REST API (and later the operator panel) on uvicorn.

The server owns the station: it opens one session at start (the twins too, in
simulation) and closes it at shutdown (Ctrl-C, SIGTERM).

A SIGTERM (systemd's stop, ``kill``) that uvicorn shut down for ends the process with
exit status 0 through the interpreter's normal exit. uvicorn re-raises the signal it
stopped for once shutdown is done; under the default handler that kills the process
outright, so no exit handler would run: multiprocessing's finalizers would not release
the renderer's queues (the resource tracker then warns of "leaked semaphore objects"),
and a stop that was asked for and done would read as death by a signal.
"""

from __future__ import annotations

import math
import signal
from pathlib import Path
from typing import Optional

import typer

from api.settings import Settings
from station.cli.common import fail


def _exit_cleanly(signum, frame) -> None:
    """SIGTERM as an orderly exit: the exit handlers run, the status is 0."""
    raise SystemExit(0)


def register(app: typer.Typer) -> None:
    @app.command("serve")
    def serve(
        host: str = typer.Option("127.0.0.1", "--host", help="address to listen on (0.0.0.0: every interface)"),
        port: int = typer.Option(8000, "--port", help="TCP port"),
        config: Optional[Path] = typer.Option(None, "--config", help="station config TOML (default: simulated)"),
        scenario: Optional[Path] = typer.Option(None, "--scenario", help="twin scenario TOML (simulation only)"),
        data: Path = typer.Option(Path("var"), "--data", help="data folder: database, images, parts, models"),
        time_scale: Optional[float] = typer.Option(None, "--time-scale", help="simulation: moves run this much faster"),
        db: Optional[str] = typer.Option(None, "--db", envvar="STATION_DB_URL",
                                         help="database URL (default: SQLite in the data folder); also from "
                                              "$STATION_DB_URL, which keeps a password out of the process list"),
        station_id: Optional[str] = typer.Option(None, "--station-id", help="this station's id on a shared "
                                                 "database (default: the config's [station] id)"),
        cookie_secure: bool = typer.Option(False, "--cookie-secure", help="mark the panel's session cookie Secure "
                                           "(https only): for a station behind a TLS reverse proxy (docs/security.md)"),
        opcua: Optional[str] = typer.Option(None, "--opcua", help="also serve OPC UA at opc.tcp://HOST:PORT "
                                            "(docs/opcua.md)"),
        opcua_cert: Optional[Path] = typer.Option(None, "--opcua-cert", help="OPC UA server certificate (PEM or "
                                                  "DER): offers Basic256Sha256 besides SecurityPolicy None"),
        opcua_key: Optional[Path] = typer.Option(None, "--opcua-key", help="the OPC UA certificate's private key"),
        write_rate: float = typer.Option(Settings.write_rate_per_s, "--write-rate",
                                         help="writes per second per API token, sustained (0: no limit; "
                                              "docs/api.md, Limit on writes)"),
        write_burst: int = typer.Option(Settings.write_burst, "--write-burst",
                                        help="writes per API token at once before the rate applies"),
    ) -> None:
        """Run the REST API (docs/api.md), and with --opcua an OPC UA server beside it (docs/opcua.md).
        Create a token first: station token create --role mes."""
        import uvicorn

        from api.app import create_app

        if time_scale is not None and not time_scale > 0:
            fail("--time-scale must be positive")
        if station_id is not None:
            from station.store.repository import check_station_id

            try:
                check_station_id(station_id)
            except ValueError as exc:
                fail(f"--station-id: {exc}")
        if opcua is not None:
            from api.opcua import OpcUaStartError, check_endpoint_free, parse_endpoint

            try:
                parse_endpoint(opcua)
                check_endpoint_free(opcua)
            except (ValueError, OpcUaStartError) as exc:
                fail(f"--opcua: {exc}")
        if not (math.isfinite(write_rate) and write_rate >= 0):
            fail("--write-rate must be 0 (no limit) or a positive number of writes per second")
        if write_burst < 1:
            fail("--write-burst must be at least 1")
        if (opcua_cert is None) != (opcua_key is None):
            fail("--opcua-cert and --opcua-key go together")
        if opcua_cert is not None and opcua is None:
            fail("--opcua-cert needs --opcua opc.tcp://HOST:PORT")
        for option, path in (("--opcua-cert", opcua_cert), ("--opcua-key", opcua_key)):
            if path is not None and not path.is_file():
                fail(f"{option}: no file {path}")
        settings = Settings(config=config, scenario=scenario, data_dir=data, db_url=db, time_scale=time_scale,
                            station_id=station_id,
                            cookie_secure=cookie_secure, opcua_endpoint=opcua, opcua_cert=opcua_cert,
                            opcua_key=opcua_key, write_rate_per_s=write_rate, write_burst=write_burst)
        # uvicorn takes SIGTERM over while it serves and restores this handler before
        # re-raising the signal after its graceful shutdown (module docstring)
        previous = signal.signal(signal.SIGTERM, _exit_cleanly)
        try:
            # open SSE/MJPEG streams end when the runtime closes; this bounds the wait for them
            uvicorn.run(create_app(settings), host=host, port=port, timeout_graceful_shutdown=5,
                        log_level="info")
        except OSError as exc:
            fail(f"cannot listen on {host}:{port}: {exc.strerror or exc}")
        finally:
            signal.signal(signal.SIGTERM, previous)
