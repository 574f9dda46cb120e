"""All twin servers of the station, started and stopped together.

:class:`TwinStation` builds, from a scenario (``sim/scenarios/*.toml``), one
:class:`~sim.servo.physics.ServoAxisPhysics` and one Modbus TCP server per axis and
the grating-encoder twin on a pty, and runs them in the caller's asyncio loop.
:class:`TwinsThread` runs a TwinStation in a loop of its own in a background thread,
for synchronous callers (the CLI, benches, sync tests).

Where the world plugs in (see also docs/drivers.md):

* ``station.physics["Z"].actual_offset = fn(motor_position_mm, direction, time_s) -> mm``
  (same for ``"C"`` in deg): the carriage's deviation from the motor position;
* ``station.encoder.position_mm = fn() -> mm``: what the grating reads (default: the Z
  physics' ``carriage_position``, which already includes ``actual_offset``).
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, Callable

from sim.encoder.twin import SerialEncoderTwin
from sim.servo.modbus_face import ModbusDriveTwin
from sim.servo.null_modem import PtyNullModem
from sim.servo.physics import ServoAxisConfig, ServoAxisPhysics
from station.loopthread import LoopThread

DEFAULT_SCENARIO = Path(__file__).with_name("scenarios") / "default.toml"


class ScenarioError(ValueError):
    """A scenario file that cannot be used; the message names the file and the key."""


@dataclass
class AxisScenario:
    config: ServoAxisConfig
    device_id: int = 1
    port: int = 0
    unit_per_count: float = 1e-4
    #: also serve Modbus RTU on a pty null modem (the driver opens ``endpoints()[name]["rtu_path"]``)
    rtu: bool = False
    rtu_baudrate: int = 115200


@dataclass
class EncoderScenario:
    axis: str = "Z"
    resolution_um: float = 0.05
    baudrate: int = 115200
    model: str = "GRT-005"
    version: str = "V1.3"


@dataclass
class Scenario:
    host: str = "127.0.0.1"
    time_scale: float = 1.0
    axes: dict[str, AxisScenario] = field(default_factory=dict)
    encoder: EncoderScenario | None = None
    source: str = "<built-in>"


def load_scenario(path: str | Path | None = None) -> Scenario:
    """Read a scenario TOML file (default: ``sim/scenarios/default.toml``)."""
    path = Path(path) if path is not None else DEFAULT_SCENARIO
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8-sig"))
    except FileNotFoundError:
        raise ScenarioError(f"scenario file not found: {path}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{path}: not valid TOML: {exc}") from None
    return scenario_from_dict(data, str(path))


def scenario_from_dict(data: dict[str, Any], source: str = "<dict>") -> Scenario:
    station = data.get("station", {})
    host = station.get("host", "127.0.0.1")
    if host not in ("127.0.0.1", "localhost"):
        raise ScenarioError(f"{source}: twins listen on loopback only, not {host!r}")
    cfg_names = {f.name for f in fields(ServoAxisConfig)}
    axes: dict[str, AxisScenario] = {}
    for name, spec in data.get("axes", {}).items():
        spec = dict(spec)
        device_id = int(spec.pop("device_id", 1))
        port = int(spec.pop("port", 0))
        unit_per_count = float(spec.pop("unit_per_count", 1e-4))
        rtu = bool(spec.pop("rtu", False))
        rtu_baudrate = int(spec.pop("rtu_baudrate", 115200))
        unknown = set(spec) - cfg_names
        if unknown:
            raise ScenarioError(f"{source}: axes.{name} has unknown keys {sorted(unknown)}")
        axes[name] = AxisScenario(
            ServoAxisConfig(name=name, **spec), device_id, port, unit_per_count, rtu, rtu_baudrate
        )
    encoder = None
    if "encoder" in data:
        enc = dict(data["encoder"])
        unknown = set(enc) - {f.name for f in fields(EncoderScenario)}
        if unknown:
            raise ScenarioError(f"{source}: encoder has unknown keys {sorted(unknown)}")
        encoder = EncoderScenario(**enc)
        if encoder.axis not in axes:
            raise ScenarioError(f"{source}: encoder reads axis {encoder.axis!r}, which is not defined")
    return Scenario(host, float(station.get("time_scale", 1.0)), axes, encoder, source)


class TwinStation:
    """The physics, the drive servers and the encoder twin of one scenario."""

    def __init__(self, scenario: Scenario | None = None, *, clock: Callable[[], float] | None = None):
        self.scenario = scenario or load_scenario()
        kw = {"clock": clock} if clock is not None else {}
        self.physics: dict[str, ServoAxisPhysics] = {
            name: ServoAxisPhysics(ax.config, time_scale=self.scenario.time_scale, **kw)
            for name, ax in self.scenario.axes.items()
        }
        self.drives: dict[str, ModbusDriveTwin] = {
            name: ModbusDriveTwin(self.physics[name], device_id=ax.device_id, unit_per_count=ax.unit_per_count, name=name)
            for name, ax in self.scenario.axes.items()
        }
        self.null_modems: dict[str, PtyNullModem] = {}
        self.encoder: SerialEncoderTwin | None = None
        enc = self.scenario.encoder
        if enc is not None:
            self.encoder = SerialEncoderTwin(
                self.physics[enc.axis].carriage_position,
                resolution_um=enc.resolution_um,
                model=enc.model,
                version=enc.version,
            )
        self.running = False

    async def start(self) -> dict[str, Any]:
        try:
            for name, drive in self.drives.items():
                ax = self.scenario.axes[name]
                rtu_port = None
                if ax.rtu:
                    modem = self.null_modems[name] = PtyNullModem(f"{name}-rtu")
                    rtu_port, _ = modem.start()
                await drive.start(self.scenario.host, ax.port, rtu_port=rtu_port, baudrate=ax.rtu_baudrate)
            if self.encoder is not None:
                self.encoder.start()
        except BaseException:
            await self.stop()
            raise
        self.running = True
        return self.endpoints()

    async def stop(self) -> None:
        for drive in self.drives.values():
            await drive.stop()
        for modem in self.null_modems.values():
            modem.stop()
        self.null_modems.clear()
        if self.encoder is not None:
            self.encoder.stop()
        self.running = False

    def endpoints(self) -> dict[str, Any]:
        """Where everything listens: ``{"Z": {"host", "port", "device_id", ...}, "encoder": {...}}``."""
        out: dict[str, Any] = {}
        for name, d in self.drives.items():
            ax = self.scenario.axes[name]
            out[name] = {
                "protocol": "modbus-tcp",
                "host": d.host,
                "port": d.port,
                "device_id": d.device_id,
                "unit_per_count": ax.unit_per_count,
                "kind": ax.config.kind,
            }
            if name in self.null_modems:
                out[name]["rtu_path"] = self.null_modems[name].client_path
                out[name]["rtu_baudrate"] = ax.rtu_baudrate
        if self.encoder is not None and self.scenario.encoder is not None:
            out["encoder"] = {
                "protocol": "serial-ascii",
                "path": self.encoder.path,
                "baudrate": self.scenario.encoder.baudrate,
                "resolution_um": self.encoder.resolution_um,
                "axis": self.scenario.encoder.axis,
            }
        return out

    async def __aenter__(self):
        await self.start()
        return self

    async def __aexit__(self, *exc):
        await self.stop()


class TwinsThread:
    """A TwinStation in its own event loop on a background thread (``with TwinsThread() as t:``),
    for synchronous callers; the thread is :class:`station.loopthread.LoopThread`, which
    enters the TwinStation (starting its servers) on that loop and leaves it there."""

    #: how long stopping the servers and joining the thread may take
    STOP_TIMEOUT_S = 10.0

    def __init__(self, station: TwinStation | None = None, start_timeout_s: float = 10.0):
        self.station = station or TwinStation()
        self.start_timeout_s = start_timeout_s
        self._runner = LoopThread("twins")

    def start(self) -> dict[str, Any]:
        """Start the servers; returns where they listen (:meth:`TwinStation.endpoints`)."""
        self._runner.start(self.start_timeout_s)
        try:
            self._runner.enter(lambda: self.station, timeout=self.start_timeout_s)
        except TimeoutError:
            self._runner.stop(self.STOP_TIMEOUT_S)
            raise TimeoutError("the twins did not start in time") from None
        except BaseException:
            self._runner.stop(self.STOP_TIMEOUT_S)
            raise
        return self.station.endpoints()

    def call(self, fn: Callable[[], Any]) -> Any:
        """Run ``fn`` in the twins' loop thread and return its result (thread-safe access)."""
        return self._runner.call(fn, timeout=self.start_timeout_s)

    def stop(self) -> None:
        self._runner.stop(self.STOP_TIMEOUT_S)

    def __enter__(self):
        self.start()
        return self

    def __exit__(self, *exc):
        self.stop()
