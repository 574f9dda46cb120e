"""The station watches itself (docs/monitor.md), over REST: checks on the certified
master, and the model proposals an engineer approves or rejects.

``POST /checks`` starts a check on the master as the station's job (one job at a time,
like a job order: 409 while another runs) and answers 202 at once with the check,
whose id is the master inspection's. ``GET /checks/{id}`` is the check: running, then
the session's ``MasterCheckOutcome`` (each characteristic against the certificate, the
alarms, ``in_control``); a check out of control makes a model proposal, as the
campaign does. The checks are kept by the server process (the last 100); the master's
inspection stays in the store at ``/inspections/{id}``.

``/model-proposals`` lists the station's proposals (any role), each with its
before/after picture (``/model-proposals/{id}/plot``, PNG), and takes an engineer's
decision (``approve`` / ``reject``, engineer or admin), made on the station loop and
not while a job runs (409): approved, the station uses the changed model from its next
inspection. Each decision is an event of the store's log (``approval`` /
``rejection``, by the token's name) and an ``audit`` entry.
"""

from __future__ import annotations

import contextlib
from typing import Annotated, Literal

from fastapi import APIRouter, Body, Depends, HTTPException, Response, status
from pydantic import BaseModel, ConfigDict, Field

from api import auth
from api.deps import EngineerDep, ReaderDep, RuntimeDep
from api.routes.common import blocking
from station.store.repository import finite_json
from api.routes.parts import load_by_number
from api.runtime import Busy, StationRuntime
from api.schemas.monitor import Check, DecidedProposal, Proposal, ProposalList
from station.parts import PartSpecError
from station.parts.spec import PART_NUMBER_PATTERN
from station.store import StoreError

router = APIRouter(prefix="/api/v1", tags=["station checks and model proposals"])

#: the master a check uses when the request names none
DEFAULT_MASTER = "MC-22.2-A"
#: who may start a check: whoever works at the machine (the MES orders parts, not checks)
checks_role = auth.require("operator", "engineer")
CheckStarterDep = Annotated[auth.Principal, Depends(checks_role)]


class CheckOrder(BaseModel):
    """Check the station on its certified master."""

    model_config = ConfigDict(extra="forbid")
    kind: Literal["master"] = Field(description="what to check the station on: `master` (its certified master part)")
    master: str = Field(default=DEFAULT_MASTER, pattern=PART_NUMBER_PATTERN,
                        description="a built-in master's id (`station/data/masters/<id>.toml`)")


class Decision(BaseModel):
    """An engineer's note on a decision (optional)."""

    model_config = ConfigDict(extra="forbid")
    note: str = Field(default="", max_length=500, description="why (kept with the proposal and in the event log)")


def _load_master(master_id: str):
    """The certificate, its part family's spec (the station's, as a job order finds it)
    and the spec the master is inspected with; ValueError naming the field."""
    from station.checks.master import builtin_masters, load_master

    known = builtin_masters()
    if master_id not in known:  # never a file named by a request
        raise ValueError(f"master: no built-in master {master_id!r} (built in: {', '.join(known) or 'none'})")
    try:
        cert = load_master(master_id)
    except PartSpecError as exc:
        raise ValueError(f"master: {master_id}: {exc}") from None
    return cert


def _family_of(cert, parts_dir):
    try:
        family = load_by_number(cert.part_number, parts_dir)
    except PartSpecError as exc:
        raise ValueError(f"master: {cert.master_id}: its part family {cert.part_number}: {exc}") from None
    try:
        cert.as_part_spec(family)  # its holes must be the family's: refused now, not mid-check
    except ValueError as exc:
        raise ValueError(f"master: {exc}") from None
    return family


@router.post("/checks", status_code=status.HTTP_202_ACCEPTED, response_model=Check,
             response_model_exclude_unset=True,
             responses={409: {"description": "the station is busy with another job"},
                        422: {"description": "unknown kind or master"}})
async def start_check(order: CheckOrder, response: Response, rt: RuntimeDep, who: CheckStarterDep) -> dict:
    """Start a check on the certified master (the operator has put it on the table; in
    simulation the twin's world holds it for the check). 202 with the check (state
    ``running``) and ``Location``; poll ``GET /checks/{id}``."""
    try:
        cert = await blocking(_load_master, order.master)
        family = await blocking(_family_of, cert, rt.settings.parts_dir)
    except ValueError as exc:
        raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, str(exc)) from None
    try:
        rec = await rt.start_check(cert, family)
    except Busy as exc:
        raise HTTPException(status.HTTP_409_CONFLICT, str(exc)) from None
    with contextlib.suppress(StoreError):
        await blocking(rt.audit, who.who, f"started check {rec.id} on master {cert.master_id}")
    response.headers["Location"] = f"/api/v1/checks/{rec.id}"
    return finite_json(rec.to_json())


@router.get("/checks/{check_id}", response_model=Check, response_model_exclude_unset=True,
            responses={404: {"description": "no check of that id in this server process"}})
async def get_check(check_id: str, rt: RuntimeDep, who: ReaderDep) -> dict:
    rec = rt.checks.get(check_id)
    if rec is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"no check {check_id!r} (this server keeps the last "
                                                       f"checks it ran; the inspection is at /inspections/{{id}})")
    # the master inspection's cycle may hold a number JSON cannot carry (a ratio to a zero bound): null
    return finite_json(rec.to_json())


# ---------------------------------------------------------------------- model proposals
def _proposal(rt, proposal_id: str):
    from station.monitor.proposals import ProposalError

    try:
        return rt.session.proposals.get(proposal_id)
    except ProposalError as exc:
        raise HTTPException(status.HTTP_404_NOT_FOUND, str(exc)) from None


def _proposal_json(rt, p) -> dict:
    """A proposal as the API shows it: its JSON and ``plot_url``, where its before/after
    picture is (null when it has none: an old proposal, or one without checks to show)."""
    has_plot = rt.session.proposals.plot_path(p.id).is_file()
    return {**p.to_json(), "plot_url": f"/api/v1/model-proposals/{p.id}/plot" if has_plot else None}


def _proposal_plot(rt, proposal_id: str) -> bytes:
    p = _proposal(rt, proposal_id)  # 404 when there is no such proposal
    try:
        return rt.session.proposals.plot_path(p.id).read_bytes()
    except FileNotFoundError:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"proposal {p.id} has no picture (it was made without "
                                                       f"master checks over time to show)") from None


@router.get("/model-proposals", response_model=ProposalList)
async def list_proposals(rt: RuntimeDep, who: ReaderDep) -> dict:
    """The station's model proposals, oldest first (newest last), and the version of
    the model it uses now."""
    items = await blocking(lambda: [_proposal_json(rt, p) for p in rt.session.proposals.list()])
    version = await blocking(lambda: rt.session.model_version)
    return {"model_version": version, "items": items}


@router.get("/model-proposals/{proposal_id}", response_model=Proposal,
            responses={404: {"description": "no such proposal"}})
async def get_proposal(proposal_id: str, rt: RuntimeDep, who: ReaderDep) -> dict:
    return await blocking(lambda: _proposal_json(rt, _proposal(rt, proposal_id)))


@router.get("/model-proposals/{proposal_id}/plot", response_class=Response,
            responses={200: {"content": {"image/png": {}},
                             "description": "the proposal's picture: the master checks' position errors before "
                                            "and after the change (PNG)"},
                       404: {"description": "no such proposal, or it has no picture"}})
async def get_proposal_plot(proposal_id: str, rt: RuntimeDep, who: ReaderDep) -> Response:
    """The proposal's before/after picture (``image/png``): each master check's
    position error per hole against the machine clock, as measured and as the proposed
    model would have read it. 404 (JSON) when the proposal does not exist or has none."""
    data = await blocking(_proposal_plot, rt, proposal_id)
    return Response(data, media_type="image/png", headers={"Cache-Control": "private, no-cache"})


async def _decide(rt: StationRuntime, proposal_id: str, approve: bool, body: Decision | None,
                  who: auth.Principal) -> dict:
    from station.monitor.proposals import ProposalError

    await blocking(_proposal, rt, proposal_id)  # 404 before anything else
    note = body.note.strip() if body is not None else ""
    try:
        p, version = await rt.decide_proposal(proposal_id, approve, who.name, note)
    except Busy as exc:
        raise HTTPException(status.HTTP_409_CONFLICT, str(exc)) from None
    except ProposalError as exc:  # decided already
        raise HTTPException(status.HTTP_409_CONFLICT, str(exc)) from None
    with contextlib.suppress(StoreError):
        await blocking(rt.audit, who.who, f"{'approved' if approve else 'rejected'} model proposal {p.id}"
                                          + (f"; the station's model is now {version}" if approve else ""))
    return {**(await blocking(_proposal_json, rt, p)), "model_version": version}


DECISION_RESPONSES = {404: {"description": "no such proposal"},
                      409: {"description": "decided already, or a job is running"}}


@router.post("/model-proposals/{proposal_id}/approve", response_model=DecidedProposal, responses=DECISION_RESPONSES)
async def approve_proposal(proposal_id: str, rt: RuntimeDep, who: EngineerDep,
                           body: Decision | None = Body(default=None)) -> dict:
    """Approve: the station uses the changed model from its next inspection (its charts
    start again); kept under ``<data>/models`` and applied at every start."""
    return await _decide(rt, proposal_id, True, body, who)


@router.post("/model-proposals/{proposal_id}/reject", response_model=DecidedProposal, responses=DECISION_RESPONSES)
async def reject_proposal(proposal_id: str, rt: RuntimeDep, who: EngineerDep,
                          body: Decision | None = Body(default=None)) -> dict:
    """Reject: the station's model stays as it is."""
    return await _decide(rt, proposal_id, False, body, who)
