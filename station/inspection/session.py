"""An inspection session: the station, the store and the service, built and torn down together.

The CLI (``station inspect``, ``station gauge``, ``station paper``), the benches and
the end-to-end tests all run inspections through this one object, so they exercise
the same code the plant runs.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from station.inspection.scan import CameraGeometry, ScanSettings
from station.inspection.service import InspectionOutcome, InspectionService
from station.parts.spec import PartSpec
from station.sequencer.engine import Devices, Engine


def vision_measure(mm_per_px: float):
    """The vision stage as the engine calls it: image -> hole measurements.  Its compiled
    kernels are loaded here, before any inspection (``warm_up``)."""
    from station.vision.measure import measure_holes, warm_up

    warm_up()

    def measure(image):
        return measure_holes(image, mm_per_px=mm_per_px)

    return measure


def truth_of(world) -> Any:
    """Simulation only: the twin's true value of a characteristic (hole id, kind)."""

    def truth(hole_id: str, kind: str):
        for h in world.part.holes:
            if h.name == hole_id:
                return h.axial_mm if kind == "position" else h.diameter_mm
        return None

    return truth


@dataclass
class Session:
    station: Any  # station.runtime.Station
    store: Any  # station.store.Store
    engine: Engine
    settings: ScanSettings

    def service_for(self, part: PartSpec) -> InspectionService:
        st = self.station
        geo = CameraGeometry(st.mm_per_px, st.frame_size_px[0], st.frame_size_px[1], part.bore.diameter_mm / 2.0)
        trace = {"config_hash": st.config_hash, "mode": st.mode}
        if st.twins is not None:
            trace["scenario"] = str(st.twins.station.scenario.source)
        return InspectionService(self.engine, self.store, st.model, geo, self.settings, traceability=trace,
                                 truth=truth_of(st.world) if st.world is not None else None,
                                 time_scale=st.time_scale)

    async def inspect(self, part: PartSpec, serial: str, **kw) -> InspectionOutcome:
        return await self.service_for(part).inspect(part, serial, **kw)


@contextlib.asynccontextmanager
async def open_session(config: str | Path | None = None, *, scenario: str | Path | None = None,
                       time_scale: float | None = None, data_dir: str | Path = "var", db_url: str | None = None,
                       settings: ScanSettings | None = None, world=None, model: str | Path | None = None):
    """Build the station, connect it, open the store (recovering interrupted
    inspections); close everything on the way out, whatever happened. ``model``: the
    station's model file (its belief), instead of the config's; ``world``: a caller's
    world whose part replaces the scenario's."""
    from station.runtime import build_station
    from station.store import Store

    station = build_station(config, scenario=scenario, time_scale=time_scale, model=model)
    store = None
    try:
        if world is not None and station.world is not None:
            # a caller's world (a test's or a study's part) replaces the scenario's
            station.world.part = world.part
        store = Store.open(db_url, data_dir=data_dir)
        await station.connect()
        devices = Devices(station.z, station.c, station.encoder, station.camera, measure=vision_measure(station.mm_per_px))
        yield Session(station, store, Engine(devices), settings or ScanSettings())
    finally:
        await station.close()
        if store is not None:
            store.close()
