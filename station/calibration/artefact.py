"""The calibration artefact: a certified cylinder with a pattern of small target holes.

What a plant orders: a cylinder with the production part's bore (22.2 mm for the
ZDZG-22.2 family, so the endoscope's detection point sits on its wall at the same
radius and in focus), with small through-holes (0.3 mm) at several axial positions and
angles, e.g. 5 axial rings x 8 angles. The holes are targets: the vision stage
measures their centres like a compensating hole's. An accredited laboratory certifies
each target's axial position (from the datum face that sits on the table) and its
angle (from the angular datum, target ``a1_000``'s nominal 0 deg), each with its
expanded uncertainty U (k = 2), the angle's U stated as the arc length at the wall
(um), the unit the camera sees.

The certificate is a TOML file in the manner of the master part's (``station/checks/
master.py``): ``position_mm`` and ``position_U_um`` as there, plus the nominal values
the artefact was drawn with and ``tangential_U_um``. Built-in artefacts live in
``station/data/masters/artefacts/`` (a folder of their own, so the master-part listing
does not try to read them as master certificates); format in docs/calibration.md.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from station.parts.loader import builtin_names, load_certificate, parse_toml_as
from station.parts.spec import HOLE_ID_PATTERN, PART_NUMBER_PATTERN

_BUILTIN = ("data", "masters", "artefacts")


class CertifiedTarget(BaseModel):
    """One target hole: drawn (nominal) and certified position, with U (k = 2)."""

    model_config = ConfigDict(extra="forbid")

    id: str = Field(pattern=HOLE_ID_PATTERN)
    nominal_position_mm: float = Field(gt=0.0)
    nominal_angle_deg: float = Field(ge=0.0, lt=360.0)
    position_mm: float = Field(gt=0.0, description="certified axial position from the datum face")
    angle_deg: float = Field(ge=0.0, lt=360.0, description="certified angle from the angular datum")
    position_U_um: float = Field(gt=0.0, le=50.0, description="expanded uncertainty, k = 2")
    tangential_U_um: float = Field(gt=0.0, le=50.0, description="U (k = 2) of the angle, as arc length at the wall")
    diameter_mm: float = Field(gt=0.0, le=2.0)

    @model_validator(mode="after")
    def _near_nominal(self) -> CertifiedTarget:
        # a certified value more than 0.2 mm from its drawing is a typing error, not a
        # manufacturing one (the drilling tolerance of such a target is +/-0.05 mm)
        if abs(self.position_mm - self.nominal_position_mm) > 0.2:
            raise ValueError(f"position_mm {self.position_mm} is more than 0.2 mm from nominal {self.nominal_position_mm}")
        d = (self.angle_deg - self.nominal_angle_deg + 180.0) % 360.0 - 180.0
        if abs(d) > 1.0:
            raise ValueError(f"angle_deg {self.angle_deg} is more than 1 deg from nominal {self.nominal_angle_deg}")
        return self


class ArtefactCertificate(BaseModel):
    model_config = ConfigDict(extra="forbid")

    artefact_id: str = Field(pattern=PART_NUMBER_PATTERN)
    description: str = ""
    bore_diameter_mm: float = Field(gt=0.0, le=200.0)
    certificate: str = Field(min_length=1)
    calibrated_on: str = ""
    temperature_c: float = 20.0
    targets: list[CertifiedTarget] = Field(min_length=3)

    @model_validator(mode="after")
    def _unique(self) -> ArtefactCertificate:
        ids = [t.id for t in self.targets]
        dup = sorted({i for i in ids if ids.count(i) > 1})
        if dup:
            raise ValueError(f"target ids appear twice: {', '.join(dup)}")
        return self

    # ----------------------------------------------------------- arrays for the fit
    @property
    def radius_mm(self) -> float:
        return self.bore_diameter_mm / 2.0

    @property
    def ids(self) -> list[str]:
        return [t.id for t in self.targets]

    def certified_axial_mm(self) -> np.ndarray:
        return np.array([t.position_mm for t in self.targets])

    def certified_angle_deg(self) -> np.ndarray:
        return np.array([t.angle_deg for t in self.targets])

    def axial_u_um(self) -> np.ndarray:
        """Standard uncertainty (k = 1) of each certified axial position."""
        return np.array([t.position_U_um for t in self.targets]) / 2.0

    def tangential_u_um(self) -> np.ndarray:
        """Standard uncertainty (k = 1) of each certified angle, as arc length at the wall."""
        return np.array([t.tangential_U_um for t in self.targets]) / 2.0


def parse_artefact(text: str, source: str = "<text>") -> ArtefactCertificate:
    """Validate TOML text as an artefact certificate; :class:`PartSpecError` lists
    every problem with its file, line and key."""
    return parse_toml_as(ArtefactCertificate, text, source)


def builtin_artefacts() -> list[str]:
    return builtin_names(_BUILTIN)


def load_artefact(id_or_path: str | Path) -> ArtefactCertificate:
    """A built-in artefact by id, or a certificate file by path (``.toml`` or a path separator)."""
    return load_certificate(id_or_path, parse_artefact, _BUILTIN, "artefact", "artefact_id")


def design_artefact(artefact_id: str = "CA-22.2-5x8", *, bore_diameter_mm: float = 22.2,
                    rings_mm=(10.0, 42.5, 75.0, 107.5, 140.0), angles_deg=tuple(range(0, 360, 45)),
                    target_diameter_mm: float = 0.3, U_um: float = 1.0, made_sigma_um: float = 8.0,
                    seed: int = 2026) -> ArtefactCertificate:
    """A ring x angle pattern as drawn, with 'certified' values that differ from the
    drawing by a drilling error (``made_sigma_um``, a jig-bored hole's few um), as a
    laboratory would report them. Used to write the shipped certificate and by tests."""
    rng = np.random.default_rng(seed)
    r_mm = bore_diameter_mm / 2.0
    targets = []
    for i, a in enumerate(rings_mm, start=1):
        for phi in angles_deg:
            da_mm = rng.normal(0.0, made_sigma_um) * 1e-3
            dphi_deg = math.degrees(rng.normal(0.0, made_sigma_um) * 1e-3 / r_mm)
            targets.append(CertifiedTarget(
                id=f"a{i}_{int(phi):03d}", nominal_position_mm=float(a), nominal_angle_deg=float(phi),
                position_mm=round(float(a) + da_mm, 4), angle_deg=round(float(phi + dphi_deg) % 360.0, 5),
                position_U_um=U_um, tangential_U_um=U_um, diameter_mm=target_diameter_mm))
    return ArtefactCertificate(artefact_id=artefact_id,
                               description=f"calibration artefact, {bore_diameter_mm} mm bore, "
                                           f"{len(rings_mm)} rings x {len(angles_deg)} target holes",
                               bore_diameter_mm=bore_diameter_mm, certificate="design (not certified)",
                               targets=targets)
