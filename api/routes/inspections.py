"""Job orders in, job responses out (ISA-95's words): start an inspection, read results.

``POST /job-orders`` starts an inspection and answers 202 with the job response as it
is then (state ``running``); with an ``Idempotency-Key`` header a retried POST answers
200 with the same inspection and starts nothing. ``GET /inspections/{id}`` is the job
response: state, verdict and every characteristic with its limits and uncertainty;
``/qif`` the same as a QIF 3.0 results document. Both, and every item of the list,
carry the machine time (``machine_s``, how it divides in ``cycle``); one inspection
also its ``findings`` and its ``surface`` inspection, whose unrolled picture of the
bore wall is ``/surface.png`` (docs/api.md).
"""

from __future__ import annotations

import contextlib
import copy
import hashlib
from datetime import datetime
from typing import Annotated, Literal

from fastapi import APIRouter, Header, HTTPException, Query, Response, status
from pydantic import BaseModel, ConfigDict, Field, StrictBool

from api.deps import JobOrdersDep, ReaderDep, RuntimeDep
from api.routes.common import blocking
from api.routes.parts import load_by_number
from api.runtime import Busy, StationRuntime
from api.schemas.inspections import Inspection, InspectionList, Stations
from station import __version__
from station.exports.qif import finished_qif_bytes
from station.parts import PartSpecError
from station.parts.spec import PART_NUMBER_PATTERN
from station.store import InspectionNotFound, InspectionStateError, StoreError
from station.store.repository import finite_json

router = APIRouter(prefix="/api/v1", tags=["job orders and inspections"])

#: the idempotency key column's length (station.store.models.KEY_LEN)
KEY_MAX = 128


class JobOrder(BaseModel):
    """What the MES asks for: inspect this part."""

    model_config = ConfigDict(extra="forbid")
    part_number: str = Field(pattern=PART_NUMBER_PATTERN, description="a part spec's part number")
    serial: str = Field(min_length=1, max_length=64, pattern=r"\S", description="the part's serial number")
    order_id: str | None = Field(default=None, min_length=1, max_length=64, pattern=r"\S",
                                 description="the production order (ISA-95 job order id)")
    surface: StrictBool | None = Field(
        default=None, description="scan the whole inner surface too (true) or not (false), judged by the part "
                                  "spec's [surface] criteria; absent or null: as the spec's `every_part` says. "
                                  "true for a part spec without [surface] is refused (422)")


def characteristic_json(c) -> dict:
    return {"id": c.characteristic_id, "unit": c.unit, "nominal": c.nominal, "lower_limit": c.lower_limit,
            "upper_limit": c.upper_limit, "measured": c.measured, "uncertainty_k2": c.uncertainty_k2,
            "pass": c.passed}


def finding_json(f) -> dict:
    return {"kind": f.kind, "message": f.message, "subject": f.subject, "axial_mm": f.axial_mm,
            "angle_deg": f.angle_deg, "diameter_mm": f.diameter_mm, "u_mm": f.u_mm}


#: the unrolled picture of an inspection's bore wall (the record's image, subject "surface")
SURFACE_PNG = "surface.png"


def surface_url(inspection_id: str) -> str:
    return f"/api/v1/inspections/{inspection_id}/{SURFACE_PNG}"


def surface_json(rec) -> dict | None:
    """The record's surface document as the API shows it: the picture's meta with its
    URL (null when the record holds no picture), the defects without the twin's truth."""
    if rec.surface is None:
        return None
    doc = finite_json(copy.deepcopy(dict(rec.surface)))
    doc["defects"] = [{k: v for k, v in d.items() if k != "truth"} for d in doc.get("defects") or []]
    picture = doc.get("picture")
    doc["picture"] = ({**picture, "url": surface_url(rec.id)}
                      if picture is not None and rec.surface_image() is not None else None)
    return doc


def job_response(rec) -> dict:
    """An inspection record as the API shows it (the twin's truth stays out: simulation
    bookkeeping, not a measurement)."""
    out = {
        "id": rec.id, "station_id": rec.station_id, "part_number": rec.part_number, "serial": rec.serial,
        "order_id": rec.order_id, "state": rec.state, "result": rec.result, "reason": rec.reason,
        "started_at": rec.started_at.isoformat(), "finished_at": rec.finished_at and rec.finished_at.isoformat(),
        "traceability": dict(rec.traceability),
        # the plan's machine time (s) and how it divides; null while running or when unknown
        "machine_s": finite_json(rec.machine_s),
        "cycle": None if rec.cycle is None else finite_json(dict(rec.cycle)),
        "links": {"self": f"/api/v1/inspections/{rec.id}", "qif": f"/api/v1/inspections/{rec.id}/qif"},
    }
    if hasattr(rec, "characteristics"):
        out["characteristics"] = [characteristic_json(c) for c in rec.characteristics]
        out["images"] = [{"subject": i.subject, "sha256": i.sha256} for i in rec.images]
        out["findings"] = [finding_json(f) for f in rec.findings]
        out["surface"] = surface_json(rec)
    return out


async def _get_record(rt: StationRuntime, inspection_id: str):
    try:
        # read once per committed change; clients polling meanwhile share it (api/records.py)
        return await rt.records.get(inspection_id)
    except InspectionNotFound:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"no inspection {inspection_id!r}") from None


@router.post("/job-orders", status_code=status.HTTP_202_ACCEPTED, response_model=Inspection,
             response_model_exclude_unset=True,
             responses={200: {"model": Inspection,
                              "description": "a retried order (same Idempotency-Key): the existing job"},
                        409: {"description": "the station is busy with another job"},
                        422: {"description": "invalid order or unknown part number"}})
async def create_job_order(
    order: JobOrder, response: Response, rt: RuntimeDep, who: JobOrdersDep,
    idempotency_key: Annotated[str | None, Header(min_length=1, max_length=KEY_MAX)] = None,
) -> dict:
    try:
        spec = await blocking(load_by_number, order.part_number, rt.settings.parts_dir)
    except PartSpecError as exc:
        raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, f"part {order.part_number}: {exc}") from None
    if order.surface and spec.surface is None:
        raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT,
                            f"part {order.part_number} has no [surface] table: its surface has no criteria to judge")
    try:
        iid, created = await rt.start_inspection(spec, order.serial, order.order_id, idempotency_key,
                                                 surface=order.surface)
    except Busy as exc:
        raise HTTPException(status.HTTP_409_CONFLICT, str(exc)) from None
    if created:  # who ordered it (the record names the order, not the caller); the job runs either way
        what = f"ordered inspection {iid} of part {spec.part_number}, serial {order.serial!r}" + (
            f", order {order.order_id!r}" if order.order_id else "")
        with contextlib.suppress(StoreError):
            await blocking(rt.audit, who.who, what)
    rec = await _get_record(rt, iid)
    if not created:
        response.status_code = status.HTTP_200_OK
    response.headers["Location"] = f"/api/v1/inspections/{iid}"
    return job_response(rec)


@router.get("/inspections/{inspection_id}", response_model=Inspection, response_model_exclude_unset=True,
            responses={404: {"description": "no such inspection"}})
async def get_inspection(inspection_id: str, rt: RuntimeDep, who: ReaderDep) -> dict:
    return job_response(await _get_record(rt, inspection_id))


@router.get("/inspections/{inspection_id}/qif", response_class=Response,
            responses={200: {"content": {"application/xml": {}}, "description": "QIF 3.0 results document"},
                       409: {"description": "the inspection is still running"}})
async def get_inspection_qif(inspection_id: str, rt: RuntimeDep, who: ReaderDep) -> Response:
    rec = await _get_record(rt, inspection_id)
    try:
        body = finished_qif_bytes(rec, software_version=__version__)  # station/exports/qif.py
    except InspectionStateError as exc:  # still running: no results yet
        raise HTTPException(status.HTTP_409_CONFLICT, str(exc)) from None
    return Response(body, media_type="application/xml",
                    headers={"Content-Disposition": f'inline; filename="{inspection_id}.qif"'})


def _read_surface_picture(store, rec) -> tuple[bytes, str]:
    image = rec.surface_image()
    if image is None:
        why = ("its part spec asks for no surface inspection, or it did not complete" if rec.surface is None
               else "its surface inspection made no picture")
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"inspection {rec.id} has no surface picture ({why})")
    try:
        data = store.image_path(image).read_bytes()
    except FileNotFoundError:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"inspection {rec.id}: its surface picture is missing "
                                                       f"from the data folder ({image.path})") from None
    if hashlib.sha256(data).hexdigest() != image.sha256:  # evidence: served only as the station stored it
        raise HTTPException(status.HTTP_500_INTERNAL_SERVER_ERROR,
                            f"inspection {rec.id}: the surface picture on disk ({image.path}) does not match the "
                            "SHA-256 recorded with it; it was changed after the inspection")
    return data, image.sha256


@router.get("/inspections/{inspection_id}/surface.png", response_class=Response,
            responses={200: {"content": {"image/png": {}},
                             "description": "the unrolled picture of the bore wall (PNG, grey)"},
                       304: {"description": "not modified (the picture's ETag, its SHA-256, in If-None-Match)"},
                       404: {"description": "no such inspection, or it has no surface picture"}})
async def get_surface_picture(
    inspection_id: str, rt: RuntimeDep, who: ReaderDep,
    if_none_match: Annotated[str | None, Header(max_length=256)] = None,
) -> Response:
    """The unrolled picture of the bore wall that the inspection's surface scan stitched
    (``image/png``): rows are axial position, columns the wall round the bore; where
    its pixels are on the part is the job response's ``surface.picture``. A stored
    picture never changes: its ETag is its SHA-256, as recorded with it."""
    rec = await _get_record(rt, inspection_id)
    data, digest = await blocking(_read_surface_picture, rt.store, rec)
    headers = {"Cache-Control": "private, no-cache", "ETag": f'"{digest}"'}
    if if_none_match is not None and f'"{digest}"' in [t.strip().removeprefix("W/") for t in if_none_match.split(",")]:
        return Response(status_code=status.HTTP_304_NOT_MODIFIED, headers=headers)
    return Response(data, media_type="image/png", headers=headers)


@router.get("/inspections", response_model=InspectionList, response_model_exclude_unset=True)
async def list_inspections(
    rt: RuntimeDep,
    who: ReaderDep,
    since: Annotated[datetime | None, Query(description="started at or after (ISO 8601 with offset)")] = None,
    until: Annotated[datetime | None, Query(description="started before (ISO 8601 with offset)")] = None,
    part_number: Annotated[str | None, Query(max_length=64)] = None,
    serial: Annotated[str | None, Query(max_length=64)] = None,
    result: Literal["pass", "fail"] | None = None,
    state: Literal["running", "complete", "aborted", "faulted", "interrupted"] | None = None,
    station: Annotated[str | None, Query(max_length=64, pattern=r"^[A-Za-z0-9][A-Za-z0-9._-]*$",
                                         description="only this station's inspections (its station id); "
                                                     "default: every station writing this database")] = None,
    limit: Annotated[int, Query(ge=1, le=1000)] = 50,
    offset: Annotated[int, Query(ge=0, le=10**9)] = 0,
) -> dict:
    for name, t in (("since", since), ("until", until)):
        if t is not None and t.utcoffset() is None:
            raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT,
                                f"{name} needs a time zone (e.g. 2024-05-01T08:00:00Z)")
    store = rt.store
    filters = dict(since=since, until=until, part_number=part_number, serial=serial, result=result, state=state,
                   station=station)
    total = await blocking(store.count_inspections, **filters)
    items = await blocking(store.list_inspections, **filters, limit=limit, offset=offset)
    return {"total": total, "limit": limit, "offset": offset, "items": [job_response(r) for r in items]}


@router.get("/stations", response_model=Stations)
async def list_stations(rt: RuntimeDep, who: ReaderDep) -> dict:
    """The stations whose inspections this database holds, and this one's id."""
    store = rt.store
    return {"this": store.station_id, "stations": await blocking(store.stations)}
