"""Part specs as the API shows them: the spec as written (``PartSpec.to_json()``:
the file's structure, docs/part-specs.md) plus its derived characteristics. A key the
file leaves out (a tolerance's other form, an angular tolerance, an angular datum) is
left out of the answer too."""

from __future__ import annotations

from pydantic import Field

from api.schemas.common import ClosedModel, Number, OpenModel


class ToleranceDoc(OpenModel):
    """A nominal with either ``tol`` (symmetric) or ``upper`` and ``lower`` (signed deviations), mm."""

    nominal: Number
    tol: Number | None = Field(default=None, description="symmetric tolerance: nominal ± tol")
    upper: Number | None = Field(default=None, description="upper deviation from nominal (signed)")
    lower: Number | None = Field(default=None, description="lower deviation from nominal (signed)")


class BoreDoc(OpenModel):
    """The cylinder bore the endoscope enters."""

    diameter_mm: Number
    depth_mm: Number


class PlacementDoc(OpenModel):
    """How well the part's place on the table is known (docs/part-specs.md, Search zones)."""

    axial_mm: Number
    angle_deg: Number
    angular_datum: str | None = Field(default=None, description="the hole that sets the part's angle (no fixture)")


class HoleDoc(OpenModel):
    """A compensating hole: diameter and axial position (from the datum face), mm."""

    id: str
    angle_deg: Number = Field(description="nominal angle about the bore axis, [0, 360) deg")
    angle_tol_deg: Number | None = Field(default=None, description="angular tolerance of the hole's place, +/- deg")
    diameter: ToleranceDoc
    position: ToleranceDoc


class CharacteristicLimits(OpenModel):
    """A characteristic derived from the holes, with its absolute limits."""

    id: str = Field(description="`<hole id>.<kind>`")
    unit: str
    nominal: Number
    lower_limit: Number
    upper_limit: Number


class PartSpecDoc(OpenModel):
    """A part spec: what a part must be."""

    part_number: str
    description: str
    unit: str = Field(description="mm")
    bore: BoreDoc
    placement: PlacementDoc
    holes: list[HoleDoc]
    characteristics: list[CharacteristicLimits] = Field(description="derived: per hole, diameter then position")


class PartList(ClosedModel):
    """Every part spec the station knows: built-in and its own (these win)."""

    items: list[PartSpecDoc]
