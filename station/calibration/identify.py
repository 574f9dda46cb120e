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

How the observations err is the run's noise model (:class:`NoiseModel`, docs/calibration.md
stage 4): each approach's carriage error shared by a pose's grating row and its axial
sightings, the grating reference's error common to every grating row, the camera's
scale at the view offsets, the vision stage's own u per sighting, and variance factors
estimated from the residuals. A run's parameterisation is *shaped* by the station's
model (``Parameterisation.shaped``): between the nodes each curve keeps the model's own
shape, so only the node values' changes are interpolated, as the proposal applies them.

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
    #: True: a curve of the parameterised model is the base model's own curve (its
    #: finer table and its effects: eccentricity, periodic, backlash) plus the node
    #: values' changes times their hat functions, as a calibration proposal applies
    #: them (``proposal.apply_node_change``); False: a table at the nodes alone
    shaped: bool = False
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
        """The ``StationModel`` of a parameter vector: its curves are tables at the nodes
        (``shaped``: the base model's curves plus the node changes' hats)."""
        if self.shaped:
            return self._shaped_model(x)
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

    def _shaped_model(self, x) -> StationModel:
        """The base model with each node's change from the base's own value as its hat
        (1 at the node, 0 at its neighbours: the interpolation of ``basis``) added to
        the curve, and the static errors less the curves' constants that
        ``values_from_model`` moved into them: ``to_model(values_from_model(base))`` is
        the base itself, its curves between the nodes kept."""
        x = np.asarray(x, dtype=float)
        x0 = self._base_vector()
        delta = x - x0
        static = {b: self.base.static_of(b).values().copy() for b, is_motion, _ in self.base.parameter_blocks()
                  if not is_motion}
        changes: dict[str, np.ndarray] = {}
        for j, s in enumerate(self.slots):
            if s[0] == "static":
                static[s[1]][s[2]] += delta[j]
            else:
                nodes, _ = self.nodes_of(s[1])
                changes.setdefault(s[1], np.zeros((6, len(nodes))))[s[2], s[3]] = delta[j]
        motions = dict(self.base.motions)
        for body, table in changes.items():
            nodes, _ = self.nodes_of(body)
            kind = self.kind_of(body)
            old = self.base.motions_of(body)
            curves = []
            for i, cv in enumerate(old.curves()):
                if not np.any(table[i]):
                    curves.append(cv)
                    continue
                # the merged table: every breakpoint of both, the base's curve (without
                # its effects) plus the hats, exact at each breakpoint and linear between
                hat = ErrorCurve.table(nodes, table[i], kind)
                pts = np.union1d(np.asarray(cv.target, dtype=float), np.asarray(nodes, dtype=float))
                if kind == "rotary":
                    pts = np.unique(np.mod(pts, 360.0))
                dev = cv.baseline(pts) + hat.baseline(pts)
                curves.append(ErrorCurve.table(pts, dev, kind, cv.effects))
            motions[body] = ErrorMotions(*curves)
        return replace(self.base, static_errors={b: SixDof.from_values(v) for b, v in static.items()},
                       motions=motions)

    def _base_vector(self) -> np.ndarray:
        cached = self.__dict__.get("_x0")
        if cached is None:
            cached = self.values_from_model(self.base)
            object.__setattr__(self, "_x0", cached)
        return cached


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
    #: the grating rows are relative to the mean of this many approaches of the
    #: reference position (``measure.calibration_plan``); 0: relative to nothing measured
    reference_approaches: int = 0
    #: the vision stage's own standard uncertainty of each sighting (um), tangential and
    #: axial (its per-frame centre u, ``HoleMeasurement.x_u_px`` / ``y_u_px``); None: unknown
    tangential_u_um: np.ndarray | None = None
    axial_u_um: np.ndarray | None = None

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
    return predict_with_model(model, par.z_body, design, axial_mm, angle_deg, radius_mm,
                              z_reference_mm=par.z_nodes_mm[0])


def predict_with_model(model: StationModel, z_body: str, design: Sightings, axial_mm, angle_deg, radius_mm: float,
                       z_reference_mm: float | None = None):
    """As :func:`predict`, for any ``StationModel`` (a world's, with effects beyond the
    node tables). ``z_reference_mm``: the grating rows are relative to the reading
    there (a run's grating reference, the gauge's first node), else absolute."""
    e = model.errors(design.z_mm, design.c_deg)
    ax_dp, ang_dp, _ = model.part_coordinates(e.actual_point_mm)
    ezz = model.motions_of(z_body).z
    grating_um = ezz.evaluate(design.z_mm)
    if z_reference_mm is not None:
        grating_um = grating_um - ezz.evaluate(np.array([float(z_reference_mm)]))[0]
    a_t = np.asarray(axial_mm, dtype=float)[design.target]
    phi_t = np.asarray(angle_deg, dtype=float)[design.target]
    tangential_um = radius_mm * np.radians(_wrap_deg(phi_t - ang_dp[design.pose])) * 1e3
    axial_um = (a_t - ax_dp[design.pose]) * 1e3
    return np.concatenate([grating_um, tangential_um, axial_um])


def off_z_nodes(par: Parameterisation, z_mm) -> np.ndarray:
    """(M,) bool: poses whose z is not one of the parameterisation's z nodes."""
    z = np.atleast_1d(np.asarray(z_mm, dtype=float))
    return ~np.isclose(z[:, None], np.asarray(par.z_nodes_mm)[None, :], atol=1e-6).any(axis=1)


def jacobian(par: Parameterisation, design: Sightings, n_targets: int, radius_mm: float,
             free_carriage_off_nodes: bool = False) -> np.ndarray:
    """d(observations)/d(parameters), analytic, first order at zero error.

    Rows: grating (M), tangential (K), axial (K). Columns: the model parameters
    (``par.names``, per um or arcsec), then each target's axial deviation (um), then
    each target's tangential deviation (um).

    ``free_carriage_off_nodes``: the structure the noise model gives a run (``NoiseModel``:
    the carriage off the z nodes is a free nuisance, so EZZ's node values reach no row of
    such a pose); for the observability report and the planner, which must see what the
    identification sees."""
    z, c = design.z_mm, design.c_deg
    M, K = z.size, design.pose.size
    eff = pose_effects(par, z, c, radius_mm)
    A_ax, A_an, G = eff["axial_um"], eff["tangential_um"], eff["grating_um"]
    if free_carriage_off_nodes:
        off = off_z_nodes(par, z)
        ezz = [j for j, s in enumerate(par.slots) if s[0] == "motion" and s[1] == par.z_body and s[2] == 2]
        for A in (A_ax, A_an, G):
            A[np.ix_(off, ezz)] = 0.0
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
    S, d_axial_mm, d_angle_rad, d_radial_mm, block_col = _point_derivatives(par, z, c)
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


def _point_derivatives(par: Parameterisation, z: np.ndarray, c: np.ndarray):
    """The model's closed-form sensitivity at zero error (per mm or rad of every column of
    the full parameter vector) and, by the chain rule of ``part_coordinates``, the
    detection point's axial (mm), angular (rad) and radial (mm) derivatives; with the
    first column of each parameter block."""
    base = par.base.without_errors()
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
    return S, d_axial_mm, d_angle_rad, d_radial_mm, block_col


def carriage_effects(par: Parameterisation, z_mm, c_deg, radius_mm: float) -> dict[str, np.ndarray]:
    """First-order effect of 1 um of the carriage along its own z at each pose (M,):
    what the slide's repeatability does at one approach (an EZZ of that approach
    alone). The grating reads it (1), the camera sees the detection point move with
    it (axial, tangential um)."""
    z = np.atleast_1d(np.asarray(z_mm, dtype=float))
    c = np.atleast_1d(np.asarray(c_deg, dtype=float))
    _, d_ax, d_an, _, block_col = _point_derivatives(par, z, c)
    k = block_col[(par.z_body, True)] + 2  # EZZ's column: a translation along the carriage's z
    w = TO_SI[2]
    return {"grating_um": np.ones(z.size), "axial_um": d_ax[:, k] * w * 1e3,
            "tangential_um": radius_mm * d_an[:, k] * w * 1e3}


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
    #: the noise model's figures of the run (sigmas as estimated, the run's nuisances)
    noise: dict = field(default_factory=dict)

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


@dataclass(frozen=True)
class NoiseModel:
    """How a calibration run's observations err, for :func:`identify`.

    * The grating's own reading (``sigma_grating_um``).
    * The slide's **repeatability per approach** (``repeatability_um``, ISO 230-2's s):
      each pose's approach leaves the carriage a random amount off, which the grating
      reads and the camera sees (the detection point rides the carriage). It is one
      nuisance per pose with prior N(0, s^2) (``carriage_effects``), so a pose's grating
      row and its axial sightings share it, as they do on the machine.
    * The **grating's reference**: the rows are each reading minus the mean of
      ``Observations.reference_approaches`` readings at the first z node, so that mean's
      own repeatability (s / sqrt(n)) is common to every grating row: one more nuisance.
    * The **camera's scale at the view offsets**: every sighting's offset from the image
      centre is read through the camera's mm-per-pixel (its calibration's relative u,
      ``CameraGeometry.scale_u_rel``, 2e-4) and the lens's barrel distortion, which the
      vision stage does not correct (about -3e-4 of a 0.7 mm offset for a k1 of -0.08 at
      1400 px). Both act as one relative scale of the offsets, common to every sighting:
      a nuisance with prior N(0, ``image_scale_u``^2), wide, so the run measures it.
    * The vision stage's tangential and axial reading: per sighting, its own stated u
      (``Observations.tangential_u_um`` / ``axial_u_um``), else ``sigma_vision_um``.

    With ``estimate``, a factor on the variance of each group (tangential and axial
    sightings, the repeatability) is **estimated from the run's residuals** (variance
    components, Foerstner's iteration: the group's squared residuals, whitened by the
    nominal, over its redundancy, the trace of I - H over its rows), each with a
    conjugate prior of ``prior_dof`` degrees of freedom at 1 (the nominal), so a group
    with little redundancy stays near its nominal. A model that does not fit the world
    (structure between the nodes that neither the station's model nor the nodes hold:
    a screw's lead error, a finer straightness) shows in the residuals and so in u:
    the stated u are those of the data, not of a guessed sigma.
    """

    sigma_grating_um: float = SIGMA_GRATING_UM
    sigma_vision_um: float = SIGMA_VISION_UM
    repeatability_um: float = 0.3
    image_scale_u: float = 1e-3
    estimate: bool = True
    prior_dof: float = 4.0
    max_rounds: int = 10
    free_off_node: bool = True


def identify(par: Parameterisation, prior_model: StationModel, cert: ArtefactCertificate, obs: Observations, *,
             sigma_vision_um: float = SIGMA_VISION_UM, sigma_grating_um: float = SIGMA_GRATING_UM,
             rtol: float = RANK_RTOL, max_iterations: int = 6, noise: NoiseModel | None = None) -> Identification:
    """Weighted least squares of the model parameters and target nuisances, starting from
    the station's present model (``prior_model``) and the certificate.

    The certificate is a prior: each target's deviation from its certified position has
    prior N(0, (U/2)^2). The model parameters have no prior: a combination the data do
    not see (the null space of the whitened Jacobian, rank by ``rtol``) is left where the
    present model has it (minimum-norm Gauss-Newton steps), and is reported unobservable
    rather than guessed.

    ``noise``: the run's noise model (:class:`NoiseModel`: per-approach carriage errors,
    the grating reference's, the camera's scale, estimated variances); without it every
    row is independent with ``sigma_vision_um`` / ``sigma_grating_um``."""
    design = obs.design
    T = len(cert.targets)
    P = par.size
    r = cert.radius_mm
    M, K = design.z_mm.size, design.pose.size
    a0 = cert.certified_axial_mm()
    phi0 = cert.certified_angle_deg()
    J = jacobian(par, design, T, r)
    u_cert = np.concatenate([cert.axial_u_um(), cert.tangential_u_um()])
    n_obs = M + 2 * K
    y = obs.vector()
    # the run's own nuisances (noise model): per-pose carriage, the grating reference,
    # the camera's scale at the offsets (per mille)
    n_ref = int(obs.reference_approaches) if noise is not None and obs.reference_approaches > 0 else 0
    if noise is not None:
        ce = carriage_effects(par, design.z_mm, design.c_deg, r)
        n_run = M + (1 if n_ref else 0) + 1
        E = np.zeros((n_obs, n_run))
        E[np.arange(M), np.arange(M)] = 1.0
        E[M + np.arange(K), design.pose] = -ce["tangential_um"][design.pose]
        E[M + K + np.arange(K), design.pose] = -ce["axial_um"][design.pose]
        col = M
        if n_ref:
            E[:M, col] = -1.0  # every row is a reading minus the reference's mean
            col += 1
        E[M:, col] = y[M:] * 1e-3  # each sighting's offset, read through the scale
        J = np.hstack([J, E])
    N = J.shape[1]
    n_run = N - P - 2 * T

    # nominal sigmas: grating rows, tangential and axial sightings; the run's priors
    if noise is None:
        sig_g = sigma_grating_um
        sig_t0 = np.full(K, sigma_vision_um)
        sig_a0 = np.full(K, sigma_vision_um)
        rep0 = math.nan
    else:
        sig_g = noise.sigma_grating_um
        sig_t0 = (np.asarray(obs.tangential_u_um, dtype=float) if obs.tangential_u_um is not None
                  else np.full(K, noise.sigma_vision_um))
        sig_a0 = (np.asarray(obs.axial_u_um, dtype=float) if obs.axial_u_um is not None
                  else np.full(K, noise.sigma_vision_um))
        rep0 = noise.repeatability_um
    factor = {"tangential": 1.0, "axial": 1.0, "repeatability": 1.0, "off_node": 1.0}

    # the carriage at a pose off the z nodes: its approach's error and EZZ's departure
    # from the nodes' interpolation there (a screw's lead error, finer structure) act
    # alike (an EZZ at that pose alone), and the grating reads their sum. So the carriage
    # nuisances off the nodes are a variance group of their own ("off_node", nominal the
    # repeatability): where EZZ has structure between the nodes they come out larger,
    # their prior widens, and the nodes' EZZ rests on the poses at the nodes (and the
    # reference) instead of on the interpolation
    at_node = ~off_z_nodes(par, design.z_mm)

    def system():
        sig = np.r_[np.full(M, sig_g), sig_t0 * math.sqrt(factor["tangential"]),
                    sig_a0 * math.sqrt(factor["axial"])]
        u_prior = u_cert
        if n_run:
            rep = rep0 * math.sqrt(factor["repeatability"])
            off = rep0 * math.sqrt(factor["off_node"]) if not noise.free_off_node else np.inf
            u_prior = np.r_[u_cert, np.where(at_node, rep, off), [rep / math.sqrt(n_ref)] if n_ref else [],
                            [noise.image_scale_u * 1e3]]
        prior = np.zeros((u_prior.size, N))
        prior[np.arange(u_prior.size), P + np.arange(u_prior.size)] = 1.0 / u_prior
        return np.vstack([J / sig[:, None], prior]), sig, u_prior

    def unpack(x):
        ax = a0 + x[P:P + T] * 1e-3
        ang = phi0 + np.degrees(x[P + T:P + 2 * T] * 1e-3 / r)
        return ax, ang

    def residuals(x, sig, u_prior):
        ax, ang = unpack(x)
        res_obs = y - predict(par, x[:P], design, ax, ang, r) - J[:, P + 2 * T:] @ x[P + 2 * T:]
        return res_obs, np.concatenate([res_obs / sig, -x[P:] / u_prior])

    x = np.concatenate([par.values_from_model(prior_model), np.zeros(N - P)])
    it = 0
    rounds = 1 if noise is None or not noise.estimate else noise.max_rounds
    estimated: dict[str, float] = {}
    groups = {"tangential": (np.arange(M, M + K), sig_t0), "axial": (np.arange(M + K, M + 2 * K), sig_a0),
              "repeatability": (n_obs + 2 * T + np.nonzero(at_node)[0], np.full(int(at_node.sum()), rep0)),
              "off_node": (n_obs + 2 * T + np.nonzero(~at_node)[0], np.full(int((~at_node).sum()), rep0))}
    for _round in range(rounds):
        A, sig, u_prior = system()
        U_, s, Vt = np.linalg.svd(A, full_matrices=False)
        rank = int((s > rtol * s[0]).sum())
        Ur, sr, Vr = U_[:, :rank], s[:rank], Vt[:rank].T
        for it in range(1, max_iterations + 1):
            _, res = residuals(x, sig, u_prior)
            dx = Vr @ ((Ur.T @ res) / sr)
            x = x + dx
            if np.max(np.abs(dx)) < 1e-6:  # um / arcsec: far below any u
                break
        if rounds == 1:
            break
        # variance components: per group, the squared residuals whitened by the nominal
        # over the redundancy, with prior_dof degrees of freedom at the nominal
        res_obs, _ = residuals(x, sig, u_prior)
        raw = np.r_[res_obs, x[P:]]  # a prior row's residual is its nuisance itself
        redundancy = 1.0 - (Ur ** 2).sum(axis=1)
        nu0 = noise.prior_dof
        change = 0.0
        for g, (rows, nominal) in groups.items():
            if g == "off_node" and noise.free_off_node:
                continue
            q2 = float(((raw[rows] / nominal) ** 2).sum())
            red = float(redundancy[rows].sum())
            new = (q2 + nu0) / (red + nu0)
            change = max(change, abs(new / factor[g] - 1.0))
            factor[g] = new
            estimated["redundancy_" + g] = red
        if change < 0.01:
            break
    A, sig, u_prior = system()
    U_, s, Vt = np.linalg.svd(A, full_matrices=True)
    rank = int((s > rtol * s[0]).sum())
    sr, Vr = s[:rank], Vt[:rank].T
    V0 = Vt[rank:].T
    res_obs, res_w = residuals(x, sig, u_prior)
    dof = max(A.shape[0] - rank, 1)
    cov = (Vr / sr ** 2) @ Vr.T
    null_fraction = (V0 ** 2).sum(axis=1)
    # observable: the unit vector of the parameter is orthogonal to the null space (an
    # estimable function); 1e-6 of its squared norm allows for rounding, a combination
    # that touches it genuinely leaves 1e-3 or more
    observable = null_fraction < 1e-6
    u = np.where(observable, np.sqrt(np.clip(np.diag(cov), 0.0, None)), np.nan)
    n_vision = design.pose.size
    vis = res_obs[M:]
    keep = P + 2 * T  # the run's nuisances are reported apart (``noise``)
    names = par.names + tuple(f"axial_{t}" for t in cert.ids) + tuple(f"tangential_{t}" for t in cert.ids)
    units = par.units + ("um",) * (2 * T)
    noise_out: dict = {}
    if noise is not None:
        xr = x[keep:]
        noise_out = {"sigma_grating_um": sig_g,
                     "sigma_vision_tangential_um": float(np.median(sig[M:M + K])) if K else None,
                     "sigma_vision_axial_um": float(np.median(sig[M + K:])) if K else None,
                     "variance_factors": dict(factor),
                     "repeatability_um": float(rep0 * math.sqrt(factor["repeatability"])),
                     "estimated": bool(noise.estimate), "reference_approaches": n_ref,
                     "reference_offset_um": float(xr[M]) if n_ref else None,
                     "image_scale_permille": float(xr[-1]), "image_scale_u_permille": float(math.sqrt(cov[-1, -1])),
                     "carriage_um": [float(v) for v in xr[:M]], **estimated}
    return Identification(
        names=names, units=units, n_model=P, value=x[:keep], u=u[:keep], observable=observable[:keep],
        null_fraction=null_fraction[:keep], covariance=cov[:keep, :keep], rank=rank - n_run,
        condition=float(s[0] / sr[-1]), singular_values=s, null_space=V0[:keep],
        residual_rms_um=float(np.sqrt(np.mean(vis ** 2))) if n_vision else math.nan,
        chi2_per_dof=float((res_w ** 2).sum() / dof), iterations=it, noise=noise_out)
