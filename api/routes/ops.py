"""Probes and metrics: /healthz (the process answers), /readyz (store and station
reachable), /metrics (Prometheus text format)."""

from __future__ import annotations

from fastapi import APIRouter, Response
from fastapi.responses import JSONResponse
from prometheus_client import CONTENT_TYPE_LATEST, generate_latest

from api.deps import ReaderDep, RuntimeDep
from api.routes.common import blocking
from api.schemas.ops import Health, Readiness

router = APIRouter(tags=["operations"])


@router.get("/healthz", response_model=Health)
async def healthz() -> dict:
    return {"status": "ok"}


@router.get("/readyz", response_model=Readiness,
            responses={503: {"model": Readiness, "description": "the store or the station is not reachable"}})
async def readyz(rt: RuntimeDep) -> JSONResponse:
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
    # a response of its own (its status says ready or not): FastAPI passes it on as it is
    return JSONResponse({"ready": ready, "checks": checks}, status_code=200 if ready else 503)


@router.get("/metrics", response_class=Response,
            responses={200: {"content": {"text/plain": {}}, "description": "Prometheus text exposition format"}})
async def metrics(rt: RuntimeDep, who: ReaderDep) -> Response:
    # this station's pass rate, not the plant's: several stations may share the database
    mine = rt.store.station_id
    passed = await blocking(rt.store.count_inspections, state="complete", result="pass", station=mine)
    complete = await blocking(rt.store.count_inspections, state="complete", station=mine)
    rt.metrics.pass_rate.set(passed / complete if complete else 0.0)
    rt.update_monitor_metrics()  # as it is now, whatever changed it
    return Response(generate_latest(rt.metrics.registry), media_type=CONTENT_TYPE_LATEST)
