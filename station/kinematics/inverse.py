"""Inverse compensation: the commanded (z, C) that puts the endoscope's detection
point on a target of the part under the full error model.

A target is (axial position mm, angle deg) on the bore wall, in the part frame M
(see ``StationModel.part_coordinates``). The radial component is not a target: the
side-view endoscope looks at the wall, and a radial error only changes the focus.
We solve F(z, C) = (axial(z, C) - a, angle(z, C) - phi) = 0 by Newton's method on
the exact model, vectorised over targets, with a forward-difference Jacobian
(the error motions are interpolated tables, piecewise smooth: an analytic
derivative would not be better defined than the difference quotient).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from station.kinematics.model import StationModel

#: convergence bars, well inside the goal of 1 nm and 0.01 arcsec
AXIAL_TOL_MM = 1e-7  # 0.1 nm
ANGLE_TOL_DEG = 1e-3 / 3600.0  # 0.001 arcsec
#: difference steps: small against the table spacing, large against rounding (1e-16 * 150 mm)
STEP_Z_MM = 1e-4
STEP_C_DEG = 1e-4


@dataclass(frozen=True)
class Compensation:
    target_axial_mm: np.ndarray
    target_angle_deg: np.ndarray
    z_mm: np.ndarray  # commanded slide position
    c_deg: np.ndarray  # commanded table angle
    axial_error_mm: np.ndarray  # remaining error at the solution (model)
    angle_error_deg: np.ndarray
    radial_error_mm: np.ndarray  # radial offset of the detection point from the wall (not compensated)
    iterations: int
    converged: np.ndarray  # bool per target

    @property
    def dz_mm(self) -> np.ndarray:
        """Correction added to the nominal command (commanded minus target)."""
        return self.z_mm - self.target_axial_mm

    @property
    def dc_deg(self) -> np.ndarray:
        return _wrap_deg(self.c_deg - self.target_angle_deg)


def _wrap_deg(a):
    return (np.asarray(a) + 180.0) % 360.0 - 180.0


def _residual(model, z, c, axial, angle, ctx):
    e = model.errors(z, c, **ctx)
    ax, ang, rad = model.part_coordinates(e.actual_point_mm)
    return ax - axial, _wrap_deg(ang - angle), rad


def compensate(
    model: StationModel,
    axial_mm,
    angle_deg,
    *,
    direction_z=None,
    direction_c=None,
    time_s=None,
    temperature_c=None,
    max_iterations: int = 30,
) -> Compensation:
    """Commanded (z, C) for each target (axial_mm, angle_deg), vectorised."""
    axial = np.atleast_1d(np.asarray(axial_mm, dtype=float))
    angle = np.atleast_1d(np.asarray(angle_deg, dtype=float))
    axial, angle = np.broadcast_arrays(axial, angle)
    ctx = dict(direction_z=direction_z, direction_c=direction_c, time_s=time_s, temperature_c=temperature_c)
    # nominal command: the ideal model puts the point at axial z and angle C
    z = axial.astype(float).copy()
    c = angle.astype(float).copy()
    n = z.size
    converged = np.zeros(n, dtype=bool)
    it = 0
    for it in range(1, max_iterations + 1):
        f_ax, f_an, _ = _residual(model, z, c, axial, angle, ctx)
        converged = (np.abs(f_ax) < AXIAL_TOL_MM) & (np.abs(f_an) < ANGLE_TOL_DEG)
        if converged.all():
            break
        # Jacobian by forward differences, all targets at once (2 extra model calls)
        fz_ax, fz_an, _ = _residual(model, z + STEP_Z_MM, c, axial, angle, ctx)
        fc_ax, fc_an, _ = _residual(model, z, c + STEP_C_DEG, axial, angle, ctx)
        j11 = (fz_ax - f_ax) / STEP_Z_MM
        j21 = _wrap_deg(fz_an - f_an) / STEP_Z_MM
        j12 = (fc_ax - f_ax) / STEP_C_DEG
        j22 = _wrap_deg(fc_an - f_an) / STEP_C_DEG
        det = j11 * j22 - j12 * j21
        dz = (j22 * f_ax - j12 * f_an) / det
        dc = (-j21 * f_ax + j11 * f_an) / det
        step = ~converged
        z = np.where(step, z - dz, z)
        c = np.where(step, c - dc, c)
    f_ax, f_an, rad = _residual(model, z, c, axial, angle, ctx)
    converged = (np.abs(f_ax) < AXIAL_TOL_MM) & (np.abs(f_an) < ANGLE_TOL_DEG)
    r0 = np.hypot(*(np.asarray(model.endoscope_offset_mm[:2]) - np.asarray(model.table_offset_mm[:2])))
    return Compensation(axial, angle, z, c, f_ax, f_an, rad - r0, it, converged)
