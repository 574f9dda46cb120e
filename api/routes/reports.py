"""Reports computed from uploads: ISO 230-2 figures of a recording, and mismatch
discovery (model + recording). The JSON is the contract of the matching CLI commands
(``station iso230 --json``, ``station discover``).

Every discovery report is also kept in the data folder
(``<data>/reports/discovery/<id>.json``: who, when, the files' names and the report),
so the panel can list them: ``GET /reports/discovery`` (newest first, a summary each)
and ``GET /reports/discovery/{id}``; the POST's ``Location`` header names it.
The run's pictures, the residual before and after against position, time and
direction and the periodogram (``station.discovery.plots``, as ``station discover``
draws them), are kept beside it (``<data>/reports/discovery/<id>/<name>.png``) and
served by ``GET /reports/discovery/{id}/plots/{name}``: only the names the run wrote,
as listed in its report's ``plots``."""

from __future__ import annotations

import json
import logging
import os
import shutil
import tomllib
import uuid
from datetime import datetime, timezone
from pathlib import Path
from typing import Annotated

from fastapi import APIRouter, File, HTTPException, Path as PathParam, Query, Response, UploadFile, status

from api.deps import EngineerDep, ReaderDep, RuntimeDep
from api.routes.common import blocking, read_upload
from api.schemas.reports import DiscoveryList, DiscoveryReport, Iso230Report, StoredDiscoveryReport

log = logging.getLogger(__name__)

router = APIRouter(prefix="/api/v1/reports", tags=["reports"])

#: discovery fits effect models to thousands of rows: bounded, so a request cannot
#: hold a worker thread forever
DISCOVERY_TIMEOUT_S = 120.0


def _iso230(text: str, source: str) -> dict:
    from station.iso230 import analyse
    from station.recording import parse_recording

    return analyse(parse_recording(text, source)).to_json()


def _discovery(model_text: str, model_source: str, rec_text: str, rec_source: str):
    from station.axis_model import axis_model_from_dict
    from station.discovery import discover
    from station.recording import parse_recording

    try:
        data = tomllib.loads(model_text)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{model_source}: not valid TOML: {exc}") from None
    model = axis_model_from_dict(data, model_source)
    return discover(model, parse_recording(rec_text, rec_source))


def _unprocessable(exc: Exception) -> HTTPException:
    return HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, str(exc))


@router.post("/iso230", response_model=Iso230Report,
             responses={413: {"description": "file too large"}, 422: {"description": "bad recording"}})
async def iso230_report(rt: RuntimeDep, who: EngineerDep, recording: UploadFile = File(..., description="laser / "
                        "rotary calibrator recording (CSV)")) -> dict:
    text = await read_upload(recording, rt.settings.max_upload_bytes, "recording")
    try:
        return await blocking(_iso230, text, recording.filename or "recording.csv")
    except (ValueError, ArithmeticError) as exc:
        raise _unprocessable(exc) from None


def discovery_folder(rt) -> Path:
    return rt.settings.data_path / "reports" / "discovery"


def _save_report(folder: Path, entry: dict) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{entry['id']}.json"
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(entry, allow_nan=False, default=str) + "\n", encoding="utf-8")
    os.replace(tmp, path)


#: the pictures a discovery run draws (station.discovery.plots.write_plots), by file
#: name: what each shows. A plot is served only by one of these names, and only when
#: the run's stored report lists it (it wrote it).
PLOT_VIEWS = {
    "residual_position.png": "residual before and after, against position",
    "residual_time.png": "residual before and after, against time",
    "residual_direction.png": "residual before and after, by approach direction",
    "spectrum.png": "periodogram of the residual before",
}
def _write_discovery_plots(d, folder: Path, report_id: str) -> list[str]:
    """The run's pictures in ``<folder>/<id>/``; their names (none when drawing failed:
    the report stands without them, the trouble is logged)."""
    from station.discovery.plots import write_plots

    out = folder / report_id
    try:
        out.mkdir(parents=True, exist_ok=False)
        paths = write_plots(d, out)  # one picture at a time: station.discovery.plots.PLOT_LOCK
    except Exception:  # noqa: BLE001 - the numbers are the report; a picture is extra
        log.exception("discovery report %s: its plots could not be drawn", report_id)
        shutil.rmtree(out, ignore_errors=True)
        return []
    return [p.name for p in paths if p.name in PLOT_VIEWS]


def _plot_links(entry: dict) -> list[dict]:
    return [{"name": name, "view": PLOT_VIEWS[name],
             "url": f"/api/v1/reports/discovery/{entry['id']}/plots/{name}"}
            for name in entry.get("plots", []) if name in PLOT_VIEWS]


def _summary(entry: dict) -> dict:
    r = entry.get("report", {})
    return {"id": entry["id"], "created_at": entry["created_at"], "created_by": entry["created_by"],
            "model_file": entry["model_file"], "recording_file": entry["recording_file"],
            "axis": r.get("axis"), "verdict": r.get("verdict"),
            "rms_before": (r.get("before") or {}).get("rms"), "rms_after": (r.get("after") or {}).get("rms"),
            "effects": [e.get("name") for e in r.get("effects", [])],
            "links": {"self": f"/api/v1/reports/discovery/{entry['id']}"}}


def _list_reports(folder: Path) -> list[dict]:
    entries = []
    for path in folder.glob("*.json"):
        try:
            entries.append(_summary(json.loads(path.read_text(encoding="utf-8"))))
        except (OSError, ValueError, KeyError):  # a half-written or foreign file: not a report
            continue
    entries.sort(key=lambda e: e["created_at"], reverse=True)
    return entries


@router.post("/discovery", response_model=DiscoveryReport, response_model_exclude_unset=True,
             responses={413: {"description": "file too large"}, 422: {"description": "bad input"}})
async def discovery_report(response: Response, rt: RuntimeDep, who: EngineerDep,
                           model: UploadFile = File(..., description="axis model (TOML)"),
                           recording: UploadFile = File(..., description="recording (CSV)")) -> dict:
    limit = rt.settings.max_upload_bytes
    model_text = await read_upload(model, limit, "model")
    rec_text = await read_upload(recording, limit, "recording")
    model_name, rec_name = model.filename or "model.toml", recording.filename or "recording.csv"
    try:
        found = await blocking(_discovery, model_text, model_name, rec_text, rec_name,
                               timeout=DISCOVERY_TIMEOUT_S)
    except (ValueError, ArithmeticError, KeyError, TypeError) as exc:
        raise _unprocessable(exc) from None
    report = found.report
    report_id = str(uuid.uuid4())
    plots = await blocking(_write_discovery_plots, found, discovery_folder(rt), report_id,
                           timeout=DISCOVERY_TIMEOUT_S)
    entry = {"id": report_id, "created_at": datetime.now(timezone.utc).isoformat(),
             "created_by": who.name, "model_file": model_name, "recording_file": rec_name, "report": report,
             "plots": plots}
    await blocking(_save_report, discovery_folder(rt), entry)
    response.headers["Location"] = f"/api/v1/reports/discovery/{entry['id']}"
    return report


@router.get("/discovery", response_model=DiscoveryList, response_model_exclude_unset=True)
async def list_discovery_reports(rt: RuntimeDep, who: ReaderDep,
                                 limit: Annotated[int, Query(ge=1, le=1000)] = 100) -> dict:
    """The stored discovery reports, newest first: a summary each."""
    items = await blocking(_list_reports, discovery_folder(rt))
    return {"total": len(items), "items": items[:limit]}


@router.get("/discovery/{report_id}", response_model=StoredDiscoveryReport, response_model_exclude_unset=True,
            responses={404: {"description": "no such report"}})
async def get_discovery_report(report_id: uuid.UUID, rt: RuntimeDep, who: ReaderDep) -> dict:
    """One stored report: who made it, when, from which files, the report itself, and
    its pictures (``plots``: name, what it shows, url; none for a report stored before
    the API kept them)."""
    entry = await blocking(_read_entry, discovery_folder(rt), report_id)
    return {**entry, "plots": _plot_links(entry)}


def _read_entry(folder: Path, report_id: uuid.UUID) -> dict:
    try:
        return json.loads((folder / f"{report_id}.json").read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"no discovery report {report_id}") from None


def _read_plot(folder: Path, report_id: uuid.UUID, name: str) -> bytes:
    entry = _read_entry(folder, report_id)  # 404: no such report
    if name not in PLOT_VIEWS or name not in entry.get("plots", []):
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"discovery report {report_id} has no plot {name!r} "
                                                       f"(it has: {', '.join(entry.get('plots', [])) or 'none'})")
    path = folder / str(report_id) / name  # both parts checked above: a UUID and a name of PLOT_VIEWS
    try:
        return path.read_bytes()
    except FileNotFoundError:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"discovery report {report_id}: plot {name} is missing "
                                                       f"from the data folder") from None


@router.get("/discovery/{report_id}/plots/{name}", response_class=Response,
            responses={200: {"content": {"image/png": {}}, "description": "the plot (PNG)"},
                       404: {"description": "no such report, or no such plot of it"},
                       422: {"description": "not a report id, or not a plot's name"}})
async def get_discovery_plot(
    report_id: uuid.UUID, rt: RuntimeDep, who: ReaderDep,
    name: str = PathParam(pattern=r"^[a-z_]{1,40}\.png$", description="a plot's name as the report's `plots` lists it"),
) -> Response:
    """One of a stored run's pictures (``image/png``): the residual before and after
    the effects found, against position, time or direction, or the periodogram."""
    data = await blocking(_read_plot, discovery_folder(rt), report_id, name)
    return Response(data, media_type="image/png", headers={"Cache-Control": "private, no-cache"})
