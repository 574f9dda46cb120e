"""What the API process is started with (``station serve`` fills it from its options)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

#: largest upload (model TOML, calibration JSON, recording CSV, part spec): these are
#: small text files; a bigger body is a mistake or an attack, refused with 413
MAX_UPLOAD_BYTES = 1024 * 1024


@dataclass
class Settings:
    #: station config TOML (None: the embedded default, a simulated station)
    config: str | Path | None = None
    #: twin scenario (simulation only)
    scenario: str | Path | None = None
    #: data folder: database, image crops, part specs, models, calibrations
    data_dir: str | Path = "var"
    #: database URL (None: SQLite in the data folder)
    db_url: str | None = None
    #: this station's id on a shared database (None: the config's ``[station] id``
    #: or name; docs/plant.md)
    station_id: str | None = None
    #: simulation: moves run this much faster than real time
    time_scale: float | None = None
    max_upload_bytes: int = MAX_UPLOAD_BYTES
    #: mark the panel's session cookie ``Secure`` (sent over https only) whatever the
    #: request's scheme: True for a station behind a TLS-terminating reverse proxy that
    #: does not pass ``X-Forwarded-Proto`` from a trusted address; False (default) for
    #: plain http on 127.0.0.1 or a segmented station network. A request that arrives
    #: as https (directly or through a trusted proxy) gets ``Secure`` either way.
    cookie_secure: bool = False
    #: the OPC UA server beside REST, ``opc.tcp://HOST:PORT`` (None: none; api/opcua.py,
    #: docs/opcua.md), and its certificate and private key (PEM or DER; both or neither:
    #: with them Basic256Sha256 is offered besides SecurityPolicy None)
    opcua_endpoint: str | None = None
    opcua_cert: str | Path | None = None
    opcua_key: str | Path | None = None
    #: how often the camera stream grabs a frame while no inspection runs
    idle_camera_hz: float = 2.0
    #: SSE keep-alive comment interval (proxies close silent connections)
    sse_keepalive_s: float = 15.0
    #: longest a station command (reset, a driver read) may take before the API gives up
    command_timeout_s: float = 10.0
    #: writes (POST/PUT/PATCH/DELETE) per API token: a bucket of ``write_burst`` that
    #: refills at ``write_rate_per_s`` (api/ratelimit.py; 0 turns the limit off). A
    #: station does one inspection at a time, so an MES sends a job order per part
    #: (tens of seconds each), a retry now and then and a burst of part specs at a
    #: changeover; an operator clicks a button or two a second. 5/s sustained with 60 at
    #: once is many times that, and caps a runaway client's writes (each one a
    #: transaction, an audit row, maybe a 1 MiB parse) at a small share of the two cores
    write_rate_per_s: float = 5.0
    write_burst: int = 60
    #: tests and studies only: a sim.world.World whose part replaces the scenario's
    world: Any = None
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def data_path(self) -> Path:
        return Path(self.data_dir)

    @property
    def parts_dir(self) -> Path:
        return self.data_path / "parts"
