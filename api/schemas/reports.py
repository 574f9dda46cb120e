"""Reports from uploads: ISO 230-2 figures (``station iso230 --json``) and mismatch
discovery (``station discover``'s ``report.json``, ../shared/spec/discovery.md section 4).
Deviations are in the recording's deviation unit (um or arcsec), positions in its
position unit (mm or deg)."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field

from api.schemas.common import ClosedModel, IsoTime, Links, Number, OpenModel

#: the figures of ISO 230-2:2014 a report gives, null where undefined (docs/iso230.md)
_FIGURE = "ISO 230-2 figure, in unit; null where undefined (docs/iso230.md)"


class Iso230Target(OpenModel):
    """Statistics at one target position."""

    target: Number = Field(description="in the recording's position unit")
    mean_up: Number | None
    mean_down: Number | None
    s_up: Number | None
    s_down: Number | None
    n_up: int
    n_down: int
    B_i: Number | None = Field(description="reversal value at the target")


class Iso230Report(OpenModel):
    """The ISO 230-2 figures of one axis (``Iso230Result.to_json()``)."""

    B: Number | None = Field(description=f"reversal value: {_FIGURE}")
    B_mean: Number | None = Field(description=f"mean reversal value: {_FIGURE}")
    R_up: Number | None = Field(description=f"repeatability, + direction: {_FIGURE}")
    R_down: Number | None = Field(description=f"repeatability, - direction: {_FIGURE}")
    R: Number | None = Field(description=f"bidirectional repeatability: {_FIGURE}")
    E_up: Number | None = Field(description=f"systematic positioning error, + direction: {_FIGURE}")
    E_down: Number | None = Field(description=f"systematic positioning error, - direction: {_FIGURE}")
    E: Number | None = Field(description=f"bidirectional systematic positioning error: {_FIGURE}")
    M: Number | None = Field(description=f"mean bidirectional positioning error: {_FIGURE}")
    A_up: Number | None = Field(description=f"accuracy, + direction: {_FIGURE}")
    A_down: Number | None = Field(description=f"accuracy, - direction: {_FIGURE}")
    A: Number | None = Field(description=f"bidirectional accuracy: {_FIGURE}")
    targets: list[Iso230Target]
    unit: str = Field(description="deviation unit: um (linear) or arcsec (rotary)")
    kind: str = Field(description="linear or rotary")
    warnings: list[str]


class ResidualSummary(OpenModel):
    """The residual (recording minus model prediction) before or after the effects found."""

    rms: Number
    bic: Number | None
    white: bool = Field(description="passes the whiteness tests (Ljung-Box and runs)")
    ljung_box_p: Number | None = None
    runs_p: Number | None = None
    max_abs: Number | None = None


class DiscoveryFinding(OpenModel):
    """Where the residual is structured; further keys depend on the signature."""

    signature: str = Field(description="direction, position, periodic, time, temperature, angle or local")
    stage: str | None = Field(default=None, description="before or after the effects found")
    range: list[Number] | None = Field(default=None, description="the position range it concerns")
    direction: str | None = None
    description: str | None = None


class DiscoveredEffect(OpenModel):
    """An effect the tool is confident in, with its physical explanation."""

    name: str = Field(description="an effect of the vocabulary (backlash, scale, periodic, ...)")
    parameters: dict[str, Any]
    stderr: dict[str, Any] = Field(description="the parameters' standard errors")
    delta_bic: Number | None = None
    p_value: Number | None = None
    explanation: str | None = None


class DiscoveryAxis(OpenModel):
    name: str
    kind: str = Field(description="linear or rotary")


class DiscoveryRecording(OpenModel):
    source: str
    rows: int
    rows_used: int
    runs: int


class DiscoveryReport(OpenModel):
    """The discovery report: the contract's keys, and what the tool adds (``noise``,
    ``ambiguities``, ``not_analysed``, ``outliers``, ``selection``, ``axis``,
    ``recording``), which a report stored by an older version may lack."""

    verdict: Literal["no-mismatch", "explained", "partly-explained"]
    noise_floor: Number
    before: ResidualSummary
    after: ResidualSummary
    findings: list[DiscoveryFinding]
    effects: list[DiscoveredEffect] = Field(description="empty when the verdict is no-mismatch")
    ambiguities: list[dict[str, Any]] | None = None
    not_analysed: list[dict[str, Any]] | None = None
    outliers: list[dict[str, Any]] | None = None
    noise: dict[str, Any] | None = None
    selection: dict[str, Any] | None = None
    axis: DiscoveryAxis | None = None
    recording: DiscoveryRecording | None = None


class DiscoverySummary(ClosedModel):
    """A stored discovery report in a list."""

    id: str
    created_at: IsoTime
    created_by: str = Field(description="the token's name")
    model_file: str
    recording_file: str
    axis: DiscoveryAxis | None
    verdict: str | None
    rms_before: Number | None
    rms_after: Number | None
    effects: list[str | None] = Field(description="the effects' names")
    links: Links


class DiscoveryList(ClosedModel):
    """The stored discovery reports, newest first."""

    total: int
    items: list[DiscoverySummary]


class PlotLink(ClosedModel):
    """One of a run's pictures."""

    name: str = Field(description="e.g. residual_position.png")
    view: str = Field(description="what it shows")
    url: str


class StoredDiscoveryReport(OpenModel):
    """A stored report: who made it, when, from which files, the report, its pictures."""

    id: str
    created_at: IsoTime
    created_by: str
    model_file: str
    recording_file: str
    report: DiscoveryReport
    plots: list[PlotLink] = Field(description="none for a report stored before the API kept plots")
