"""What an artefact and a plan can see of the station's error model.

The whitened design A (observation rows / sigma, then the certificate's prior rows; see
``identify.weighted_system``) has singular values s_1 >= s_2 >= ...; its **rank** counts
those above ``rtol * s_1`` (``RANK_RTOL``); the **condition** is s_1 / s_rank, the
spread of the part that is seen. The right singular vectors of the rest span the **null
space**: parameter changes that leave every observation unchanged (to first order).

A parameter is **observable** when its unit vector is orthogonal to the null space
(``||V0^T e_i||^2 < 1e-6``): it is then an estimable function, its least-squares value
does not depend on how the null space is fixed, and its variance is the pseudo-inverse's
(no null direction contributes). Otherwise its value is set by the gauge (the present
model), not by the data, and it is reported unobservable.

Each null direction is **named**: the null space is brought to reduced row-echelon form
(each combination sparse), grouped where the same combination repeats at every node of
a curve, written in ISO 230-1 names, and described by what it does to the detection
point (computed, not listed by hand): a radial move only (the camera sees axial and
tangential), a translation and a rotation cancelling at the wall (with the arm),
the same rigid error stated twice in the chain, or one indistinguishable from the
artefact's seat on the table (installation of M). **Suggestions** test candidate poses
and artefact features (extra target rings or angles) for the rank they add and name
those that make a combination observable.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from station.calibration.artefact import ArtefactCertificate, CertifiedTarget
from station.calibration.identify import (
    RANK_RTOL,
    SIGMA_GRATING_UM,
    SIGMA_VISION_UM,
    Parameterisation,
    Sightings,
    jacobian,
    pose_effects,
    sightings_for_poses,
    weighted_system,
)
from station.kinematics.parameters import motion_names
from station.kinematics.rigid import RAD_PER_ARCSEC

#: a term of a combination smaller than this share of its largest is rounding
TERM_TOL = 1e-6
#: an effect of a unit null direction below this (um or arcsec) is none at all
EFFECT_TOL = 1e-6


@dataclass
class Combination:
    name: str
    description: str
    dimension: int  # how many null directions this named family holds
    terms: list[tuple[str, float]]  # of the first member, normalised to max |coef| = 1
    directions: np.ndarray  # (n_model, dimension): the members, unit norm
    suggestions: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        return {"name": self.name, "description": self.description, "dimension": self.dimension,
                "suggestions": list(self.suggestions)}


@dataclass
class ObservabilityReport:
    rank: int
    n_parameters: int
    n_model: int
    condition: float
    rtol: float
    singular_values: np.ndarray
    observable: np.ndarray  # (n_model,) bool
    unobservable: list[Combination]

    def to_dict(self) -> dict:
        return {"rank": self.rank, "n_parameters": self.n_parameters, "condition": self.condition,
                "rank_rtol": self.rtol, "unobservable": [c.to_dict() for c in self.unobservable]}


def whitened(par: Parameterisation, cert: ArtefactCertificate, design: Sightings,
             sigma_vision_um: float = SIGMA_VISION_UM, sigma_grating_um: float = SIGMA_GRATING_UM,
             free_carriage_off_nodes: bool = False) -> np.ndarray:
    J = jacobian(par, design, len(cert.targets), cert.radius_mm, free_carriage_off_nodes)
    return weighted_system(J, design.z_mm.size, cert, par.size, sigma_vision_um, sigma_grating_um)[0]


def rank_of(A: np.ndarray, rtol: float = RANK_RTOL) -> tuple[int, np.ndarray, np.ndarray]:
    _, s, Vt = np.linalg.svd(A, full_matrices=True)
    r = int((s > rtol * s[0]).sum())
    return r, s, Vt[r:].T


def _rref(B: np.ndarray) -> np.ndarray:
    """Reduced row-echelon form of the rows of B (partial pivoting): sparse combinations."""
    B = B.copy()
    rows, cols = B.shape
    r = 0
    for c in range(cols):
        if r == rows:
            break
        p = r + int(np.argmax(np.abs(B[r:, c])))
        if abs(B[p, c]) < 1e-9:
            continue
        B[[r, p]] = B[[p, r]]
        B[r] /= B[r, c]
        others = np.arange(rows) != r
        B[others] -= np.outer(B[others, c], B[r])
        r += 1
    B[np.abs(B) < TERM_TOL] = 0.0
    return B[:r]


_NODE = re.compile(r"@(-?[0-9.]+(?:mm|deg))$")


def _describe(par: Parameterisation, w: np.ndarray, z_grid, c_grid, radius_mm: float, free: bool = False) -> str:
    names = [par.names[i] for i in np.nonzero(w)[0]]
    ezz = motion_names(par.z_body)[2] + "@"
    if free and names and all(n.startswith(ezz) for n in names):
        return ("EZZ at a node seen only from poses off the z nodes, where the grating reads the carriage there and "
                "not at the node (a lead error, finer structure between): a view at the node (centred, or offset "
                "tangentially) sees it")
    eff = pose_effects(par, z_grid, c_grid, radius_mm)
    w = w / np.linalg.norm(w)
    radial = np.abs(eff["radial_um"] @ w).max()
    rot = np.abs(np.einsum("mkp,p->mk", eff["rotation_arcsec"], w)).max()
    names = [par.names[i] for i in np.nonzero(w)[0]]
    seat = any(n.endswith("_M") for n in names)
    units = [par.units[i] for i in np.nonzero(w)[0]]
    if radial > EFFECT_TOL and rot <= EFFECT_TOL:
        text = "moves the detection point only radially (along the endoscope's line of sight: focus), which the side-view camera does not measure"
    elif radial > EFFECT_TOL:
        text = ("moves the detection point radially and turns the endoscope against the part; neither reaches the "
                "camera's axial and tangential reading")
    elif rot > EFFECT_TOL and all(u == "arcsec" for u in units):
        text = ("turns the endoscope about its own detection point (view direction or image rotation): "
                "no target at the image centre moves")
    elif rot > EFFECT_TOL:
        trans = [abs(w[i]) for i in np.nonzero(w)[0] if par.units[i] == "um"]
        angs = [abs(w[i]) for i in np.nonzero(w)[0] if par.units[i] == "arcsec"]
        arm = ""
        if trans and angs:
            arm = f" (arm {max(trans) / (max(angs) * RAD_PER_ARCSEC * 1e3):.1f} mm)"
        text = ("a translation and a rotation that cancel at the detection point" + arm +
                ": separable only by targets at another distance from the rotation")
    else:
        text = "the same rigid error stated twice in the chain: only their sum acts on the detection point"
    if seat:
        text += "; indistinguishable from the artefact's seat on the table (installation of M)"
    return text


def analyse(par: Parameterisation, cert: ArtefactCertificate, design: Sightings, *,
            candidate_poses: Sightings | None = None, candidate_features: list[tuple[str, list[CertifiedTarget]]] | None = None,
            sigma_vision_um: float = SIGMA_VISION_UM, sigma_grating_um: float = SIGMA_GRATING_UM,
            rtol: float = RANK_RTOL, half_field_mm=(1.0, 1.0),
            free_carriage_off_nodes: bool = False) -> ObservabilityReport:
    """The observability report of ``design`` on ``cert``; with candidates, suggestions.
    ``free_carriage_off_nodes``: as the noise model identifies a run (EZZ's nodes seen
    only from poses at the z nodes; ``identify.jacobian``)."""
    P = par.size
    free = free_carriage_off_nodes
    A = whitened(par, cert, design, sigma_vision_um, sigma_grating_um, free)
    rank, s, V0 = rank_of(A, rtol)
    null_fraction = (V0[:P] ** 2).sum(axis=1)
    observable = null_fraction < 1e-6
    rows = _rref(V0[:P].T) if V0.shape[1] else np.zeros((0, P))
    z_grid = np.repeat(np.linspace(*par.base.z_travel_mm, 7), 8)
    c_grid = np.tile(np.arange(0.0, 360.0, 45.0), 7)
    groups: dict[tuple, list[np.ndarray]] = {}
    labels: dict[tuple, tuple[str, str]] = {}
    for w in rows:
        nz = np.nonzero(w)[0]
        coef = w[nz] / np.abs(w[nz]).max()
        node_labels = {m.group(1) for n in (par.names[i] for i in nz) if (m := _NODE.search(n))}
        same_node = len(node_labels) == 1 and all(_NODE.search(par.names[i]) for i in nz)
        stripped = tuple(_NODE.sub("", par.names[i]) if same_node else par.names[i] for i in nz)
        key = (stripped, tuple(np.round(coef, 4)), same_node if same_node else tuple(par.names[i] for i in nz))
        groups.setdefault(key, []).append(w / np.linalg.norm(w))
        if key not in labels:
            labels[key] = (_describe(par, w, z_grid, c_grid, cert.radius_mm, free), "")
        if same_node:
            labels[key] = (labels[key][0], labels[key][1] + ("," if labels[key][1] else "") + node_labels.pop())
    combos = []
    for key, ws in groups.items():
        stripped, coefs, _ = key
        desc, nodes = labels[key]
        terms = " ".join(f"{c:+.4g}*{n}" for c, n in zip(coefs, stripped)).lstrip("+")
        name = terms + (f" at {nodes}" if nodes else "")
        first = ws[0]
        nz = np.nonzero(first)[0]
        combos.append(Combination(name, desc, len(ws),
                                  [(par.names[i], float(first[i] / np.abs(first[nz]).max())) for i in nz],
                                  np.stack(ws, axis=1)))
    if candidate_poses is not None or candidate_features:
        _suggest(par, cert, design, combos, rank, candidate_poses, candidate_features or [],
                 sigma_vision_um, sigma_grating_um, rtol, half_field_mm, s[0], free)
    cond = float(s[0] / s[rank - 1]) if rank else float("inf")
    return ObservabilityReport(rank, A.shape[1], P, cond, rtol, s, observable, combos)


def _suggest(par, cert, design, combos, rank, cand: Sightings | None, features, sv, sg, rtol, half_field_mm, s0,
             free: bool = False):
    """For each candidate pose (alone) and feature (new targets, sighted at their
    centred poses): the rank it adds; for each combination, the candidates that see it
    (their whitened rows move the combination by more than ``rtol * s0``)."""
    T = len(cert.targets)
    trials: list[tuple[str, Parameterisation, ArtefactCertificate, Sightings]] = []
    if cand is not None:
        for m in range(cand.z_mm.size):
            sel = cand.pose == m
            if not sel.any():
                continue
            d = Sightings(np.r_[design.z_mm, cand.z_mm[m]], np.r_[design.c_deg, cand.c_deg[m]],
                          np.r_[design.pose, np.full(sel.sum(), design.z_mm.size)], np.r_[design.target, cand.target[sel]])
            trials.append((f"pose z = {cand.z_mm[m]:.2f} mm, C = {cand.c_deg[m]:.2f} deg", par, cert, d))
    for label, targets in features:
        ext = cert.model_copy(update={"targets": list(cert.targets) + list(targets)})
        zc = np.array([t.nominal_position_mm for t in targets])
        cc = np.array([t.nominal_angle_deg for t in targets])
        extra = sightings_for_poses(ext, zc, cc, half_field_mm)
        d = Sightings(np.r_[design.z_mm, zc], np.r_[design.c_deg, cc],
                      np.r_[design.pose, extra.pose + design.z_mm.size], np.r_[design.target, extra.target])
        trials.append((label, par, ext, d))
    for label, p, c, d in trials:
        A = whitened(p, c, d, sv, sg, free)
        r, _, _ = rank_of(A, rtol)
        gain = r - rank - 2 * (len(c.targets) - T)  # new targets bring their own (prior) rank
        if gain <= 0:
            continue
        # the trial's rows restricted to the model columns, against each combination
        B = A[:, :par.size]
        for combo in combos:
            seen = np.linalg.norm(B @ combo.directions, axis=0).max()
            if seen > np.sqrt(rtol) * s0 and len(combo.suggestions) < 3:
                combo.suggestions.append(f"{label} (rank +{gain})")
