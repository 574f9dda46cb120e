"""Self-calibration on a certified artefact over REST (issue 21, docs/calibration.md).

``POST /calibrations/master`` (engineers) starts ``station.calibration.run.calibrate``
as the station's job, like a check on the master (one job at a time: 409 while another
runs), and answers 202 at once with the run (state ``running``) and ``Location``;
``GET /calibrations/master/{id}`` is the run: ``running``, then ``complete`` with
``result``, the object ``station calibrate master --json`` prints (the world's truth
left out, as a check's is), or ``faulted`` with the reason. With ``propose`` the
observable parameters become a model proposal (``/model-proposals/{id}``, approved by an
engineer) and ``result.model_version`` is its id. Runs are kept by the server process
(the last 20).
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import logging
import uuid
from collections import OrderedDict
from datetime import datetime, timezone

from fastapi import APIRouter, HTTPException, Response, status
from pydantic import BaseModel, ConfigDict, Field

from api.deps import EngineerDep, ReaderDep, RuntimeDep
from api.routes.common import blocking
from station.store.repository import finite_json
from api.runtime import Busy
from api.schemas.calibration import CalibrationRun
from station.store import StoreError

log = logging.getLogger(__name__)

router = APIRouter(prefix="/api/v1", tags=["self-calibration"])

#: the runs this server process keeps
RUNS_KEPT = 20
#: an artefact id: a built-in certificate's name (never a path from a request)
ARTEFACT_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$"


class CalibrationOrder(BaseModel):
    """Calibrate the station's error model on a certified artefact."""

    model_config = ConfigDict(extra="forbid")
    artefact: str = Field(default="CA-22.2-5x8", pattern=ARTEFACT_PATTERN,
                          description="a built-in artefact's id (`station/data/masters/artefacts/<id>.toml`)")
    poses: int = Field(default=40, ge=1, le=200, description="poses to measure (chosen for observability)")
    propose: bool = Field(default=False, description="make a model proposal of the observable parameters")
    min_significance: float = Field(default=2.0, ge=0.0, le=10.0,
                                    description="propose an observable parameter only when the calibration differs "
                                                "from the present model by more than this many u (0: every one)")
    seed: int = Field(default=0, ge=0, description="simulation only: the artefact's making in the twin's world")


def _now() -> str:
    return datetime.now(timezone.utc).isoformat()


@dataclasses.dataclass
class _Run:
    id: str
    order: CalibrationOrder
    state: str = "running"
    reason: str | None = None
    started_at: str = dataclasses.field(default_factory=_now)
    finished_at: str | None = None
    result: dict | None = None
    proposal_id: str | None = None

    def to_json(self) -> dict:
        links = {"self": f"/api/v1/calibrations/master/{self.id}"}
        if self.proposal_id:
            links["proposal"] = f"/api/v1/model-proposals/{self.proposal_id}"
        return {"id": self.id, "kind": "master", "artefact": self.order.artefact, "poses": self.order.poses,
                "propose": self.order.propose, "state": self.state, "reason": self.reason,
                "started_at": self.started_at, "finished_at": self.finished_at, "result": self.result,
                "links": links}


def _runs(rt) -> OrderedDict:
    runs = getattr(rt, "calibration_runs", None)
    if runs is None:
        runs = rt.calibration_runs = OrderedDict()
    return runs


def _load_artefact(artefact_id: str):
    from station.calibration.artefact import load_artefact

    return load_artefact(artefact_id)  # an id matching ARTEFACT_PATTERN: a built-in certificate


async def _calibrate(rt, run: _Run, cert):
    """On the station loop: plan, measure, identify; the proposal when asked."""
    from station.calibration.proposal import propose_from_calibration
    from station.calibration.run import calibrate
    from station.monitor.proposals import ProposalError

    session = rt.session
    outcome = await calibrate(session, cert, n_poses=run.order.poses, seed=run.order.seed)
    proposal = None
    if run.order.propose:
        try:
            proposal = await propose_from_calibration(session, outcome, cert.artefact_id,
                                                      min_significance=run.order.min_significance)
        except ProposalError as exc:
            await asyncio.to_thread(session.store.log_event, "alarm", f"no model proposal: {exc}")
    # the twin's truth is an annotation for tests and benches, not a result served to clients
    doc = dataclasses.replace(outcome, truth=None).to_json(model_version=None if proposal is None else proposal.id)
    return doc, proposal


def _ended(rt, run: _Run, fut) -> None:
    """On the API loop: the run's record and the events."""
    run.finished_at = _now()
    try:
        doc, proposal = fut.result()
    except BaseException as exc:  # noqa: BLE001 - a job must end recorded, whatever broke
        run.state, run.reason = "faulted", f"{type(exc).__name__}: {exc}"
        log.warning("calibration %s failed: %s", run.id, run.reason)
        with contextlib.suppress(StoreError):
            rt.store.log_event("alarm", f"calibration {run.id} failed: {run.reason}")
    else:
        run.state, run.result = "complete", finite_json(doc)
        if proposal is not None:
            run.proposal_id = proposal.id
            rt.hub.publish("proposal", event="proposed", id=proposal.id, state=proposal.state,
                           reason=proposal.reason, terms=[c.term for c in proposal.changes])
    rt.hub.publish("job", event="finished", job="calibration", id=run.id, state=run.state, reason=run.reason)


@router.post("/calibrations/master", status_code=status.HTTP_202_ACCEPTED, response_model=CalibrationRun,
             response_model_exclude_unset=True,
             responses={409: {"description": "the station is busy with another job"},
                        422: {"description": "unknown artefact, or a bad order"}})
async def start_calibration(order: CalibrationOrder, response: Response, rt: RuntimeDep, who: EngineerDep) -> dict:
    """Start a self-calibration on the artefact (the engineer has put it on the table; in
    simulation the twin's world holds it for the run). 202 with the run (``running``)
    and ``Location``; poll ``GET /calibrations/master/{id}``."""
    try:
        cert = await blocking(_load_artefact, order.artefact)
    except ValueError as exc:
        raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, f"artefact: {exc}") from None
    if rt.busy:
        raise HTTPException(status.HTTP_409_CONFLICT, rt.busy_text())
    run = _Run(uuid.uuid4().hex[:12], order)
    runs = _runs(rt)
    runs[run.id] = run
    while len(runs) > RUNS_KEPT:
        runs.popitem(last=False)
    try:
        rt.start_job("calibration", _calibrate(rt, run, cert), lambda fut: _ended(rt, run, fut))
    except Busy as exc:  # pragma: no cover - the check above holds on the one API loop
        raise HTTPException(status.HTTP_409_CONFLICT, str(exc)) from None
    rt.hub.publish("job", event="started", job="calibration", id=run.id, artefact=cert.artefact_id)
    with contextlib.suppress(StoreError):
        await blocking(rt.audit, who.who, f"started calibration {run.id} on artefact {cert.artefact_id} "
                                          f"({order.poses} poses{', propose' if order.propose else ''})")
    response.headers["Location"] = f"/api/v1/calibrations/master/{run.id}"
    return run.to_json()


@router.get("/calibrations/master/{run_id}", response_model=CalibrationRun, response_model_exclude_unset=True,
            responses={404: {"description": "no calibration of that id in this server process"}})
async def get_calibration(run_id: str, rt: RuntimeDep, who: ReaderDep) -> dict:
    run = _runs(rt).get(run_id)
    if run is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"no calibration {run_id!r} (this server keeps the last "
                                                       f"{RUNS_KEPT} it ran)")
    return run.to_json()

