"""Reports computed from uploads: ISO 230-2 figures of a recording, and mismatch
discovery (model + recording). The JSON is the contract of the matching CLI commands
(``station iso230 --json``, ``station discover``).

Every discovery report is also kept in the data folder
(``<data>/reports/discovery/<id>.json``: who, when, the files' names and the report),
so the panel can list them: ``GET /reports/discovery`` (newest first, a summary each)
and ``GET /reports/discovery/{id}``; the POST's ``Location`` header names it."""

from __future__ import annotations

import json
import os
import tomllib
import uuid
from datetime import datetime, timezone
from pathlib import Path
from typing import Annotated

from fastapi import APIRouter, Depends, File, HTTPException, Query, Request, Response, UploadFile, status

from api import auth
from api.routes.common import blocking, read_upload, runtime

router = APIRouter(prefix="/api/v1/reports", tags=["reports"])

#: discovery fits effect models to thousands of rows: bounded, so a request cannot
#: hold a worker thread forever
DISCOVERY_TIMEOUT_S = 120.0


def _iso230(text: str, source: str) -> dict:
    from station.iso230 import analyse
    from station.recording import parse_recording

    return analyse(parse_recording(text, source)).to_json()


def _discovery(model_text: str, model_source: str, rec_text: str, rec_source: str) -> dict:
    from station.axis_model import axis_model_from_dict
    from station.discovery import discover
    from station.recording import parse_recording

    try:
        data = tomllib.loads(model_text)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{model_source}: not valid TOML: {exc}") from None
    model = axis_model_from_dict(data, model_source)
    return discover(model, parse_recording(rec_text, rec_source)).report


def _unprocessable(exc: Exception) -> HTTPException:
    return HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, str(exc))


@router.post("/iso230", responses={413: {"description": "file too large"}, 422: {"description": "bad recording"}})
async def iso230_report(request: Request, recording: UploadFile = File(..., description="laser / rotary "
                        "calibrator recording (CSV)"), who: auth.Principal = Depends(auth.engineer)) -> dict:
    rt = runtime(request)
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


@router.post("/discovery", responses={413: {"description": "file too large"}, 422: {"description": "bad input"}})
async def discovery_report(request: Request, response: Response,
                           model: UploadFile = File(..., description="axis model (TOML)"),
                           recording: UploadFile = File(..., description="recording (CSV)"),
                           who: auth.Principal = Depends(auth.engineer)) -> dict:
    rt = runtime(request)
    limit = rt.settings.max_upload_bytes
    model_text = await read_upload(model, limit, "model")
    rec_text = await read_upload(recording, limit, "recording")
    model_name, rec_name = model.filename or "model.toml", recording.filename or "recording.csv"
    try:
        report = await blocking(_discovery, model_text, model_name, rec_text, rec_name,
                                timeout=DISCOVERY_TIMEOUT_S)
    except (ValueError, ArithmeticError, KeyError, TypeError) as exc:
        raise _unprocessable(exc) from None
    entry = {"id": str(uuid.uuid4()), "created_at": datetime.now(timezone.utc).isoformat(),
             "created_by": who.name, "model_file": model_name, "recording_file": rec_name, "report": report}
    await blocking(_save_report, discovery_folder(rt), entry)
    response.headers["Location"] = f"/api/v1/reports/discovery/{entry['id']}"
    return report


@router.get("/discovery")
async def list_discovery_reports(request: Request, limit: Annotated[int, Query(ge=1, le=1000)] = 100,
                                 who: auth.Principal = Depends(auth.reader)) -> dict:
    """The stored discovery reports, newest first: a summary each."""
    items = await blocking(_list_reports, discovery_folder(runtime(request)))
    return {"total": len(items), "items": items[:limit]}


@router.get("/discovery/{report_id}", responses={404: {"description": "no such report"}})
async def get_discovery_report(report_id: uuid.UUID, request: Request,
                               who: auth.Principal = Depends(auth.reader)) -> dict:
    """One stored report: who made it, when, from which files, and the report itself."""
    path = discovery_folder(runtime(request)) / f"{report_id}.json"
    try:
        text = await blocking(path.read_text, encoding="utf-8")
    except FileNotFoundError:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"no discovery report {report_id}") from None
    return json.loads(text)
