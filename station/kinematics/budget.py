"""The error budget: which error parameter matters where.

Each parameter's first-order contribution (sensitivity x its value at the pose)
to the detection point's error in the part's own coordinates: axial (um, what the
hole-position measurement sees), tangential (um along the wall) and the angle
(arcsec); the radial component only changes focus and is reported for completeness.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from station.kinematics.model import StationModel
from station.kinematics.rigid import ARCSEC_PER_RAD


@dataclass(frozen=True)
class BudgetRow:
    parameter: str
    max_axial_um: float
    max_tangential_um: float
    max_angle_arcsec: float
    max_radial_um: float
    worst_z_mm: float
    worst_c_deg: float


def part_directions(model: StationModel, z_mm, c_deg) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors (N, 3) in M of the radial and the tangential (increasing part
    angle) directions at the ideal detection points, and the radius."""
    pt = model.ideal_point_mm(z_mm, c_deg)
    r = np.asarray(model.endoscope_offset_mm) - np.asarray(model.table_offset_mm)
    q = pt[..., :2] + r[:2]
    radius = np.hypot(q[..., 0], q[..., 1])[..., None]
    radial = np.concatenate([q / radius, np.zeros(q.shape[:-1] + (1,))], axis=-1)
    # the part angle grows clockwise seen from +z (the table turns the part by -C in M)
    tangential = np.stack([radial[..., 1], -radial[..., 0], np.zeros(q.shape[:-1])], axis=-1)
    return radial, tangential


def error_budget(model: StationModel, z_mm, c_deg) -> list[BudgetRow]:
    z = np.atleast_1d(np.asarray(z_mm, dtype=float))
    c = np.atleast_1d(np.asarray(c_deg, dtype=float))
    z, c = np.broadcast_arrays(z, c)
    S = model.sensitivity(z, c)[:, 6:9, :]  # point displacement per SI unit, (N, 3, P)
    values = model.parameter_values_si(z, c)  # (N, P)
    contrib_mm = S * values[:, None, :]  # (N, 3, P)
    radial, tangential = part_directions(model, z, c)
    r = np.hypot(*(np.asarray(model.endoscope_offset_mm[:2]) - np.asarray(model.table_offset_mm[:2])))
    axial = contrib_mm[:, 2, :] * 1e3
    tang = np.einsum("nkp,nk->np", contrib_mm, tangential) * 1e3
    rad = np.einsum("nkp,nk->np", contrib_mm, radial) * 1e3
    angle = tang * 1e-3 / r * ARCSEC_PER_RAD
    rows = []
    for j, name in enumerate(model.parameter_names):
        k = int(np.argmax(np.abs(axial[:, j]) + np.abs(tang[:, j])))
        rows.append(
            BudgetRow(
                name,
                float(np.max(np.abs(axial[:, j]))),
                float(np.max(np.abs(tang[:, j]))),
                float(np.max(np.abs(angle[:, j]))),
                float(np.max(np.abs(rad[:, j]))),
                float(z[k]),
                float(c[k]),
            )
        )
    rows.sort(key=lambda b: -(b.max_axial_um + b.max_tangential_um))
    return rows
