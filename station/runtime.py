"""The composition root: build a running station from a config file.

This module (with the CLI) is the only place in ``station`` that imports concrete
drivers or ``sim``. Nothing else decides "simulated or real": a simulated station
is the *same real drivers* pointed at twin servers on 127.0.0.1 (and ptys), with the
world of the scenario plugged into the twins.

Config file (TOML), every key optional; the embedded default is a simulated station:

    [station]
    mode = "simulated"          # or "hardware"
    model = "path/to/model.toml"  # the station's geometric error model (default: built-in);
                                # in simulation never the world's (the scenario has its own)

    [simulation]
    scenario = "path/to/scenario.toml"  # default: sim/scenarios/default.toml
    time_scale = 20.0           # overrides the scenario's (moves run 20x faster)

    [hardware.Z]                # mode = "hardware" only
    transport = "tcp"           # or "rtu"
    host = "192.168.10.11"      # tcp
    port = 502
    serial_port = "/dev/ttyUSB0"  # rtu
    baudrate = 115200
    device_id = 1
    unit_per_count = 0.0001
    default_velocity = 20.0
    default_acceleration = 200.0
    max_velocity = 50.0         # the scan's moves (default: default_velocity)
    max_acceleration = 500.0    # (default: default_acceleration)

    [hardware.C]                # as Z
    [hardware.encoder]
    serial_port = "/dev/ttyUSB1"
    baudrate = 115200
    resolution_um = 0.05

    [hardware.camera]
    device = "/dev/video0"      # or an index
    width = 1280
    height = 1024
    mm_per_px = 0.010           # scale at the bore wall, from `station vision calibrate`
    calibration = "camera.json" # optional: `station vision calibrate`'s file (the lens's
                                # distortion, for the surface scan's off-centre defects)
    exposure = 100.0            # optional, driver units
    gain = 0.0                  # optional
    exposure_s = 0.008          # optional: the sensor's exposure and readout (s),
    readout_s = 0.025           # for the cycle time's lower bound
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import hashlib
import logging
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from drivers.interfaces import Camera, CameraTiming, CommunicationLost, DeviceTimeout, LinearAxis, PositionEncoder, RotaryAxis
from station.kinematics.model import StationModel, load_model

log = logging.getLogger(__name__)

#: tries of each device's connect at start: the sequencer retries a lost link while it
#: runs, nothing did at start, and a clean-clone CI run once lost a session's start to
#: one 0.5 s connect timeout (a loop stalled on a loaded machine, most likely)
CONNECT_ATTEMPTS = 2


#: the station id of a config that names none (and has no name)
DEFAULT_STATION_ID = "station"


def config_station_id(data: dict[str, Any], source: str) -> str:
    """The station's id on a shared database: the config's ``[station] id``, else its
    ``name``, else "station"; checked (letters, digits, '.', '_', '-'; it names the
    station in URLs, file names and OPC UA nodes)."""
    from station.store.repository import check_station_id

    table = data.get("station") if isinstance(data.get("station"), dict) else {}
    if "id" in table:
        value, key = table["id"], "[station] id"
    else:
        value, key = data.get("name", DEFAULT_STATION_ID), "name"
    try:
        check_station_id(value)
    except ValueError as exc:
        raise ConfigError(f"{source}: {key}: {exc}") from None
    return value


class ConfigError(ValueError):
    """A station config that cannot be used; names the file and the key."""


@dataclass
class Station:
    """A built station: drivers, the error model and, when simulated, the twins."""

    z: LinearAxis
    c: RotaryAxis
    encoder: PositionEncoder | None
    model: StationModel
    mode: str
    config_hash: str
    camera: Camera | None = None
    #: the camera's scale at the bore wall and its frame size
    mm_per_px: float = 0.010
    frame_size_px: tuple[int, int] = (1280, 1024)
    #: how much faster than real time the twins' motion runs; None on hardware (the
    #: wall clock is the machine's)
    time_scale: float | None = None
    twins: Any = None  # sim.twins.TwinsThread when simulated
    world: Any = None  # sim.world.World when simulated
    endpoints: dict[str, Any] = field(default_factory=dict)
    #: this station's id on a shared database (docs/plant.md): the config's
    #: ``[station] id``, else its ``name``
    station_id: str = DEFAULT_STATION_ID
    #: the camera's calibration (``station.vision.calibration.CameraCalibration``): its
    #: lens's distortion, for what the station measures off the frame's centre (the
    #: surface scan's defects and picture); None: not calibrated (everything re-centred)
    camera_calibration: Any = None
    #: the camera's flawed pixels (``station.vision.pixelmap.PixelMap``, from ``station
    #: vision pixel-map``), mended in every frame before it is measured; None: none known
    pixel_map: Any = None

    @contextlib.contextmanager
    def master_on_table(self, cert, *, bore_diameter_mm: float, seed: int = 0):
        """The certified master on the table for a check. On hardware the operator has
        put it there; in simulation the twin's world holds the master (made within its
        certificate, ``sim.masters``) until the block ends, then the production part again."""
        def make():
            from sim.masters import master_part

            return master_part(cert, bore_diameter_mm=bore_diameter_mm, seed=seed)

        with self._part_on_table(make):
            yield

    @contextlib.contextmanager
    def artefact_on_table(self, cert, *, seed: int = 0):
        """The calibration artefact (an ``ArtefactCertificate``) on the table for a
        self-calibration run (docs/calibration.md). On hardware the operator has put it
        there; in simulation the twin's world holds the artefact (its targets made within
        the certificate's U, ``sim.masters.artefact_part``) until the block ends, then the
        production part again."""
        def make():
            from sim.masters import artefact_part

            return artefact_part(cert, seed=seed)

        with self._part_on_table(make):
            yield

    @contextlib.contextmanager
    def _part_on_table(self, make):
        """Simulation: the world holds ``make()``'s part until the block ends, then its
        production part again; on hardware nothing to do (the operator placed it)."""
        if self.world is None:
            yield
            return
        saved = self.world.part
        self.world.part = make()
        try:
            yield
        finally:
            self.world.part = saved

    def world_model_now(self):
        """Simulation only: the world's true error model as its drift has left it now
        (ground truth, for annotating results; never an input to a measurement); None
        on hardware."""
        if self.world is None or self.twins is None:
            return None
        z = self.twins.station.physics["Z"]
        return self.world.effective_model(z.now())

    def traceability(self) -> dict[str, Any]:
        """What an inspection's record says of the station that made it: the config's
        hash, the mode and, in simulation, the scenario the world came from."""
        trace: dict[str, Any] = {"config_hash": self.config_hash, "mode": self.mode}
        if self.twins is not None:
            trace["scenario"] = str(self.twins.station.scenario.source)
        return trace

    def truth_annotator(self):
        """Simulation only: a subscriber to the inspections' documents that writes the
        twin's true value beside each measured characteristic (an annotation for tests
        and benches, never an input to a measurement); None on hardware."""
        if self.world is None:
            return None
        return TruthAnnotator(self.world)

    async def connect(self) -> None:
        for dev in (self.z, self.c, self.encoder, self.camera):
            if dev is None:
                continue
            for attempt in range(1, CONNECT_ATTEMPTS + 1):
                try:
                    await dev.connect()
                    break
                except (CommunicationLost, DeviceTimeout) as exc:
                    if attempt == CONNECT_ATTEMPTS:
                        raise
                    log.warning("%s; trying once more", exc)

    async def close(self) -> None:
        """Close drivers, then stop the twins; never raises for a link already gone."""
        for dev in (self.camera, self.encoder, self.c, self.z):
            if dev is None:
                continue
            try:
                await dev.close()
            except Exception:  # noqa: BLE001 - closing must not hide the first error
                pass
        if self.twins is not None:
            self.twins.stop()
            self.twins = None


class TruthAnnotator:
    """The twin's ground truth beside each characteristic, from the check documents of
    an inspection (station.inspection.documents): the world's hole of the same name
    at the time of the check (the part on the table then: a master's during a check)."""

    def __init__(self, world):
        self.world = world

    def __call__(self, doc) -> None:
        from station.inspection.documents import CheckDocument, SurfaceDocument

        if isinstance(doc, SurfaceDocument) and doc.surface is not None:
            from sim.world import match_defects

            for d, truth in match_defects(self.world, doc.surface.defects):
                d.truth = truth
            return
        if not isinstance(doc, CheckDocument) or doc.characteristic is None:
            return
        c = doc.characteristic
        hole_id, _, kind = c.id.rpartition(".")
        if kind not in ("position", "diameter"):
            return  # a surface criterion: its truth is each defect's (the surface document's)
        for h in self.world.part.holes:
            if h.name == hole_id:
                c.true_value = h.axial_mm if kind == "position" else h.diameter_mm
                return


@contextlib.asynccontextmanager
async def open_session(config: str | Path | None = None, *, scenario: str | Path | None = None,
                       time_scale: float | None = None, data_dir: str | Path = "var", db_url: str | None = None,
                       settings=None, world=None, model: str | Path | None = None,
                       station_id: str | None = None):
    """Build the station, connect it, open the store (recovering interrupted
    inspections) and yield an inspection session (``station.inspection.session.Session``);
    close everything on the way out, whatever happened. ``model``: the station's model
    file (its belief), instead of the config's; ``world``: a caller's world whose part
    replaces the scenario's; ``station_id``: the station's id on the database, instead
    of the config's."""
    from station.inspection.scan import ScanSettings
    from station.inspection.session import Session, vision_defects, vision_measure
    from station.monitor.watch import StationWatch
    from station.stallwatch import StallWatch, heap_frozen
    from station.sequencer.engine import Devices, Engine
    from station.store import Store

    station = build_station(config, scenario=scenario, time_scale=time_scale, model=model)
    store = None
    try:
        if world is not None and station.world is not None:
            # a caller's world (a test's or a study's part) replaces the scenario's
            station.world.part = world.part
        if station_id is not None:
            station.station_id = station_id
        store = Store.open(db_url, data_dir=data_dir, station_id=station.station_id)
        # seconds of work (the vision kernels loaded or compiled, the control charts'
        # limits solved) done in threads before the drives connect: once connected,
        # their heartbeats ride this loop, and a drive's watchdog trips on a stall of 1 s
        settings = settings or ScanSettings()
        measure = await asyncio.to_thread(vision_measure, station.mm_per_px, station.pixel_map)
        watch = await asyncio.to_thread(StationWatch, gate_um=settings.model_u_um)
        # the heap built so far (kernels, store, app) is left out of the collections the
        # session's life brings: a full one over it held the loop for 0.4-0.75 s. Its
        # garbage is collected first, here, before the drives' heartbeats ride the loop
        with heap_frozen():
            await station.connect()
            devices = Devices(station.z, station.c, station.encoder, station.camera, measure=measure,
                              surface=vision_defects(station.mm_per_px, station.pixel_map))
            session = Session(station, store, Engine(devices), settings, watch=watch)
            annotator = station.truth_annotator()
            if annotator is not None:
                session.documents.subscribe(annotator)
            async with StallWatch(stall_limit_s(station)):
                try:
                    yield session
                finally:
                    # the engine's last events reach the log before the store closes
                    await session.event_log.flush()
    finally:
        await station.close()
        if store is not None:
            store.close()


def stall_limit_s(station) -> float:
    """How long the station's loop may stall before it is logged (``station.stallwatch``):
    half the shortest watchdog of its drives, 0.5 s with none armed."""
    timeouts = [ax.watchdog_timeout_ms / 1000.0 for ax in (station.z, station.c)
                if ax is not None and getattr(ax, "watchdog_timeout_ms", 0)]
    return 0.5 * min(timeouts) if timeouts else 0.5


def load_config(path: str | Path | None) -> tuple[dict[str, Any], str]:
    """The config dict and its hash (for traceability); None gives the embedded default."""
    if path is None:
        text = '[station]\nmode = "simulated"\n'
        source = "<embedded default>"
    else:
        p = Path(path)
        try:
            text = p.read_text(encoding="utf-8-sig")
        except OSError as exc:
            raise ConfigError(f"{p}: {exc.strerror}") from None
        source = str(p)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{source}: not valid TOML: {exc}") from None
    data["_source"] = source
    return data, hashlib.sha256(text.encode()).hexdigest()[:16]


def _axis_driver(cls, name: str, spec: dict[str, Any], source: str):
    from drivers.modbus_axis import ModbusServoAxis  # noqa: F401 (cls is one of its subclasses)

    transport = spec.get("transport", "tcp")
    common = dict(
        name=name,
        device_id=int(spec.get("device_id", 1)),
        unit_per_count=float(spec.get("unit_per_count", 1e-4)),
        default_velocity=float(spec.get("default_velocity", 20.0)),
        default_acceleration=float(spec.get("default_acceleration", 200.0)),
    )
    for key, arg in (("max_velocity", "velocity_limit"), ("max_acceleration", "acceleration_limit")):
        if key in spec:
            try:
                common[arg] = float(spec[key])
            except (TypeError, ValueError):
                raise ConfigError(f"{source}: [hardware.{name}] {key} must be a number, not {spec[key]!r}") from None
    if "timeout_s" in spec:
        common["timeout_s"] = float(spec["timeout_s"])
    if transport == "tcp":
        if "host" not in spec:
            raise ConfigError(f"{source}: [hardware.{name}] needs 'host' for transport tcp")
        return cls.tcp(str(spec["host"]), int(spec.get("port", 502)), **common)
    if transport == "rtu":
        if "serial_port" not in spec:
            raise ConfigError(f"{source}: [hardware.{name}] needs 'serial_port' for transport rtu")
        return cls.rtu(str(spec["serial_port"]), int(spec.get("baudrate", 115200)), **common)
    raise ConfigError(f"{source}: [hardware.{name}] transport must be 'tcp' or 'rtu', not {transport!r}")


#: the simulated station's calibration of the twin's endoscope (``station sim
#: camera-calibration --out``; a config's ``[simulation] calibration`` replaces it)
SIM_CAMERA_CALIBRATION = Path(__file__).parent / "data" / "camera" / "endoscope-twin.json"


def build_station(config_path: str | Path | None = None, *, scenario: str | Path | None = None,
                  time_scale: float | None = None, model: str | Path | None = None) -> Station:
    """Build (not yet connect) the station the config describes. A simulated station's
    twins are started here, on 127.0.0.1, and stopped by :meth:`Station.close`.
    ``model``: the station's model file, instead of the config's."""
    from drivers.encoder import SerialGratingEncoder
    from drivers.modbus_axis import ModbusLinearAxis, ModbusRotaryAxis

    data, chash = load_config(config_path)
    source = data["_source"]
    st = data.get("station", {})
    mode = st.get("mode", "simulated")
    base = Path(source).parent if config_path is not None else Path.cwd()

    def resolve(p: str) -> Path:
        """Paths in a config are relative to the config file."""
        q = Path(p)
        return q if q.is_absolute() else base / q

    if model is not None:
        model = load_model(model)
    else:
        model = load_model(resolve(st["model"])) if "model" in st else load_model()

    def camera_calibration(table: dict, where: str, default: Path | None = None):
        """The camera's calibration file named by ``table["calibration"]`` (else
        ``default``; ``false``: none), loaded; a clear error naming the file when it is
        not one."""
        from station.vision.calibration import CameraCalibration

        given = table.get("calibration")
        if given is False:  # "not calibrated": what the station measures off-centre is re-centred
            return None
        path = resolve(str(given)) if given is not None else default
        if path is None:
            return None
        try:
            return CameraCalibration.load(path)
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise ConfigError(f"{source}: {where} calibration: {path}: {exc}") from None

    def pixel_map(table: dict, where: str, size: tuple[int, int]):
        """The camera's pixel map named by ``table["pixel_map"]``, loaded and checked
        against the frame's ``size``; None when not named."""
        from station.vision.pixelmap import PixelMap

        given = table.get("pixel_map")
        if given is None:
            return None
        path = resolve(str(given))
        try:
            pmap = PixelMap.load(path)
        except OSError as exc:
            raise ConfigError(f"{source}: {where} pixel_map: {path}: {exc.strerror or exc}") from None
        except ValueError as exc:
            raise ConfigError(f"{source}: {where} pixel_map: {exc}") from None
        if (pmap.width, pmap.height) != tuple(size):
            raise ConfigError(f"{source}: {where} pixel_map: {path} is for {pmap.width} x {pmap.height} frames, "
                              f"the camera's are {size[0]} x {size[1]}")
        return pmap

    if mode == "hardware":
        hw = data.get("hardware", {})
        for key in ("Z", "C"):
            if key not in hw:
                raise ConfigError(f"{source}: mode 'hardware' needs a [hardware.{key}] table")
        z = _axis_driver(ModbusLinearAxis, "Z", hw["Z"], source)
        c = _axis_driver(ModbusRotaryAxis, "C", hw["C"], source)
        enc = None
        if "encoder" in hw:
            e = hw["encoder"]
            enc = SerialGratingEncoder(str(e["serial_port"]), baudrate=int(e.get("baudrate", 115200)),
                                       resolution_um=float(e.get("resolution_um", 0.05)))
        cam, scale, size, cal, pmap = None, 0.010, (1280, 1024), None, None
        if "camera" in hw:
            from drivers.camera import OpenCVCamera

            k = hw["camera"]
            if "mm_per_px" not in k:
                raise ConfigError(f"{source}: [hardware.camera] needs 'mm_per_px' (from a calibration)")
            dev = k.get("device", 0)
            size = (int(k.get("width", 1280)), int(k.get("height", 1024)))
            try:
                # the camera's encoding gamma: frames are made linear in light before any
                # measurement (drivers.interfaces.pixels.linearize); 1 when it is switched off
                gamma = float(k.get("response_gamma", 1.0))
                cam = OpenCVCamera(dev, width=size[0], height=size[1], exposure=k.get("exposure"), gain=k.get("gain"),
                                   response_gamma=gamma)
            except (TypeError, ValueError) as exc:
                raise ConfigError(f"{source}: [hardware.camera] response_gamma: {exc}") from None
            if "exposure_s" in k and "readout_s" in k:
                try:
                    cam.timing = CameraTiming(float(k["exposure_s"]), float(k["readout_s"]))
                except (TypeError, ValueError) as exc:
                    raise ConfigError(f"{source}: [hardware.camera] exposure_s / readout_s: {exc}") from None
            scale = float(k["mm_per_px"])
            cal = camera_calibration(k, "[hardware.camera]")
            pmap = pixel_map(k, "[hardware.camera]", size)
        return Station(z, c, enc, model, mode, chash, camera=cam, mm_per_px=scale, frame_size_px=size,
                       station_id=config_station_id(data, source), camera_calibration=cal, pixel_map=pmap)

    if mode != "simulated":
        raise ConfigError(f"{source}: [station] mode must be 'simulated' or 'hardware', not {mode!r}")

    from sim.twins import TwinsThread, TwinStation, load_scenario
    from sim.world import load_world

    sim_cfg = data.get("simulation", {})
    scen_path = scenario or (resolve(sim_cfg["scenario"]) if "scenario" in sim_cfg else None)
    scen = load_scenario(scen_path)
    ts = time_scale if time_scale is not None else sim_cfg.get("time_scale")
    if ts is not None:
        scen.time_scale = float(ts)
    # Two models, always (docs/world.md): the world is the scenario's (what the machine
    # really does), the station's model is the config's (what was measured, some time
    # ago). Neither is copied into the other: a station told the world's truth would
    # measure only its own consistency.
    world = load_world(scen_path)
    twins = TwinsThread(TwinStation(scen))
    endpoints = twins.start()
    try:
        world.attach(twins.station)
        axes = {}
        for key, cls in (("Z", ModbusLinearAxis), ("C", ModbusRotaryAxis)):
            ep = endpoints[key]
            ax_scen = scen.axes[key]
            axes[key] = cls.tcp(
                ep["host"], ep["port"], name=key, device_id=ep["device_id"], unit_per_count=ep["unit_per_count"],
                default_velocity=ax_scen.config.default_velocity, default_acceleration=ax_scen.config.default_acceleration,
                # the scan moves at the drive's limits, as an integrator would set them
                velocity_limit=ax_scen.config.max_velocity, acceleration_limit=ax_scen.config.max_acceleration,
            )
        enc = None
        if "encoder" in endpoints:
            e = endpoints["encoder"]
            enc = SerialGratingEncoder(e["path"], baudrate=e["baudrate"], resolution_um=e["resolution_um"])
        from sim.camera.twin import CameraOptics, CameraTwin

        optics = CameraOptics()
        if world.camera_sensor is not None:
            # the world's camera has flawed pixels: the twin renders them, the station
            # knows of them only through its pixel map ([simulation] pixel_map)
            optics = dataclasses.replace(optics, params=dataclasses.replace(optics.params, sensor=world.camera_sensor))
        cam = CameraTwin(world, twins.station.physics["Z"], twins.station.physics["C"], optics, render_process=True)
    except BaseException:
        twins.stop()
        raise
    # the twin's endoscope as the station knows it: a calibration from chessboard views
    # rendered through its lens (`station sim camera-calibration`), never the lens itself
    cal = camera_calibration(sim_cfg, "[simulation]", SIM_CAMERA_CALIBRATION)
    try:
        pmap = pixel_map(sim_cfg, "[simulation]", (optics.params.width_px, optics.params.height_px))
    except BaseException:
        twins.stop()
        raise
    return Station(axes["Z"], axes["C"], enc, model, mode, chash, camera=cam, mm_per_px=optics.mm_per_px,
                   frame_size_px=(optics.params.width_px, optics.params.height_px), time_scale=scen.time_scale,
                   twins=twins, world=world, endpoints=endpoints, station_id=config_station_id(data, source),
                   camera_calibration=cal, pixel_map=pmap)
