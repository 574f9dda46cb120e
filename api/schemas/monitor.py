"""Checks on the certified master and the model proposals (docs/monitor.md)."""

from __future__ import annotations

from typing import Any

from pydantic import Field

from api.schemas.common import ClosedModel, IsoTime, Links, Number, OpenModel
from api.schemas.inspections import Cycle


class ChartAlarm(OpenModel):
    """An alarm of the station's charts."""

    index: int = Field(description="after which observation (inspections so far)")
    chart: str = Field(description="grating, scatter or master")
    reason: str = Field(description="a sentence for the operator and the event log")


class CharacteristicOutcome(OpenModel):
    """A characteristic of the master's inspection (``CharacteristicOutcome``; the twin's truth left out)."""

    id: str
    nominal: Number
    lower_limit: Number
    upper_limit: Number
    measured: Number | None
    uncertainty_k2: Number | None = Field(description="expanded uncertainty, k = 2")
    passed: bool


class ScanFinding(OpenModel):
    """What the scan saw that the spec does not say (the outcome's form of a finding)."""

    kind: str
    message: str
    subject: str | None
    axial_mm: Number | None
    angle_deg: Number | None
    diameter_mm: Number | None
    u_mm: Number | None = Field(description="expanded uncertainty (k = 2) of the position")


class InspectionOutcome(OpenModel):
    """The master's inspection as the session returned it (``InspectionOutcome.to_json()``)."""

    id: str
    part_number: str
    serial: str
    state: str = Field(description="complete, aborted or faulted")
    result: str | None = Field(description="pass or fail; null unless complete")
    reason: str | None = Field(description="why it ended as it did (empty or null when complete)")
    characteristics: list[CharacteristicOutcome]
    findings: list[ScanFinding]
    cycle: Cycle | None
    alarms: list[ChartAlarm]


class MasterCheck(OpenModel):
    """A master characteristic against its certificate (values mm; ``u_*`` standard uncertainties)."""

    id: str
    measured: Number | None
    certified: Number
    u_station: Number | None
    u_certificate: Number
    z: Number | None = Field(description="(measured - certified) / combined standard uncertainty")
    en: Number | None = Field(description="ISO 13528's E_n: z / 2")


class CheckResult(OpenModel):
    """A finished check (``MasterCheckOutcome.to_json()``, the twin's truth left out)."""

    master_id: str
    in_control: bool
    inspection: InspectionOutcome
    checks: list[MasterCheck]
    alarms: list[ChartAlarm]


class Check(OpenModel):
    """A check on the certified master (``CheckRecord.to_json()``); its id is the master inspection's."""

    id: str
    kind: str = Field(description="master")
    master_id: str
    state: str = Field(description="running, then the master inspection's: complete, aborted or faulted")
    in_control: bool | None = Field(description="null while running or when it faulted before a result")
    reason: str | None
    started_at: IsoTime
    finished_at: IsoTime | None
    result: CheckResult | None = Field(description="null while running")
    proposal_id: str | None = Field(description="the model proposal an out-of-control check made")
    links: Links = Field(description="`self`, `inspection` and, with a proposal, `proposal`")


class ProposalChange(OpenModel):
    """One parameter of the model changed."""

    term: str = Field(description="`installation.<body>.<key>`, `node.<body>.<error motion>(...)`, "
                                  "`motion.<...>` or `part.scale_ppm`")
    delta: Number = Field(description="in the term's unit (um for `z_um`)")
    why: str
    u: Number | None = Field(description="the change's standard uncertainty, when it was measured with one")


class Proposal(OpenModel):
    """A model proposal (``Proposal.to_json()``) and where its picture is."""

    id: str
    created_at: IsoTime
    base_version: str = Field(description="the model version it changes")
    reason: str = Field(description="why it was proposed")
    changes: list[ProposalChange]
    evidence: dict[str, list[Number]] = Field(description="per characteristic: measured - certified per check, um")
    expected_change_um: dict[str, Number] = Field(description="per hole: the expected change of its measured "
                                                              "position with the change")
    state: str = Field(description="proposed, approved or rejected")
    explanation: dict[str, Any] = Field(
        description="what the checks over time say the change is (`kind`: step, drift, unknown, steady or "
                    "calibration; `description`; the points or curves drawn); empty for an older proposal")
    decided_by: str | None
    decided_at: IsoTime | None
    decision_note: str | None
    plot_url: str | None = Field(description="the before/after picture (PNG); null when it has none")


class DecidedProposal(Proposal):
    """A proposal as decided, and the model the station uses after the decision."""

    model_version: str = Field(description="the station's model version now (`station_name+N@fingerprint`)")


class ProposalList(ClosedModel):
    """The station's proposals, oldest first, and the model it uses now."""

    model_version: str = Field(description="the station's model version now")
    items: list[Proposal]
