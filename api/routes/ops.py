"""Probes and metrics: /healthz (the process answers), /readyz (store and station
reachable), /metrics (Prometheus text format)."""

from __future__ import annotations


from fastapi import APIRouter, Request, Response
from fastapi.responses import JSONResponse
from prometheus_client import CONTENT_TYPE_LATEST, generate_latest

from api import auth
from api.routes.common import blocking, runtime

from fastapi import Depends

router = APIRouter(tags=["operations"])


@router.get("/healthz")
async def healthz() -> dict:
    return {"status": "ok"}


@router.get("/readyz", responses={503: {"description": "the store or the station is not reachable"}})
async def readyz(request: Request) -> JSONResponse:
    rt = runtime(request)
    checks: dict[str, str] = {}
    try:
        await blocking(rt.store.count_inspections, timeout=5.0)
        checks["store"] = "ok"
    except Exception as exc:  # noqa: BLE001 - a probe reports, it does not fail
        checks["store"] = f"{type(exc).__name__}: {exc}"
    try:
        # the drives answer on the station's own loop (api/station_thread.py)
        await rt.on_station(rt.station.z.status(), timeout=5.0)
        await rt.on_station(rt.station.c.status(), timeout=5.0)
        checks["station"] = "ok"
    except Exception as exc:  # noqa: BLE001
        checks["station"] = f"{type(exc).__name__}: {exc}"
    ready = all(v == "ok" for v in checks.values())
    return JSONResponse({"ready": ready, "checks": checks}, status_code=200 if ready else 503)


@router.get("/metrics", response_class=Response, responses={200: {"content": {"text/plain": {}}}})
async def metrics(request: Request, who: auth.Principal = Depends(auth.reader)) -> Response:
    rt = runtime(request)
    # this station's pass rate, not the plant's: several stations may share the database
    mine = rt.store.station_id
    passed = await blocking(rt.store.count_inspections, state="complete", result="pass", station=mine)
    complete = await blocking(rt.store.count_inspections, state="complete", station=mine)
    rt.metrics.pass_rate.set(passed / complete if complete else 0.0)
    rt.update_monitor_metrics()  # as it is now, whatever changed it
    return Response(generate_latest(rt.metrics.registry), media_type=CONTENT_TYPE_LATEST)
