"""Batched rigid transforms: rotation ``R`` (..., 3, 3) and translation ``p`` (..., 3).

A homogeneous 4x4 matrix [[R, p], [0, 1]] is kept as its two blocks: the product
and the inverse of rigid transforms are then exact and cheap (R^T instead of a
general 4x4 inverse), and numpy broadcasts a constant (3, 3) against a batch
(N, 3, 3) without copies.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: arcseconds in a radian (1 rad = 180/pi deg = 648000/pi arcsec)
ARCSEC_PER_RAD = 648000.0 / np.pi
RAD_PER_ARCSEC = np.pi / 648000.0
MM_PER_UM = 1e-3


@dataclass(frozen=True)
class Rigid:
    R: np.ndarray  # (..., 3, 3)
    p: np.ndarray  # (..., 3)

    @classmethod
    def identity(cls) -> "Rigid":
        return cls(np.eye(3), np.zeros(3))

    @classmethod
    def translation(cls, xyz) -> "Rigid":
        xyz = np.asarray(xyz, dtype=float)
        R = np.broadcast_to(np.eye(3), xyz.shape[:-1] + (3, 3))
        return cls(R, xyz)

    def __matmul__(self, other: "Rigid") -> "Rigid":
        R = self.R @ other.R
        p = np.einsum("...ij,...j->...i", self.R, other.p) + self.p
        return Rigid(R, p)

    def inverse(self) -> "Rigid":
        Rt = np.swapaxes(self.R, -1, -2)
        return Rigid(Rt, -np.einsum("...ij,...j->...i", Rt, self.p))

    def apply(self, points: np.ndarray) -> np.ndarray:
        return np.einsum("...ij,...j->...i", self.R, points) + self.p

    def matrix(self) -> np.ndarray:
        """The homogeneous 4x4 matrix (..., 4, 4)."""
        shape = np.broadcast_shapes(self.R.shape[:-2], self.p.shape[:-1])
        out = np.zeros(shape + (4, 4))
        out[..., :3, :3] = self.R
        out[..., :3, 3] = self.p
        out[..., 3, 3] = 1.0
        return out


def then_translate_z(T: Rigid | None, z_mm) -> Rigid:
    """T @ Trans(0, 0, z) without a full product: only p changes (p + R e_z z)."""
    z = np.asarray(z_mm, dtype=float)
    if T is None:
        p = np.zeros(z.shape + (3,))
        p[..., 2] = z
        return Rigid(np.eye(3), p)
    return Rigid(T.R, T.p + T.R[..., :, 2] * z[..., None])


def then_rotate_z(T: Rigid | None, c_rad) -> Rigid:
    """T @ Rz(c) without a full product: only the first two columns of R mix."""
    c = np.asarray(c_rad, dtype=float)
    if T is None:
        return Rigid(rot_z(c), np.zeros(3))
    cc, sc = np.cos(c)[..., None], np.sin(c)[..., None]
    R = np.broadcast_to(T.R, np.broadcast_shapes(T.R.shape, c.shape + (3, 3))).copy()
    col0 = R[..., :, 0].copy()
    R[..., :, 0] = col0 * cc + R[..., :, 1] * sc
    R[..., :, 1] = R[..., :, 1] * cc - col0 * sc
    return Rigid(R, T.p)


def rot_xyz(a_rad, b_rad, c_rad) -> np.ndarray:
    """Exact rotation R = Rz(c) Ry(b) Rx(a), shape (..., 3, 3).

    To first order it is [[1, -c, b], [c, 1, -a], [-b, a, 1]]: the small-angle
    matrix of the paper's Eqs. (2)-(8) and (13), with a, b, c the rotations about
    x, y, z (eps_x, eps_y, eps_z; ISO 230-1 EA., EB., EC.). Right-handed, positive
    counter-clockwise looking down the axis.
    """
    a = np.asarray(a_rad, dtype=float)
    b = np.asarray(b_rad, dtype=float)
    c = np.asarray(c_rad, dtype=float)
    ca, sa = np.cos(a), np.sin(a)
    cb, sb = np.cos(b), np.sin(b)
    cc, sc = np.cos(c), np.sin(c)
    shape = np.broadcast_shapes(a.shape, b.shape, c.shape)
    R = np.empty(shape + (3, 3))
    R[..., 0, 0] = cc * cb
    R[..., 0, 1] = cc * sb * sa - sc * ca
    R[..., 0, 2] = cc * sb * ca + sc * sa
    R[..., 1, 0] = sc * cb
    R[..., 1, 1] = sc * sb * sa + cc * ca
    R[..., 1, 2] = sc * sb * ca - cc * sa
    R[..., 2, 0] = -sb
    R[..., 2, 1] = cb * sa
    R[..., 2, 2] = cb * ca
    return R


def angles_xyz(R: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rot_xyz`: (a, b, c) in radians, shape (..., 3).

    This is the exact reading of Eq. (13)'s theta_x, theta_y, theta_z from the
    rotation block of E (valid for |b| < 90 deg, far beyond any error motion).
    """
    b = np.arcsin(np.clip(-R[..., 2, 0], -1.0, 1.0))
    a = np.arctan2(R[..., 2, 1], R[..., 2, 2])
    c = np.arctan2(R[..., 1, 0], R[..., 0, 0])
    return np.stack([a, b, c], axis=-1)


def rot_z(c_rad) -> np.ndarray:
    c = np.asarray(c_rad, dtype=float)
    cc, sc = np.cos(c), np.sin(c)
    R = np.zeros(c.shape + (3, 3))
    R[..., 0, 0] = cc
    R[..., 0, 1] = -sc
    R[..., 1, 0] = sc
    R[..., 1, 1] = cc
    R[..., 2, 2] = 1.0
    return R


def small_transform(six_si) -> Rigid:
    """Exact transform of a six-component error (dx, dy, dz in mm; a, b, c in rad):
    Trans(d) @ Rz(c) Ry(b) Rx(a). Shape of ``six_si``: (..., 6)."""
    six = np.asarray(six_si, dtype=float)
    return Rigid(rot_xyz(six[..., 3], six[..., 4], six[..., 5]), six[..., :3].copy())


def adjoint_apply(G: Rigid, xi: np.ndarray) -> np.ndarray:
    """Ad(G) applied to twists ``xi`` = (v, w) (..., 6): the first-order effect of a
    small error inserted after G, seen in G's base frame: w' = R w, v' = R v + p x R w."""
    v = xi[..., :3]
    w = xi[..., 3:]
    Rw = np.einsum("...ij,...j->...i", G.R, w)
    Rv = np.einsum("...ij,...j->...i", G.R, v)
    return np.concatenate([Rv + np.cross(G.p, Rw), Rw], axis=-1)
