"""A straightforward per-pose implementation of Eq. (12), for checking and as the
benchmark's baseline.

It builds every body's 4x4 homogeneous matrix for one pose at a time, multiplies
the two chains in full and inverts with a general 4x4 inverse, exactly as the
paper writes E = [(T04' T45' T56' T67')^-1 (T01' T12' T23')] [(...)^-1 (...)]^-1.
It shares only the model's data (geometry, error values) with the vectorised code,
not its algebra, so agreement between the two is a real check.
"""

from __future__ import annotations

import math

import numpy as np

from station.kinematics.model import StationModel


def _h_small(six) -> np.ndarray:
    """4x4 of Trans(d) Rz(c) Ry(b) Rx(a) for one six-vector (mm, rad)."""
    dx, dy, dz, a, b, c = (float(v) for v in six)
    ca, sa, cb, sb, cc, sc = math.cos(a), math.sin(a), math.cos(b), math.sin(b), math.cos(c), math.sin(c)
    Rx = np.array([[1, 0, 0], [0, ca, -sa], [0, sa, ca]])
    Ry = np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])
    Rz = np.array([[cc, -sc, 0], [sc, cc, 0], [0, 0, 1]])
    H = np.eye(4)
    H[:3, :3] = Rz @ Ry @ Rx
    H[:3, 3] = (dx, dy, dz)
    return H


def _h_trans(x, y, z) -> np.ndarray:
    H = np.eye(4)
    H[:3, 3] = (x, y, z)
    return H


def _h_rotz(c_rad) -> np.ndarray:
    H = np.eye(4)
    H[:2, :2] = [[math.cos(c_rad), -math.sin(c_rad)], [math.sin(c_rad), math.cos(c_rad)]]
    return H


def body_matrix(model: StationModel, body_name: str, z_mm: float, c_deg: float, motions_si: dict | None) -> np.ndarray:
    """T_{L1(j), j} for one body (actual when ``motions_si`` is given, else ideal)."""
    b = model.topology.by_name(body_name)
    D = np.asarray(model.endoscope_offset_mm)
    T = np.asarray(model.table_offset_mm)
    static = {"N": _h_trans(*D), "P2": _h_trans(*T), "M": _h_trans(*(D - T))}.get(body_name, np.eye(4))
    actual = motions_si is not None
    if actual and b.joint != "prismatic_z":
        static = static @ _h_small(model.static_of(body_name).as_si())
    if b.joint == "prismatic_z":
        motion = _h_trans(0, 0, z_mm)
        if actual:
            motion = motion @ _h_small(motions_si[body_name])
    elif b.joint == "revolute_z":
        motion = _h_rotz(math.radians(c_deg))
        if actual:
            motion = _h_small(motions_si[body_name]) @ motion
    else:
        motion = np.eye(4)
    return static @ motion


def error_matrix_loop(model: StationModel, z_mm, c_deg) -> np.ndarray:
    """E (N, 4, 4) computed one pose at a time with full 4x4 algebra (Eq. 12)."""
    z_all = np.atleast_1d(np.asarray(z_mm, dtype=float))
    c_all = np.atleast_1d(np.asarray(c_deg, dtype=float))
    z_all, c_all = np.broadcast_arrays(z_all, c_all)
    names = [b.name for b in model.topology.bodies]
    out = np.empty((z_all.size, 4, 4))
    for i, (z, c) in enumerate(zip(z_all, c_all)):
        motions = model.motion_values_si(np.array([z]), np.array([c]))
        motions = {k: v[0] for k, v in motions.items()}

        def chain(indices, m):
            H = np.eye(4)
            for j in indices:
                H = H @ body_matrix(model, names[j], z, c, m)
            return H

        tool, work = model.topology.tool_chain, model.topology.workpiece_chain
        actual = np.linalg.inv(chain(work, motions)) @ chain(tool, motions)
        ideal = np.linalg.inv(chain(work, None)) @ chain(tool, None)
        out[i] = actual @ np.linalg.inv(ideal)
    return out
