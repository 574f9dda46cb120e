"""Compensation models and camera calibrations: their versions, and the active model's curves."""

from __future__ import annotations

from pydantic import Field

from api.schemas.common import ClosedModel, IsoTime, Number, OpenModel


class UploadedVersion(OpenModel):
    """An uploaded version (an entry of ``index.json``, :mod:`api.versions`)."""

    version: int
    name: str = Field(description="the short name given at upload")
    filename: str = Field(description="the uploaded file's name")
    sha256: str
    size: int = Field(description="bytes")
    uploaded_by: str = Field(description="the token's name")
    uploaded_at: IsoTime
    active: bool = Field(description="the station uses this version now")


class VersionList(ClosedModel):
    """Every version of one kind, oldest first, and the active one."""

    active: int | None = Field(description="the active version; null: the config's default")
    items: list[UploadedVersion]


class CurveSamples(ClosedModel):
    """An error motion sampled at the axis' ``positions``."""

    unit: str = Field(description="um (a translation) or arcsec (a rotation)")
    zero: bool = Field(description="the model has no such error (values all 0)")
    values: list[Number] = Field(description="approaching in the + direction")
    values_down: list[Number] | None = Field(
        default=None, description="approaching in the - direction; only where the direction matters (backlash)")


class AxisCurves(ClosedModel):
    """An axis' six error motions over its travel (ISO 230-1 names, e.g. EXZ..ECZ)."""

    unit: str = Field(description="unit of positions: mm (Z) or deg (C)")
    positions: list[Number]
    curves: dict[str, CurveSamples] = Field(description="by error motion")


class CompensationTable(ClosedModel):
    """A tabulated curve's baseline table; the correction is minus the deviation."""

    axis: str
    position_unit: str
    unit: str = Field(description="unit of deviation and correction")
    target: list[Number] = Field(description="positions, in position_unit")
    deviation: list[Number]
    correction: list[Number]
    effects: list[str] = Field(description="the effects on the curve, by class name")


class ModelCurves(ClosedModel):
    """The error motions of the model the station compensates with now."""

    model: str = Field(description="the model's name")
    axes: dict[str, AxisCurves] = Field(description="Z and C")
    compensation_tables: dict[str, CompensationTable] = Field(
        description="by error motion, the non-zero tabulated ones")
    version: int | None = Field(description="the active model version; null: the config's model")
