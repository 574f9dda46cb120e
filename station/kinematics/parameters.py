"""The error parameters of the station: installation errors, error motions, alignment.

Names follow ISO 230-1 beside the paper's symbols (shared/design/error-model-notes.md):

* installation errors of bodies N, P1, P2, J, M (paper Eqs. 2, 4, 5, 7, 8):
  ``dx_N`` = Delta x_N ... ``gamma_N`` = Delta gamma_N (translations um, rotations arcsec);
* error motions of Z as functions of z (Eq. 3): EXZ = delta_x(z), EYZ = delta_y(z),
  EZZ = delta_z(z) (positioning), EAZ = eps_x(z), EBZ = eps_y(z), ECZ = eps_z(z);
* error motions of C as functions of C (Eq. 6, with eps_z(C) restored): EXC, EYC,
  EZC, EAC, EBC, ECC (= eps_z(C), angular positioning);
* alignment of the C axis to Z (ISO 230-1 location errors): X0C, Y0C (um), A0C, B0C
  (arcsec, the two squareness tilts), and C0C (arcsec): the paper's eta_ZC *as printed*,
  which sits in the xy block of T45p' and therefore is a zero offset of C about z,
  not a squareness.

Sign convention (one for all): every error is *actual minus nominal* in the frame
named; rotations are right-handed about +x, +y, +z. For the positioning errors this
is the recording's ``deviation`` (actual minus commanded), so an ISO 230-2 run of Z
is EZZ(z) and a rotary-calibrator run of C is ECC(C) directly.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np

from station.effects import ErrorCurve
from station.kinematics.rigid import MM_PER_UM, RAD_PER_ARCSEC

#: the six components of a small rigid error, in the order of all six-vectors here
COMPONENTS = ("x", "y", "z", "a", "b", "c")
#: unit of each component in files and reports (SI inside the kinematics: mm, rad)
COMPONENT_UNITS = ("um", "um", "um", "arcsec", "arcsec", "arcsec")
#: factor from the report unit to the kinematics' unit (um -> mm, arcsec -> rad)
TO_SI = np.array([MM_PER_UM] * 3 + [RAD_PER_ARCSEC] * 3)


@dataclass(frozen=True)
class SixDof:
    """A constant small rigid error: translations in um, rotations in arcsec."""

    x_um: float = 0.0
    y_um: float = 0.0
    z_um: float = 0.0
    a_arcsec: float = 0.0
    b_arcsec: float = 0.0
    c_arcsec: float = 0.0

    def values(self) -> np.ndarray:
        return np.array([getattr(self, f.name) for f in fields(self)], dtype=float)

    def as_si(self) -> np.ndarray:
        """(dx, dy, dz) mm and (a, b, c) rad."""
        return self.values() * TO_SI

    @classmethod
    def from_values(cls, v) -> "SixDof":
        return cls(*map(float, v))


@dataclass(frozen=True)
class ErrorMotions:
    """The six error motions of one axis, each an :class:`ErrorCurve` of the axis
    position (mm for Z, deg for C): translations in um, rotations in arcsec."""

    x: ErrorCurve = field(default_factory=ErrorCurve)
    y: ErrorCurve = field(default_factory=ErrorCurve)
    z: ErrorCurve = field(default_factory=ErrorCurve)
    a: ErrorCurve = field(default_factory=ErrorCurve)
    b: ErrorCurve = field(default_factory=ErrorCurve)
    c: ErrorCurve = field(default_factory=ErrorCurve)

    @classmethod
    def zero(cls, kind: str) -> "ErrorMotions":
        return cls(*(ErrorCurve.zero(kind) for _ in COMPONENTS))

    def curves(self) -> tuple[ErrorCurve, ...]:
        return (self.x, self.y, self.z, self.a, self.b, self.c)

    def evaluate_si(self, position, direction=None, time_s=None, temperature_c=None) -> np.ndarray:
        """All six at ``position`` (N,), as (N, 6) in mm and rad."""
        pos = np.asarray(position, dtype=float)
        out = np.empty(pos.shape + (6,))
        for i, curve in enumerate(self.curves()):
            if curve.is_zero:
                out[..., i] = 0.0
            else:
                out[..., i] = curve.evaluate(pos, direction, time_s, temperature_c) * TO_SI[i]
        return out


def installation_names(body: str) -> tuple[str, ...]:
    """The paper's symbols for a body's installation errors: dx_N ... gamma_N."""
    return tuple(f"{n}_{body}" for n in ("dx", "dy", "dz", "alpha", "beta", "gamma"))


def motion_names(axis: str) -> tuple[str, ...]:
    """ISO 230-1 names of an axis's error motions: EXZ ... ECZ."""
    return tuple(f"E{c.upper()}{axis}" for c in ("x", "y", "z", "a", "b", "c"))


def alignment_names(axis: str) -> tuple[str, ...]:
    """ISO 230-1 location errors of a rotary axis; the sixth (Z0C) is not
    separable from dz of its bracket, and C0C is the paper's eta_ZC as printed."""
    return (f"X0{axis}", f"Y0{axis}", f"Z0{axis}", f"A0{axis}", f"B0{axis}", f"C0{axis}")
