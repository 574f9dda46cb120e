"""The certified master part: its certificate, the part spec it is inspected with, and
the comparison of a check's results with the certificate.

A certificate is a TOML file (``station/data/masters/<id>.toml`` for the built-in ones;
format in docs/monitor.md): the master's id, the part family whose spec it follows
(bore, placement, tolerances, search zones), the certificate's reference, and per hole
its certified position and diameter with their expanded uncertainties (k = 2, um).
"""

from __future__ import annotations

from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field, model_validator

from station.monitor.watch import CharacteristicCheck
from station.parts.loader import builtin_names, load_certificate, parse_toml_as
from station.parts.spec import HOLE_ID_PATTERN, PART_NUMBER_PATTERN, PartSpec

_BUILTIN = ("data", "masters")


class CertifiedHole(BaseModel):
    model_config = ConfigDict(extra="forbid")

    id: str = Field(pattern=HOLE_ID_PATTERN)
    angle_deg: float = Field(ge=0.0, lt=360.0)
    position_mm: float = Field(gt=0.0)
    position_U_um: float = Field(gt=0.0, le=50.0, description="expanded uncertainty, k = 2")
    diameter_mm: float = Field(gt=0.0)
    diameter_U_um: float = Field(gt=0.0, le=50.0, description="expanded uncertainty, k = 2")


class MasterCertificate(BaseModel):
    model_config = ConfigDict(extra="forbid")

    master_id: str = Field(pattern=PART_NUMBER_PATTERN)
    description: str = ""
    part_number: str = Field(pattern=PART_NUMBER_PATTERN)
    certificate: str = Field(min_length=1)
    calibrated_on: str = ""
    temperature_c: float = 20.0
    holes: list[CertifiedHole] = Field(min_length=1)

    @model_validator(mode="after")
    def _unique(self) -> MasterCertificate:
        ids = [h.id for h in self.holes]
        dup = sorted({i for i in ids if ids.count(i) > 1})
        if dup:
            raise ValueError(f"hole ids appear twice: {', '.join(dup)}")
        return self

    def hole(self, hole_id: str) -> CertifiedHole:
        for h in self.holes:
            if h.id == hole_id:
                return h
        raise KeyError(f"master {self.master_id} has no certified hole {hole_id!r}")

    def as_part_spec(self, family: PartSpec) -> PartSpec:
        """The spec the station inspects the master with: the family's bore, placement
        and tolerance widths about the certified values (so the search zones are the
        master's own); every certified hole must be a hole of the family."""
        data = family.model_dump(mode="json", exclude_none=True)
        data["part_number"] = self.master_id
        data["description"] = f"master {self.master_id} ({self.certificate})"
        fam = {h.id: h for h in family.holes}
        missing = [h.id for h in self.holes if h.id not in fam]
        if missing:
            raise ValueError(f"master {self.master_id}: {', '.join(missing)} not holes of {family.part_number}")
        holes = []
        for h in self.holes:
            f = fam[h.id]
            holes.append({"id": h.id, "angle_deg": h.angle_deg,
                          **({"angle_tol_deg": f.angle_tol_deg} if f.angle_tol_deg is not None else {}),
                          "diameter": {"nominal": h.diameter_mm, "upper": f.diameter.upper_limit - f.diameter.nominal,
                                       "lower": f.diameter.lower_limit - f.diameter.nominal},
                          "position": {"nominal": h.position_mm, "upper": f.position.upper_limit - f.position.nominal,
                                       "lower": f.position.lower_limit - f.position.nominal}})
        data["holes"] = holes
        return PartSpec.model_validate(data)


def parse_master(text: str, source: str = "<text>") -> MasterCertificate:
    """Validate TOML text as a master certificate; :class:`PartSpecError` lists every
    problem with its file, line and field."""
    return parse_toml_as(MasterCertificate, text, source)


def builtin_masters() -> list[str]:
    return builtin_names(_BUILTIN)


def load_master(id_or_path: str | Path) -> MasterCertificate:
    """A built-in master by id, or a certificate file by path (``.toml`` or a path separator)."""
    return load_certificate(id_or_path, parse_master, _BUILTIN, "master", "master_id")


def compare(cert: MasterCertificate, characteristics) -> list[CharacteristicCheck]:
    """Each measured characteristic (``CharacteristicOutcome``: id, measured, U k = 2)
    of a master inspection against its certificate, standard uncertainties (k = 1)."""
    out = []
    for c in characteristics:
        hole_id, _, kind = c.id.rpartition(".")
        if kind not in ("position", "diameter"):
            continue  # a surface criterion: the certificate states the holes only
        h = cert.hole(hole_id)
        certified, U_um = (h.position_mm, h.position_U_um) if kind == "position" else (h.diameter_mm, h.diameter_U_um)
        u_station = None if c.uncertainty_k2 is None else c.uncertainty_k2 / 2.0
        out.append(CharacteristicCheck(c.id, c.measured, certified, u_station, U_um * 1e-3 / 2.0))
    return out
