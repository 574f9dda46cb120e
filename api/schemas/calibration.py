"""A self-calibration run on a certified artefact (docs/calibration.md)."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field


class Parameter(BaseModel):
    model_config = ConfigDict(extra="allow")
    name: str
    unit: str
    value: float
    u: float | None = Field(description="standard uncertainty; null when not observable")
    observable: bool


class Observability(BaseModel):
    model_config = ConfigDict(extra="allow")
    rank: int
    n_parameters: int
    condition: float | None
    unobservable: list[dict[str, Any]]


class CalibrationResult(BaseModel):
    """What ``station calibrate master --json`` prints (docs/calibration.md)."""

    model_config = ConfigDict(extra="allow")
    parameters: list[Parameter]
    observability: Observability
    residual_rms_um: float | None
    model_version: str | None = Field(description="the model proposal made from the result (propose), else null")


class CalibrationRun(BaseModel):
    id: str
    kind: Literal["master"] = "master"
    artefact: str
    poses: int
    propose: bool
    state: Literal["running", "complete", "faulted"]
    reason: str | None = None
    started_at: str
    finished_at: str | None = None
    result: CalibrationResult | None = None
    links: dict[str, str]
