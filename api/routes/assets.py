"""Compensation models and camera calibrations: upload (validated), list, activate.

An upload is checked with the station's own readers (``model_from_dict``,
``CameraCalibration.from_json``) before it is kept, so a version that exists can be
activated. Activation applies to the running station at once (not during a job:
409), and every upload and activation goes to the audit log with who did it.
"""

from __future__ import annotations

import json
import tomllib

from fastapi import APIRouter, File, Form, HTTPException, UploadFile, status

from api.deps import EngineerDep, ReaderDep, RuntimeDep
from api.routes.common import blocking, read_upload
from api.runtime import StationRuntime
from api.schemas.assets import ModelCurves, UploadedVersion, VersionList
from api.versions import VersionStore

router = APIRouter(prefix="/api/v1", tags=["models and calibrations"])


def model_store(rt: StationRuntime) -> VersionStore:
    return VersionStore(rt.settings.data_path / "models", "toml")


def calibration_store(rt: StationRuntime) -> VersionStore:
    return VersionStore(rt.settings.data_path / "calibrations", "json")


def parse_model(text: str, source: str):
    from station.kinematics.model import model_from_dict

    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{source}: not valid TOML: {exc}") from None
    try:
        return model_from_dict(data, source)
    except (KeyError, TypeError, IndexError) as exc:  # a wrong shape deep in the file
        raise ValueError(f"{source}: not a station model: {type(exc).__name__}: {exc}") from None


def parse_calibration(text: str, source: str):
    from station.vision.calibration import CameraCalibration

    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{source}: not valid JSON: {exc}") from None
    try:
        if not isinstance(data, dict):
            raise ValueError("the calibration must be a JSON object")
        cal = CameraCalibration.from_json(data)
    except (KeyError, TypeError) as exc:
        raise ValueError(f"{source}: not a camera calibration: missing or wrong {exc}") from None
    except ValueError as exc:
        raise ValueError(f"{source}: not a camera calibration: {exc}") from None
    if cal.mm_per_px is not None and not (isinstance(cal.mm_per_px, (int, float)) and cal.mm_per_px > 0):
        raise ValueError(f"{source}: mm_per_px must be a positive number")
    return cal


def _use_model(rt: StationRuntime, model) -> None:
    """On the station loop: ``model`` with the engineer-approved changes over it (the
    station's model proposals, docs/monitor.md: applied over whatever model the station
    is configured with, at every start and at every activation), and the station's
    charts started again (their reference was the old model's predictions)."""
    from station.monitor.proposals import apply_changes

    approved = rt.session.proposals.approved_changes()
    if approved:
        model = apply_changes(model, approved, f"+{len(approved)}")
    rt.station.model = model
    rt.session.watch.model_changed()


async def apply_model(rt: StationRuntime, text: str, source: str) -> None:
    """The compensation model the next inspection uses: parsed in a worker thread,
    set on the station loop (the station reads it there)."""
    model = await blocking(parse_model, text, source)
    await rt.thread.run(_use_model, rt, model)


def _set_scale(rt: StationRuntime, mm_per_px: float) -> None:
    """On the station loop: the vision scale and the engine's measure and surface stages
    together (the camera's pixel map kept)."""
    from station.inspection.session import vision_defects, vision_measure

    rt.station.mm_per_px = mm_per_px
    pmap = getattr(rt.station, "pixel_map", None)
    rt.engine.devices.measure = vision_measure(mm_per_px, pmap)
    if rt.engine.devices.surface is not None:
        rt.engine.devices.surface = vision_defects(mm_per_px, pmap)


async def apply_calibration(rt: StationRuntime, text: str, source: str) -> None:
    """The scale at the bore wall the vision stage measures with (when the file has one)."""
    cal = await blocking(parse_calibration, text, source)
    if cal.mm_per_px is not None:
        await rt.thread.run(_set_scale, rt, float(cal.mm_per_px))


KINDS = {
    "models": (model_store, parse_model, apply_model, "compensation model"),
    "calibrations": (calibration_store, parse_calibration, apply_calibration, "camera calibration"),
}


def _listing(store: VersionStore) -> dict:
    index = store.index()
    return {"active": index["active"],
            "items": [{**v, "active": v["version"] == index["active"]} for v in index["versions"]]}


def _register(kind: str) -> None:
    store_of, parse, apply, what = KINDS[kind]

    @router.get(f"/{kind}", name=f"list_{kind}", response_model=VersionList)
    async def list_versions(rt: RuntimeDep, who: ReaderDep) -> dict:
        return await blocking(_listing, store_of(rt))

    @router.post(f"/{kind}", name=f"upload_{kind}", status_code=status.HTTP_201_CREATED,
                 response_model=UploadedVersion,
                 responses={413: {"description": "file too large"}, 422: {"description": "not a valid file"}})
    async def upload(rt: RuntimeDep, who: EngineerDep, file: UploadFile = File(..., description=f"the {what} file"),
                     name: str = Form("", max_length=64, description="a short name for the version")) -> dict:
        text = await read_upload(file, rt.settings.max_upload_bytes, what)
        source = file.filename or what
        try:
            await blocking(parse, text, source)
        except ValueError as exc:
            raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, str(exc)) from None
        entry = await blocking(store_of(rt).add, text, who=who.name, name=name, filename=source)
        await blocking(rt.audit, who.who, f"uploaded {what} version {entry['version']} ({source}, "
                                          f"sha256 {entry['sha256'][:12]})")
        return entry

    @router.post(f"/{kind}/{{version}}/activate", name=f"activate_{kind}", response_model=UploadedVersion,
                 responses={404: {"description": "no such version"}, 409: {"description": "a job is running"}})
    async def activate(version: int, rt: RuntimeDep, who: EngineerDep) -> dict:
        store = store_of(rt)
        entry = await blocking(store.entry, version)
        if entry is None:
            raise HTTPException(status.HTTP_404_NOT_FOUND, f"no {what} version {version}")
        if rt.busy:
            raise HTTPException(status.HTTP_409_CONFLICT, f"cannot change the {what} while a job runs")
        text = await blocking(store.text, version)
        await apply(rt, text, f"{kind}/{version}")
        await blocking(store.activate, version)
        await blocking(rt.audit, who.who, f"activated {what} version {version}")
        return {**entry, "active": True}


for _kind in KINDS:
    _register(_kind)


async def apply_active(rt: StationRuntime) -> None:
    """At start: the station uses the versions last activated, not the config's defaults."""
    for kind, (store_of, _parse, apply, _what) in KINDS.items():
        store = store_of(rt)
        active = (await blocking(store.index))["active"]
        if active is not None:
            await apply(rt, await blocking(store.text, active), f"{kind}/{active}")


# ---------------------------------------------------------------------- the active model's curves
#: sample points per curve for the panel's plots
CURVE_POINTS = 121


def _sample(curve, x, unit: str) -> dict:
    import numpy as np

    if curve.is_zero:
        return {"unit": unit, "zero": True, "values": [0.0] * len(x)}
    up = np.asarray(curve.evaluate(x, np.ones_like(x)), dtype=float)
    down = np.asarray(curve.evaluate(x, -np.ones_like(x)), dtype=float)
    out = {"unit": unit, "zero": False, "values": [round(float(v), 4) for v in up]}
    if not np.allclose(up, down):  # a direction-dependent effect (backlash): both approaches
        out["values_down"] = [round(float(v), 4) for v in down]
    return out


def curves_of(model, points: int = CURVE_POINTS) -> dict:
    """Every error motion of Z and C sampled over its travel, and each non-zero
    curve's baseline table (the compensation table: the correction is minus the
    deviation)."""
    import numpy as np

    from station.kinematics.parameters import COMPONENT_UNITS, motion_names

    axes, tables = {}, {}
    for axis, unit, lo_hi in (("Z", "mm", model.z_travel_mm), ("C", "deg", (0.0, 360.0))):
        x = np.linspace(float(lo_hi[0]), float(lo_hi[1]), points)
        motions = model.motions_of(axis)
        curves = {}
        for name, curve, cunit in zip(motion_names(axis), motions.curves(), COMPONENT_UNITS):
            curves[name] = _sample(curve, x, cunit)
            if curve.target:
                tables[name] = {"axis": axis, "position_unit": unit, "unit": cunit,
                                "target": list(curve.target), "deviation": list(curve.deviation),
                                "correction": [-d for d in curve.deviation],
                                "effects": [type(e).__name__ for e in curve.effects]}
        axes[axis] = {"unit": unit, "positions": [round(float(v), 4) for v in x], "curves": curves}
    return {"model": model.name, "axes": axes, "compensation_tables": tables}


@router.get("/models/active/curves", tags=["models and calibrations"], response_model=ModelCurves,
            response_model_exclude_unset=True)
async def active_model_curves(rt: RuntimeDep, who: ReaderDep) -> dict:
    """The error motions of the model the station compensates with now (ISO 230-1
    names: EXZ..ECZ of Z over its travel, EXC..ECC of C over a turn; um and arcsec),
    for the panel's plots, and the baseline tables with their corrections."""
    out = await blocking(curves_of, rt.station.model)
    out["version"] = (await blocking(model_store(rt).index))["active"]
    return out
