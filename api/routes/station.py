"""The station: its state, its axes, its alarms, and the operator's commands."""

from __future__ import annotations

import asyncio
from typing import Annotated, Literal

from fastapi import APIRouter, Depends, HTTPException, Query, Request, status

from api import auth
from api.routes.common import blocking, runtime
from api.runtime import Busy
from station.sequencer.engine import EngineStateError

router = APIRouter(prefix="/api/v1", tags=["station"])

#: event kinds that are alarms: the engine's faults and the API's own alarms
ALARM_KINDS = ("fault", "alarm")


@router.get("/station")
async def get_station(request: Request, who: auth.Principal = Depends(auth.reader)) -> dict:
    return runtime(request).station_status()


async def _read(rt, coro, timeout: float) -> tuple[object, str | None]:
    """A device read, run on the station loop, with a deadline kept here."""
    try:
        return await rt.on_station(coro, timeout=timeout), None
    except Exception as exc:  # noqa: BLE001 - a device that does not answer is reported, not a 500
        return None, f"{type(exc).__name__}: {exc}"


@router.get("/axes")
async def get_axes(request: Request, who: auth.Principal = Depends(auth.reader)) -> dict:
    """Z and C as their drives report them (``setpoint``: the last target commanded,
    null after a stop), and the grating's reading of Z. A device that does not answer
    in time shows ``error`` instead of failing the request."""
    rt = runtime(request)
    st = rt.station
    timeout = rt.settings.command_timeout_s / 2
    out: dict = {}
    for name, ax, unit in (("Z", st.z, "mm"), ("C", st.c, "deg")):
        s, err = await _read(rt, ax.status(), timeout)
        # the drive's last commanded target (None after a stop): the driver keeps it
        setpoint = getattr(ax, "_last_target", None)
        out[name] = {"unit": unit, "error": err, "setpoint": setpoint} if s is None else {
            "unit": unit, "setpoint": setpoint, "position": s.position, "velocity": s.velocity, "state": s.state.value,
            "enabled": s.enabled, "homed": s.homed, "moving": s.moving, "in_position": s.in_position,
            "fault": s.fault, "fault_code": s.fault_code, "estop": s.estop, "error": None}
    if st.encoder is not None:
        r, err = await _read(rt, st.encoder.read(), timeout)
        out["grating"] = {"unit": "mm", "error": err} if r is None else {
            "unit": "mm", "position": r.position_mm, "referenced": r.status.referenced, "ok": r.status.ok,
            "error": None}
    else:
        out["grating"] = None
    return out


@router.get("/alarms")
async def get_alarms(request: Request, limit: Annotated[int, Query(ge=1, le=1000)] = 100,
                     who: auth.Principal = Depends(auth.reader)) -> dict:
    """This station's faults and alarms from the event log, newest first (other stations
    writing the same database have their own)."""
    store = runtime(request).store
    items = []
    for kind in ALARM_KINDS:
        items += await blocking(store.events, kind=kind, limit=limit, newest_first=True, station=store.station_id,
                                with_unassigned=True)
    items.sort(key=lambda e: e.id, reverse=True)
    return {"items": [e.to_json() for e in items[:limit]]}


@router.post("/station/{command}", responses={409: {"description": "the station's state does not allow it"}})
async def station_command(command: Literal["pause", "resume", "stop", "abort", "reset", "home"], request: Request,
                          who: auth.Principal = Depends(auth.operator)) -> dict:
    try:
        return await runtime(request).command(command, who.who)
    except (EngineStateError, Busy) as exc:
        raise HTTPException(status.HTTP_409_CONFLICT, str(exc)) from None
    except asyncio.TimeoutError:
        raise HTTPException(status.HTTP_504_GATEWAY_TIMEOUT, f"{command}: the drives did not answer in time") from None
