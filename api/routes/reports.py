"""Reports computed from uploads: ISO 230-2 figures of a recording, and mismatch
discovery (model + recording). Nothing is stored; the JSON is the contract of the
matching CLI commands (``station iso230 --json``, ``station discover``)."""

from __future__ import annotations

import tomllib

from fastapi import APIRouter, Depends, File, HTTPException, Request, UploadFile, status

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


@router.post("/discovery", responses={413: {"description": "file too large"}, 422: {"description": "bad input"}})
async def discovery_report(request: Request,
                           model: UploadFile = File(..., description="axis model (TOML)"),
                           recording: UploadFile = File(..., description="recording (CSV)"),
                           who: auth.Principal = Depends(auth.engineer)) -> dict:
    rt = runtime(request)
    limit = rt.settings.max_upload_bytes
    model_text = await read_upload(model, limit, "model")
    rec_text = await read_upload(recording, limit, "recording")
    try:
        return await blocking(_discovery, model_text, model.filename or "model.toml", rec_text,
                              recording.filename or "recording.csv", timeout=DISCOVERY_TIMEOUT_S)
    except (ValueError, ArithmeticError, KeyError, TypeError) as exc:
        raise _unprocessable(exc) from None
