"""The station: its state, its axes, its alarms, and the operator's commands."""

from __future__ import annotations

import asyncio
from typing import Annotated, Literal

from fastapi import APIRouter, HTTPException, Query, status

from api.deps import OperatorDep, ReaderDep, RuntimeDep
from api.routes.common import blocking
from api.runtime import Busy
from api.schemas.station import AlarmList, Axes, StationStatus
from station.sequencer.engine import EngineStateError

router = APIRouter(prefix="/api/v1", tags=["station"])

#: event kinds that are alarms: the engine's faults and the API's own alarms
ALARM_KINDS = ("fault", "alarm")


@router.get("/station", response_model=StationStatus)
async def get_station(rt: RuntimeDep, who: ReaderDep) -> dict:
    return rt.station_status()


async def _read(rt, coro, timeout: float) -> tuple[object, str | None]:
    """A device read, run on the station loop, with a deadline kept here."""
    try:
        return await rt.on_station(coro, timeout=timeout), None
    except Exception as exc:  # noqa: BLE001 - a device that does not answer is reported, not a 500
        return None, f"{type(exc).__name__}: {exc}"


@router.get("/axes", response_model=Axes, response_model_exclude_unset=True)
async def get_axes(rt: RuntimeDep, who: ReaderDep) -> dict:
    """Z and C as their drives report them (``setpoint``: the last target commanded,
    null after a stop), and the grating's reading of Z. A device that does not answer
    in time shows ``error`` instead of failing the request."""
    st = rt.station
    timeout = rt.settings.command_timeout_s / 2
    out: dict = {}
    for name, ax, unit in (("Z", st.z, "mm"), ("C", st.c, "deg")):
        s, err = await _read(rt, ax.status(), timeout)
        # the drive's last commanded target (None after a stop): the driver keeps it
        setpoint = ax.setpoint
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


@router.get("/alarms", response_model=AlarmList)
async def get_alarms(rt: RuntimeDep, who: ReaderDep, limit: Annotated[int, Query(ge=1, le=1000)] = 100) -> dict:
    """This station's faults and alarms from the event log, newest first (other stations
    writing the same database have their own)."""
    store = rt.store
    items = []
    for kind in ALARM_KINDS:
        items += await blocking(store.events, kind=kind, limit=limit, newest_first=True, station=store.station_id,
                                with_unassigned=True)
    items.sort(key=lambda e: e.id, reverse=True)
    return {"items": [e.to_json() for e in items[:limit]]}


@router.post("/station/{command}", response_model=StationStatus,
             responses={409: {"description": "the station's state does not allow it"},
                        504: {"description": "the drives did not answer in time"}})
async def station_command(command: Literal["pause", "resume", "stop", "abort", "reset", "home"], rt: RuntimeDep,
                          who: OperatorDep) -> dict:
    """Pause, resume, stop (controlled), abort, reset or home; answers the station's status after it."""
    try:
        return await rt.command(command, who.who)
    except (EngineStateError, Busy) as exc:
        raise HTTPException(status.HTTP_409_CONFLICT, str(exc)) from None
    except asyncio.TimeoutError:
        raise HTTPException(status.HTTP_504_GATEWAY_TIMEOUT, f"{command}: the drives did not answer in time") from None
