"""Choosing the poses of a calibration run: greedy D-optimal design.

Candidates are views of each target: centred in the image, and offset by a fraction of
the field axially and tangentially (the same target seen from several (z, C) separates
the error motion at those poses from the target's own position). From the whitened rows
of every candidate (``identify.jacobian`` / sigma), the planner starts from the
certificate's prior information plus a small ridge (so the determinant exists while
combinations are unseen) and adds, one at a time, the pose whose rows increase
log det of the information matrix most: by the matrix determinant lemma,
log det(I_k + R A^-1 R^T) for its rows R, with A^-1 updated by Woodbury. A pose that
brings a new combination into view multiplies the determinant by ~1/ridge, so rank
comes first and then precision. N poses cost N passes over the candidates.
"""

from __future__ import annotations

import numpy as np

from station.calibration.artefact import ArtefactCertificate
from station.calibration.identify import (
    SIGMA_GRATING_UM,
    SIGMA_VISION_UM,
    Parameterisation,
    Sightings,
    jacobian,
    sightings_for_poses,
)

#: ridge on the model parameters, per (um or arcsec)^-2: a prior sigma of 1000 um or
#: arcsec, far wider than any error motion, only there to keep the determinant finite
RIDGE = 1e-6


def candidate_poses(cert: ArtefactCertificate, offsets_mm=((0.0, 0.0), (0.0, 0.7), (0.0, -0.7), (0.7, 0.0), (-0.7, 0.0)),
                    half_field_mm=(1.0, 1.0)) -> Sightings:
    """Views of every target at (tangential, axial) image offsets (mm on the wall)."""
    z, c = [], []
    for t in cert.targets:
        for du, dv in offsets_mm:
            z.append(t.nominal_position_mm - dv)
            c.append((t.nominal_angle_deg - np.degrees(du / cert.radius_mm)) % 360.0)
    return sightings_for_poses(cert, z, c, half_field_mm)


def subset(cand: Sightings, chosen) -> Sightings:
    chosen = np.asarray(chosen, dtype=int)
    remap = -np.ones(cand.z_mm.size, dtype=int)
    remap[chosen] = np.arange(chosen.size)
    keep = remap[cand.pose] >= 0
    return Sightings(cand.z_mm[chosen], cand.c_deg[chosen], remap[cand.pose[keep]], cand.target[keep])


def plan_poses(par: Parameterisation, cert: ArtefactCertificate, cand: Sightings, n_poses: int, *,
               sigma_vision_um: float = SIGMA_VISION_UM, sigma_grating_um: float = SIGMA_GRATING_UM,
               free_carriage_off_nodes: bool = False) -> np.ndarray:
    """Indices of ``n_poses`` candidates chosen greedily for D-optimality
    (``free_carriage_off_nodes``: as the noise model identifies a run)."""
    T = len(cert.targets)
    P = par.size
    J = jacobian(par, cand, T, cert.radius_mm, free_carriage_off_nodes)
    M, K = cand.z_mm.size, cand.pose.size
    # whitened rows of each candidate pose: its grating row and its sightings' rows
    rows_of = []
    for m in range(M):
        k = np.nonzero(cand.pose == m)[0]
        idx = np.r_[m, M + k, M + K + k]
        sig = np.r_[sigma_grating_um, np.full(2 * k.size, sigma_vision_um)]
        rows_of.append(J[idx] / sig[:, None])
    prior = np.r_[np.full(P, RIDGE), 1.0 / np.r_[cert.axial_u_um(), cert.tangential_u_um()] ** 2]
    Ainv = np.diag(1.0 / prior)
    chosen: list[int] = []
    free = np.ones(M, dtype=bool)
    for _ in range(min(n_poses, M)):
        best, best_gain = -1, -np.inf
        for m in np.nonzero(free)[0]:
            R = rows_of[m]
            S = np.eye(R.shape[0]) + R @ Ainv @ R.T
            gain = np.linalg.slogdet(S)[1]
            if gain > best_gain:
                best, best_gain = m, gain
        R = rows_of[best]
        S = np.eye(R.shape[0]) + R @ Ainv @ R.T
        AR = Ainv @ R.T
        Ainv = Ainv - AR @ np.linalg.solve(S, AR.T)
        chosen.append(best)
        free[best] = False
    return np.array(chosen, dtype=int)
