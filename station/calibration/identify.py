"""Identification of the station's error model from camera sightings of a certified
artefact: the parameterisation, the prediction of every observation, its Jacobian, and
weighted least squares with the certificate as prior (docs/calibration.md).

Parameters (report units: um for translations, arcsec for rotations):

* the static errors of the model, every block of ``StationModel.parameter_blocks``
  that is not a motion: installation errors of P1, N, P2, J, M (``dx_N`` ...) and the
  C axis's alignment (``X0C`` ... ``C0C``); M's installation is where the *artefact*
  sits on the table, so it is a nuisance of this run, not a property of the station;
* each of the 12 error-motion curves (EXZ ... ECZ over z, EXC ... ECC over C) as its
  values at a few nodes (default: z every 50 mm over the travel; C every 45 deg), zero
  at the first node (z = 0, C = 0) by convention: an error motion's constant part is
  indistinguishable from a static error, so it is kept there (a rotary axis's in its
  alignment, the slide's in the installation error of N, the body it carries), as
  ISO 230-1 states error motions relative to a reference position; with
  the station's own interpolation (``ErrorCurve``: linear, held flat outside the
  travel, periodic over the turn). The parameterised model *is* a ``StationModel``
  whose curves are tables at the nodes: the prediction runs the model's own
  ``errors`` and ``part_coordinates`` (one physics);
* the targets' true positions as nuisance parameters: axial and tangential (arc
  length at the wall) deviations from the certificate, um, with prior N(0, (U/2)^2).

Observations at a pose (commanded z, C):

* the grating's reading minus the command: EZZ(z), um (the grating reads the carriage);
* per target in the camera's field, what the vision stage reports: the target's offset
  from the image centre (the detection point) on the unrolled wall, tangential
  (arc length) and axial, um: ``r (phi_t - angle_dp)`` and ``a_t - axial_dp``, the
  camera twin's reading (``sim.world.World.holes_near``).

The Jacobian is analytic: ``StationModel.sensitivity`` (first order at zero error,
closed form) through the chain rule of ``part_coordinates`` and the curves' node basis.
Gauss-Newton uses it with residuals of the exact model; the second-order terms it
leaves out are below 1e-3 of the first order (error angles < 1e-3 rad), so two to
four iterations converge. Being structural (at zero error), its null space is exact
to rounding, which the observability report (``observability.py``) relies on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from station.calibration.artefact import ArtefactCertificate
from station.effects import ErrorCurve
from station.kinematics.model import StationModel
from station.kinematics.rigid import RAD_PER_ARCSEC, adjoint_apply
from station.kinematics.parameters import COMPONENT_UNITS, TO_SI, ErrorMotions, SixDof, motion_names

#: the vision stage's standard uncertainty of a hole centre on the wall, um
#: (docs/vision.md: 0.05-0.15 px on ~7 um pixels, and the lens calibration's residual)
SIGMA_VISION_UM = 1.0
#: the grating's reading: its 0.05 um resolution (sim/encoder/twin.py) plus the
#: repeatability of the read head; a conservative 0.05 um standard uncertainty
SIGMA_GRATING_UM = 0.05
#: default nodes of the error-motion curves: z every 50 mm over the travel, C every 45 deg
Z_NODES_MM = (0.0, 50.0, 100.0, 150.0)
C_NODES_DEG = tuple(float(a) for a in range(0, 360, 45))
#: relative tolerance on singular values for the rank: the analytic Jacobian is exact
#: to rounding (~1e-16 of its largest entry, times sqrt of ~1000 rows), so a combination
#: below 1e-9 of the best-determined one is structurally invisible, not merely weak
RANK_RTOL = 1e-9


# ====================================================================== parameters
@dataclass(frozen=True)
class Parameterisation:
    """The station model as a vector: static errors, then curve node values."""

    base: StationModel
    z_nodes_mm: tuple[float, ...] = Z_NODES_MM
    c_nodes_deg: tuple[float, ...] = C_NODES_DEG
    names: tuple[str, ...] = field(init=False)
    units: tuple[str, ...] = field(init=False)
    #: per name: ("static", body, component) or ("motion", body, component, node index)
    slots: tuple[tuple, ...] = field(init=False)

    def __post_init__(self):
        names, units, slots = [], [], []
        for body, is_motion, block in self.base.parameter_blocks():
            if is_motion:
                continue
            for i, n in enumerate(block):
                names.append(n)
                units.append(COMPONENT_UNITS[i])
                slots.append(("static", body, i))
        for body in self.base.joint_bodies:
            nodes, unit = self.nodes_of(body)
            for i, n in enumerate(motion_names(body)):
                for k, x in enumerate(nodes):
                    if k == 0:  # the reference position: zero by convention (see module doc)
                        continue
                    names.append(f"{n}@{x:g}{unit}")
                    units.append(COMPONENT_UNITS[i])
                    slots.append(("motion", body, i, k))
        object.__setattr__(self, "names", tuple(names))
        object.__setattr__(self, "units", tuple(units))
        object.__setattr__(self, "slots", tuple(slots))

    @property
    def size(self) -> int:
        return len(self.names)

    def kind_of(self, body: str) -> str:
        return "rotary" if self.base.topology.by_name(body).joint == "revolute_z" else "linear"

    def nodes_of(self, body: str) -> tuple[tuple[float, ...], str]:
        if self.kind_of(body) == "rotary":
            return self.c_nodes_deg, "deg"
        return self.z_nodes_mm, "mm"

    @property
    def z_body(self) -> str:
        return next(b.name for b in self.base.topology.bodies if b.joint == "prismatic_z")

    @property
    def c_body(self) -> str:
        return next(b.name for b in self.base.topology.bodies if b.joint == "revolute_z")

    def basis(self, body: str, position) -> np.ndarray:
        """(N, k): each node's weight at the positions, by the curves' own interpolation."""
        nodes, _ = self.nodes_of(body)
        kind = self.kind_of(body)
        pos = np.atleast_1d(np.asarray(position, dtype=float))
        return np.stack([ErrorCurve.table(nodes, np.eye(len(nodes))[k], kind).baseline(pos)
                         for k in range(len(nodes))], axis=-1)

    def values_from_model(self, model: StationModel) -> np.ndarray:
        """The parameter vector of any model: static errors as they are, each curve
        sampled at the nodes (direction-free: a direction effect contributes its mean)."""
        static = {b: model.static_of(b).values().copy() for b, is_motion, _ in self.base.parameter_blocks()
                  if not is_motion}
        curves: dict[str, np.ndarray] = {}
        for body in self.base.joint_bodies:
            nodes, _ = self.nodes_of(body)
            table = np.array([cv.evaluate(np.asarray(nodes, dtype=float)) for cv in model.motions_of(body).curves()])
            const = table[:, 0].copy()
            curves[body] = table - const[:, None]
            target, xi_si = self._constant_moves_to(body, const * TO_SI)
            static[target] = static[target] + xi_si / TO_SI
        out = np.empty(self.size)
        for j, s in enumerate(self.slots):
            out[j] = static[s[1]][s[2]] if s[0] == "static" else curves[s[1]][s[2], s[3]]
        return out

    def _constant_moves_to(self, body: str, xi_si: np.ndarray) -> tuple[str, np.ndarray]:
        """Where a constant error motion of a joint goes in the gauge (to first order):
        a rotary axis's (``Err_C @ Rz``) into its own alignment, the static error just
        before it; a linear axis's (``Trans(z) @ Err_Z``) into the installation error of
        the next body of the chain, moved past that body's ideal offset S by the
        adjoint: Err_Z S = S (Ad(S^-1) Err_Z)."""
        b = self.base.topology.by_name(body)
        if b.joint == "revolute_z":
            return body, xi_si
        nxt = next(x for x in self.base.topology.bodies if x.parent == b.index)
        S = self.base.ideal_static(nxt.name)
        return nxt.name, adjoint_apply(S.inverse(), xi_si)

    def to_model(self, x) -> StationModel:
        """The ``StationModel`` of a parameter vector: its curves are tables at the nodes."""
        x = np.asarray(x, dtype=float)
        static: dict[str, np.ndarray] = {}
        motion: dict[str, np.ndarray] = {}
        for j, s in enumerate(self.slots):
            if s[0] == "static":
                static.setdefault(s[1], np.zeros(6))[s[2]] = x[j]
            else:
                nodes, _ = self.nodes_of(s[1])
                motion.setdefault(s[1], np.zeros((6, len(nodes))))[s[2], s[3]] = x[j]
        for body in self.base.joint_bodies:  # a curve with no parameters (one node) is zero
            motion.setdefault(body, np.zeros((6, len(self.nodes_of(body)[0]))))
        motions = {}
        for body, table in motion.items():
            nodes, _ = self.nodes_of(body)
            kind = self.kind_of(body)
            motions[body] = ErrorMotions(*(ErrorCurve.table(nodes, table[i], kind) for i in range(6)))
        return replace(self.base, static_errors={b: SixDof.from_values(v) for b, v in static.items()}, motions=motions)


# ====================================================================== observations
@dataclass(frozen=True)
class Sightings:
    """A plan's poses and which target each sighting sees (no values: the design)."""

    z_mm: np.ndarray  # (M,) commanded
    c_deg: np.ndarray  # (M,) commanded
    pose: np.ndarray  # (K,) index into the poses
    target: np.ndarray  # (K,) index into the certificate's targets


@dataclass(frozen=True)
class Observations:
    """What one calibration run measured: grating minus command per pose, and the
    vision stage's tangential and axial offset of each sighted target, um."""

    design: Sightings
    grating_um: np.ndarray  # (M,)
    tangential_um: np.ndarray  # (K,)
    axial_um: np.ndarray  # (K,)

    def vector(self) -> np.ndarray:
        return np.concatenate([self.grating_um, self.tangential_um, self.axial_um])


def _wrap_deg(a):
    return (np.asarray(a) + 180.0) % 360.0 - 180.0


def sightings_for_poses(cert: ArtefactCertificate, z_mm, c_deg, half_field_mm=(1.0, 1.0)) -> Sightings:
    """Which targets each pose sees: those whose nominal offset from the ideal detection
    point lies within the camera's half field (tangential, axial; mm on the wall)."""
    z = np.atleast_1d(np.asarray(z_mm, dtype=float))
    c = np.atleast_1d(np.asarray(c_deg, dtype=float))
    r = cert.radius_mm
    a_t = np.array([t.nominal_position_mm for t in cert.targets])
    phi_t = np.array([t.nominal_angle_deg for t in cert.targets])
    du = np.radians(_wrap_deg(phi_t[None, :] - c[:, None])) * r
    dv = a_t[None, :] - z[:, None]
    pi, ti = np.nonzero((np.abs(du) <= half_field_mm[0]) & (np.abs(dv) <= half_field_mm[1]))
    return Sightings(z, c, pi, ti)


def predict(par: Parameterisation, x_model, design: Sightings, axial_mm, angle_deg, radius_mm: float) -> np.ndarray:
    """The observation vector (grating, tangential, axial; um) the model ``x_model``
    predicts for targets truly at (``axial_mm``, ``angle_deg``) on a bore of ``radius_mm``.
    Exact: the model's own ``errors`` and ``part_coordinates``."""
    model = par.to_model(x_model)
    return predict_with_model(model, par.z_body, design, axial_mm, angle_deg, radius_mm)


def predict_with_model(model: StationModel, z_body: str, design: Sightings, axial_mm, angle_deg, radius_mm: float):
    """As :func:`predict`, for any ``StationModel`` (a world's, with effects beyond the
    node tables)."""
    e = model.errors(design.z_mm, design.c_deg)
    ax_dp, ang_dp, _ = model.part_coordinates(e.actual_point_mm)
    grating_um = model.motions_of(z_body).z.evaluate(design.z_mm)
    a_t = np.asarray(axial_mm, dtype=float)[design.target]
    phi_t = np.asarray(angle_deg, dtype=float)[design.target]
    tangential_um = radius_mm * np.radians(_wrap_deg(phi_t - ang_dp[design.pose])) * 1e3
    axial_um = (a_t - ax_dp[design.pose]) * 1e3
    return np.concatenate([grating_um, tangential_um, axial_um])


def jacobian(par: Parameterisation, design: Sightings, n_targets: int, radius_mm: float) -> np.ndarray:
    """d(observations)/d(parameters), analytic, first order at zero error.

    Rows: grating (M), tangential (K), axial (K). Columns: the model parameters
    (``par.names``, per um or arcsec), then each target's axial deviation (um), then
    each target's tangential deviation (um)."""
    z, c = design.z_mm, design.c_deg
    M, K = z.size, design.pose.size
    eff = pose_effects(par, z, c, radius_mm)
    A_ax, A_an, G = eff["axial_um"], eff["tangential_um"], eff["grating_um"]
    P = par.size
    T = n_targets
    J = np.zeros((M + 2 * K, P + 2 * T))
    J[:M, :P] = G
    rows_t = M + np.arange(K)
    rows_a = M + K + np.arange(K)
    J[rows_t, :P] = -A_an[design.pose]
    J[rows_a, :P] = -A_ax[design.pose]
    J[rows_a, P + design.target] = 1.0
    J[rows_t, P + T + design.target] = 1.0
    return J


def pose_effects(par: Parameterisation, z_mm, c_deg, radius_mm: float) -> dict[str, np.ndarray]:
    """First-order effect of each parameter (per um or arcsec) at poses, (M, P) each:
    the detection point's axial, tangential (arc at ``radius_mm``) and radial
    displacement in the part (um), the grating's reading (um), and the rotation of the
    endoscope relative to the part about x, y, z (arcsec). From the model's closed-form
    ``sensitivity`` and the chain rule of ``part_coordinates``."""
    base = par.base.without_errors()
    z = np.atleast_1d(np.asarray(z_mm, dtype=float))
    c = np.atleast_1d(np.asarray(c_deg, dtype=float))
    S = base.sensitivity(z, c)  # (M, 9, P_full), per mm or rad
    D = np.asarray(base.endoscope_offset_mm) - np.asarray(base.table_offset_mm)
    q = base.ideal_point_mm(z, c)[:, :2] + D[:2]
    rq = np.sqrt((q ** 2).sum(axis=1))[:, None]
    d_axial_mm = S[:, 8, :]
    d_angle_rad = -(q[:, 0, None] * S[:, 7, :] - q[:, 1, None] * S[:, 6, :]) / rq ** 2
    d_radial_mm = (q[:, 0, None] * S[:, 6, :] + q[:, 1, None] * S[:, 7, :]) / rq
    block_col = {}
    col = 0
    for body, is_motion, _ in base.parameter_blocks():
        block_col[(body, is_motion)] = col
        col += 6
    bases = {b: par.basis(b, z if par.kind_of(b) == "linear" else c) for b in base.joint_bodies}
    M, P = z.size, par.size
    out = {k: np.zeros((M, P)) for k in ("axial_um", "tangential_um", "radial_um", "grating_um")}
    out["rotation_arcsec"] = np.zeros((M, 3, P))
    for j, s in enumerate(par.slots):
        if s[0] == "static":
            k = block_col[(s[1], False)] + s[2]
            w = np.full(M, TO_SI[s[2]])
        else:
            k = block_col[(s[1], True)] + s[2]
            w = TO_SI[s[2]] * bases[s[1]][:, s[3]]
            if s[1] == par.z_body and s[2] == 2:  # EZZ: the grating reads the carriage
                out["grating_um"][:, j] = bases[s[1]][:, s[3]]
        out["axial_um"][:, j] = d_axial_mm[:, k] * w * 1e3
        out["tangential_um"][:, j] = radius_mm * d_angle_rad[:, k] * w * 1e3
        out["radial_um"][:, j] = d_radial_mm[:, k] * w * 1e3
        out["rotation_arcsec"][:, :, j] = S[:, 3:6, k] * w[:, None] / RAD_PER_ARCSEC
    return out


# ====================================================================== least squares
@dataclass(frozen=True)
class Identification:
    """The result of one identification, parameters in report units."""

    names: tuple[str, ...]  # model parameters, then target nuisances
    units: tuple[str, ...]
    n_model: int
    value: np.ndarray
    u: np.ndarray  # standard uncertainty (nan where not observable)
    observable: np.ndarray  # bool
    null_fraction: np.ndarray  # ||P_null e_i||^2, 0 for an estimable parameter
    covariance: np.ndarray
    rank: int
    condition: float
    singular_values: np.ndarray
    null_space: np.ndarray  # (n_parameters, n_null), orthonormal
    residual_rms_um: float
    chi2_per_dof: float
    iterations: int

    def correlation(self) -> np.ndarray:
        """Correlation matrix of the parameters (nan rows/columns for unobservable ones)."""
        u = np.where(self.observable, self.u, np.nan)
        return self.covariance / np.outer(u, u)

    def model_vector(self) -> np.ndarray:
        return self.value[: self.n_model]

    def parameters(self, truth: np.ndarray | None = None) -> list[dict]:
        """The output contract's ``parameters`` list (model parameters only)."""
        out = []
        for i in range(self.n_model):
            d = {"name": self.names[i], "unit": self.units[i], "value": float(self.value[i]),
                 "u": float(self.u[i]) if self.observable[i] else None, "observable": bool(self.observable[i])}
            if truth is not None:
                d["truth"] = float(truth[i])
            out.append(d)
        return out


def weighted_system(J: np.ndarray, n_obs_grating: int, cert: ArtefactCertificate, n_model: int,
                    sigma_vision_um: float = SIGMA_VISION_UM, sigma_grating_um: float = SIGMA_GRATING_UM):
    """The whitened design: observation rows divided by their sigma, then one prior row
    per target nuisance (1/u). Returns (A, row sigmas of the observations, prior sigmas)."""
    sig = np.full(J.shape[0], sigma_vision_um)
    sig[:n_obs_grating] = sigma_grating_um
    u_prior = np.concatenate([cert.axial_u_um(), cert.tangential_u_um()])
    prior = np.zeros((u_prior.size, J.shape[1]))
    prior[np.arange(u_prior.size), n_model + np.arange(u_prior.size)] = 1.0 / u_prior
    return np.vstack([J / sig[:, None], prior]), sig, u_prior


def identify(par: Parameterisation, prior_model: StationModel, cert: ArtefactCertificate, obs: Observations, *,
             sigma_vision_um: float = SIGMA_VISION_UM, sigma_grating_um: float = SIGMA_GRATING_UM,
             rtol: float = RANK_RTOL, max_iterations: int = 6) -> Identification:
    """Weighted least squares of the model parameters and target nuisances, starting from
    the station's present model (``prior_model``) and the certificate.

    The certificate is a prior: each target's deviation from its certified position has
    prior N(0, (U/2)^2). The model parameters have no prior: a combination the data do
    not see (the null space of the whitened Jacobian, rank by ``rtol``) is left where the
    present model has it (minimum-norm Gauss-Newton steps), and is reported unobservable
    rather than guessed."""
    design = obs.design
    T = len(cert.targets)
    P = par.size
    r = cert.radius_mm
    a0 = cert.certified_axial_mm()
    phi0 = cert.certified_angle_deg()
    J = jacobian(par, design, T, r)
    A, sig, u_prior = weighted_system(J, design.z_mm.size, cert, P, sigma_vision_um, sigma_grating_um)
    U_, s, Vt = np.linalg.svd(A, full_matrices=True)
    tol = rtol * s[0]
    rank = int((s > tol).sum())
    Ur, sr, Vr = U_[:, :rank], s[:rank], Vt[:rank].T
    V0 = Vt[rank:].T
    y = obs.vector()

    def unpack(x):
        ax = a0 + x[P:P + T] * 1e-3
        ang = phi0 + np.degrees(x[P + T:] * 1e-3 / r)
        return ax, ang

    x = np.concatenate([par.values_from_model(prior_model), np.zeros(2 * T)])
    it = 0
    for it in range(1, max_iterations + 1):
        ax, ang = unpack(x)
        res = np.concatenate([(y - predict(par, x[:P], design, ax, ang, r)) / sig, -x[P:] / u_prior])
        dx = Vr @ ((Ur.T @ res) / sr)
        x = x + dx
        if np.max(np.abs(dx)) < 1e-6:  # um / arcsec: far below any u
            break
    ax, ang = unpack(x)
    res_obs = y - predict(par, x[:P], design, ax, ang, r)
    res_w = np.concatenate([res_obs / sig, -x[P:] / u_prior])
    dof = max(A.shape[0] - rank, 1)
    cov = (Vr / sr ** 2) @ Vr.T
    null_fraction = (V0 ** 2).sum(axis=1)
    # observable: the unit vector of the parameter is orthogonal to the null space (an
    # estimable function); 1e-6 of its squared norm allows for rounding, a combination
    # that touches it genuinely leaves 1e-3 or more
    observable = null_fraction < 1e-6
    u = np.where(observable, np.sqrt(np.diag(cov)), np.nan)
    n_vision = design.pose.size
    vis = res_obs[design.z_mm.size:]
    names = par.names + tuple(f"axial_{t}" for t in cert.ids) + tuple(f"tangential_{t}" for t in cert.ids)
    units = par.units + ("um",) * (2 * T)
    return Identification(
        names=names, units=units, n_model=P, value=x, u=u, observable=observable, null_fraction=null_fraction,
        covariance=cov, rank=rank, condition=float(s[0] / sr[-1]), singular_values=s, null_space=V0,
        residual_rms_um=float(np.sqrt(np.mean(vis ** 2))) if n_vision else math.nan,
        chi2_per_dof=float((res_w ** 2).sum() / dof), iterations=it)
