"""The station's multi-body error model: exact E (Eq. 12), its six components
(Eq. 13), the detection point's displacement, and first-order sensitivities.

How the paper is read (each deviation from the printed text is deliberate):

* Topology from ``station/data/topology.toml`` (Table 1 with its columns 4 and 5
  corrected, see that file). The chains are derived from it.
* Ideal transforms (Table 2): body N sits at the endoscope offset D = (Dx, Dy, Dz)
  from the Z slide; O_M coincides with O_N at z = 0, C = 0, so the ideal detection
  point at (z, C) is at axial position z and angle C of the part; Z translates
  along z; C rotates about z. Table 2 puts every other origin at O_R, which makes
  the table's pivot coincide with the slide's reference point. A real station's
  table sits far below the slide's reference (the endoscope hangs from the
  carriage), and the lever arm of the table's tilt motions depends on it; so we
  allow a table offset T (P2 from R) and put M at D - T from J, which keeps the
  paper's convention O_M = O_N. With T = 0 this is Table 2 exactly.
* Actual transforms: ``T' = T_ideal_static @ Err_static @ joint'``, where for the
  slide ``joint' = Trans(0, 0, z) @ Err_Z(z)`` (Eq. 3: errors in the carriage frame,
  so straightness is not polluted by the angular errors times z) and for the table
  ``joint' = Err_C(C) @ Rz(C)``. Eq. (6) as printed mixes both orders (its third
  column is that of Err @ Rz, its bottom row that of Rz @ Err) and drops eps_z(C);
  we use the ISO 230-7 reading, error motions of a rotary axis measured in the
  fixed frame, and restore ECC = eps_z(C) (the ~50 arcsec of section 5.2).
* Eq. (2) is printed as T34' but is the installation error of N on the slide,
  between bodies 2 and 3 (T23'); it follows the ideal offset D.
* Eq. (6)'s eta_ZC sits in the xy block of T45p': a rotation about z, i.e. C0C, a
  zero offset of C. The squareness of C to Z is modelled as the two tilts A0C, B0C
  (and offsets X0C, Y0C) of the alignment ``Err_static`` of body C.
* Every error matrix is exact: Trans(d) @ Rz(c) Ry(b) Rx(a), whose first-order form
  is the paper's small-angle matrix. E is computed with exact products and exact
  rigid inverses, not linearised.
* Eq. (13)'s dx, dy, dz are the translation of E, the displacement of M's origin.
  The detection point is not at M's origin (at C = 0 it is at (0, 0, z)), so its
  displacement is (E - I) o_w = d + theta x o_w (to first order); we report both.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from station.effects import EffectSpecError, ErrorCurve, effect_from_dict
from station.kinematics.parameters import (
    COMPONENTS,
    ErrorMotions,
    SixDof,
    alignment_names,
    installation_names,
    motion_names,
)
from station.kinematics.rigid import (
    ARCSEC_PER_RAD,
    Rigid,
    adjoint_apply,
    angles_xyz,
    rot_xyz,
    rot_z,
    small_transform,
    then_rotate_z,
    then_translate_z,
)
from station.kinematics.topology import Topology, load_topology

#: poses processed at once: keeps the temporaries of one chunk in the CPU cache
CHUNK = 16384


class ModelConfigError(ValueError):
    """A station model file that cannot be used; names file and field."""


@dataclass(frozen=True)
class Slot:
    """One factor of a kinematic chain."""

    kind: str  # "const", "prismatic_z", "revolute_z", "error"
    body: str
    const: Rigid | None = None
    #: for "error" slots: which parameter block (body name) and whether it is an
    #: error motion of a joint (per pose) or a static error (constant)
    motion: bool = False


@dataclass(frozen=True)
class PoseErrors:
    """The error of the detection point at N poses (SI: mm and rad)."""

    d_mm: np.ndarray  # (N, 3) translation of E (Eq. 13: dx, dy, dz)
    theta_rad: np.ndarray  # (N, 3) theta_x, theta_y, theta_z of E (Eq. 13), exact reading
    displacement_mm: np.ndarray  # (N, 3) actual minus ideal detection point, part frame M
    ideal_point_mm: np.ndarray  # (N, 3) ideal detection point in M
    actual_point_mm: np.ndarray  # (N, 3) actual detection point in M

    @property
    def theta_arcsec(self) -> np.ndarray:
        return self.theta_rad * ARCSEC_PER_RAD

    @property
    def displacement_um(self) -> np.ndarray:
        return self.displacement_mm * 1e3


@dataclass(frozen=True)
class StationModel:
    """The geometric error model of the station: geometry plus every error parameter."""

    topology: Topology
    endoscope_offset_mm: tuple[float, float, float]
    #: the table's pivot (P2's origin) in R; (0, 0, 0) is Table 2 as printed
    table_offset_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    #: constant small errors by body name: installation errors (N, P1, P2, J, M) and
    #: the C axis's alignment (X0C, Y0C, Z0C, A0C, B0C, C0C) under body "C"
    static_errors: dict[str, SixDof] = field(default_factory=dict)
    #: error motions by joint body name ("Z", "C")
    motions: dict[str, ErrorMotions] = field(default_factory=dict)
    z_travel_mm: tuple[float, float] = (0.0, 150.0)
    name: str = "station"

    # ------------------------------------------------------------------ structure
    @property
    def installation_bodies(self) -> tuple[str, ...]:
        """Bodies with six installation errors: every non-root body without a joint."""
        return tuple(b.name for b in self.topology.bodies if b.parent is not None and b.joint is None)

    @property
    def joint_bodies(self) -> tuple[str, ...]:
        return tuple(b.name for b in self.topology.bodies if b.joint is not None)

    def static_block_names(self, body: str) -> tuple[str, ...]:
        b = self.topology.by_name(body)
        if b.joint == "revolute_z":
            return alignment_names(body)
        return installation_names(body)

    def parameter_blocks(self) -> list[tuple[str, bool, tuple[str, ...]]]:
        """(body, is_motion, six names) for every error block, in chain order."""
        out = []
        for chain in (self.topology.tool_chain, self.topology.workpiece_chain):
            for slot in self._slots(chain, ideal=True):
                if slot.kind == "error":
                    names = motion_names(slot.body) if slot.motion else self.static_block_names(slot.body)
                    out.append((slot.body, slot.motion, names))
        return out

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(n for _, _, names in self.parameter_blocks() for n in names)

    def ideal_static(self, body: str) -> Rigid:
        """Table 2's static matrices: N at the endoscope offset D from the slide; the
        table's pivot P2 at T from R; M at D - T from J (so O_M = O_N at the start)."""
        D = np.asarray(self.endoscope_offset_mm, dtype=float)
        T = np.asarray(self.table_offset_mm, dtype=float)
        if body == "N":
            return Rigid.translation(D)
        if body == "P2":
            return Rigid.translation(T)
        if body == "M":
            return Rigid.translation(D - T)
        return Rigid.identity()

    def _slots(self, chain: list[int], ideal: bool = False) -> list[Slot]:
        """The factors of one chain, root outwards. Static errors are folded into
        constants unless ``ideal`` (then error slots stay as markers)."""
        slots: list[Slot] = []
        for j in chain:
            body = self.topology.bodies[j]
            slots.append(Slot("const", body.name, self.ideal_static(body.name)))
            # static error: installation (bodies without a joint, paper Eqs. 2, 4, 5,
            # 7, 8) or a rotary axis's alignment (T45p'). The slide has none of its
            # own: its mounting error is bracket P1's installation error.
            if body.joint != "prismatic_z":
                slots.append(Slot("error", body.name, motion=False))
            if body.joint == "prismatic_z":
                slots.append(Slot("prismatic_z", body.name))
                slots.append(Slot("error", body.name, motion=True))  # Trans(z) @ Err_Z
            elif body.joint == "revolute_z":
                # Err_C @ Rz(C): C's error motions live in the fixed frame (ISO 230-7)
                slots.append(Slot("error", body.name, motion=True))
                slots.append(Slot("revolute_z", body.name))
            elif body.joint is not None:
                raise ModelConfigError(f"unknown joint {body.joint!r} of body {body.name!r}")
        if ideal:
            return slots
        # fold constants and static errors into single constant factors
        folded: list[Slot] = []
        acc: Rigid | None = None
        for s in slots:
            if s.kind == "const" or (s.kind == "error" and not s.motion):
                t = s.const if s.kind == "const" else small_transform(self.static_of(s.body).as_si())
                acc = t if acc is None else acc @ t
            else:
                if acc is not None:
                    folded.append(Slot("const", "", acc))
                    acc = None
                folded.append(s)
        if acc is not None:
            folded.append(Slot("const", "", acc))
        return folded

    def static_of(self, body: str) -> SixDof:
        """The installation (static) error of ``body``; zero when the model has none."""
        return self.static_errors.get(body, SixDof())

    def motions_of(self, body: str) -> ErrorMotions:
        """The six error motions of a joint body (zero curves where none are configured)."""
        b = self.topology.by_name(body)
        kind = "rotary" if b.joint == "revolute_z" else "linear"
        return self.motions.get(body, ErrorMotions.zero(kind))

    # ------------------------------------------------------------------ evaluation
    def joint_positions(self, z_mm, c_deg) -> dict[str, np.ndarray]:
        pos = {}
        for b in self.topology.bodies:
            if b.joint == "prismatic_z":
                pos[b.name] = z_mm
            elif b.joint == "revolute_z":
                pos[b.name] = c_deg
        return pos

    def motion_values_si(self, z_mm, c_deg, direction_z=None, direction_c=None, time_s=None, temperature_c=None):
        """Every joint's six error motions at the poses, (N, 6) each, mm and rad."""
        out = {}
        for b in self.topology.bodies:
            if b.joint == "prismatic_z":
                out[b.name] = self.motions_of(b.name).evaluate_si(z_mm, direction_z, time_s, temperature_c)
            elif b.joint == "revolute_z":
                out[b.name] = self.motions_of(b.name).evaluate_si(c_deg, direction_c, time_s, temperature_c)
        return out

    def _chain_product(self, slots: list[Slot], z_mm, c_rad, motions_si, ideal: bool) -> Rigid:
        acc: Rigid | None = None
        for s in slots:
            if s.kind == "const":
                t = s.const
            elif s.kind == "prismatic_z":  # acc @ Trans(0, 0, z), without a full product
                acc = then_translate_z(acc, z_mm)
                continue
            elif s.kind == "revolute_z":  # acc @ Rz(C), without a full product
                acc = then_rotate_z(acc, c_rad)
                continue
            elif s.kind == "error":
                if ideal:
                    continue
                if s.motion:
                    t = small_transform(motions_si[s.body])
                else:
                    t = small_transform(self.static_of(s.body).as_si())
            else:  # pragma: no cover
                raise AssertionError(s.kind)
            acc = t if acc is None else acc @ t
        return acc if acc is not None else Rigid.identity()

    def relative_pose(self, z_mm, c_deg, *, ideal: bool = False, motions_si=None, **context) -> Rigid:
        """The detection frame N in the part frame M (Eq. 1 ideal, Eq. 9 actual)."""
        z, c = np.broadcast_arrays(np.asarray(z_mm, dtype=float), np.asarray(c_deg, dtype=float))
        if motions_si is None and not ideal:
            motions_si = self.motion_values_si(z, c, **context)
        tool = self._chain_product(self._slots(self.topology.tool_chain, ideal=ideal), z, np.radians(c), motions_si, ideal)
        work = self._chain_product(self._slots(self.topology.workpiece_chain, ideal=ideal), z, np.radians(c), motions_si, ideal)
        return work.inverse() @ tool

    def body_pose(self, body: str, z_mm, c_deg, *, ideal: bool = False, **context) -> Rigid:
        """Pose of one body's frame in the machine frame R (the chain up to it).

        This is what an instrument fixed to the machine base sees: a laser
        interferometer's reflector on the endoscope (body N), a rotary calibrator
        on the table (body C)."""
        z, c = np.broadcast_arrays(np.asarray(z_mm, dtype=float), np.asarray(c_deg, dtype=float))
        motions = None if ideal else self.motion_values_si(z, c, **context)
        chain = self.topology.chain(self.topology.by_name(body).index)
        return self._chain_product(self._slots(chain, ideal=ideal), z, np.radians(c), motions, ideal)

    def ideal_point_mm(self, z_mm, c_deg) -> np.ndarray:
        """Ideal detection point in M, closed form of Eq. (1) with Table 2:
        Trans(T - D) Rz(-C) (D - T + z e_z)."""
        z = np.asarray(z_mm, dtype=float)
        c = np.radians(np.asarray(c_deg, dtype=float))
        r = np.asarray(self.endoscope_offset_mm, dtype=float) - np.asarray(self.table_offset_mm, dtype=float)
        cc, sc = np.cos(c), np.sin(c)
        x = cc * r[0] + sc * r[1] - r[0]
        y = -sc * r[0] + cc * r[1] - r[1]
        return np.stack([x, y, np.broadcast_to(z, x.shape).astype(float)], axis=-1)

    def errors(self, z_mm, c_deg, *, direction_z=None, direction_c=None, time_s=None, temperature_c=None,
               motions_si: dict[str, np.ndarray] | None = None) -> PoseErrors:
        """Exact E (Eq. 12) and its reading (Eq. 13) at N poses, vectorised and chunked.

        The error motions are evaluated from their curves at the poses, unless
        ``motions_si`` gives them already ((N, 6) per joint body, mm and rad): a
        caller that evaluates the same poses under several hypotheses, or a
        benchmark of E alone, passes them in."""
        z = np.atleast_1d(np.asarray(z_mm, dtype=float))
        c = np.atleast_1d(np.asarray(c_deg, dtype=float))
        z, c = np.broadcast_arrays(z, c)
        n = z.size
        ctx = [direction_z, direction_c, time_s, temperature_c]
        ctx = [None if v is None else np.broadcast_to(np.asarray(v, dtype=float), z.shape) for v in ctx]
        d = np.empty((n, 3))
        th = np.empty((n, 3))
        disp = np.empty((n, 3))
        ideal_pt = np.empty((n, 3))
        actual_pt = np.empty((n, 3))
        tool_slots = self._slots(self.topology.tool_chain)
        work_slots = self._slots(self.topology.workpiece_chain)
        for lo in range(0, n, CHUNK):
            hi = min(n, lo + CHUNK)
            zz, cc = z[lo:hi], c[lo:hi]
            if motions_si is None:
                sub = [None if v is None else v[lo:hi] for v in ctx]
                m = self.motion_values_si(zz, cc, *sub)
            else:
                m = {k: v[lo:hi] for k, v in motions_si.items()}
            crad = np.radians(cc)
            actual = self._chain_product(work_slots, zz, crad, m, False).inverse() @ self._chain_product(
                tool_slots, zz, crad, m, False
            )
            # ideal relative pose in closed form: R = Rz(-C), p = ideal point
            ip = self.ideal_point_mm(zz, cc)
            # E = P' P^-1: R_E = R' Rz(-C)^T = R' Rz(C), d_E = p' - R_E p   (Eq. 12, exact)
            RE = then_rotate_z(Rigid(actual.R, actual.p), crad).R
            dE = actual.p - np.einsum("nij,nj->ni", RE, ip)
            d[lo:hi] = dE
            th[lo:hi] = angles_xyz(RE)
            ideal_pt[lo:hi] = ip
            actual_pt[lo:hi] = actual.p
            disp[lo:hi] = actual.p - ip
        return PoseErrors(d, th, disp, ideal_pt, actual_pt)

    def error_matrix(self, z_mm, c_deg, **context) -> np.ndarray:
        """E itself, (N, 4, 4)."""
        e = self.errors(z_mm, c_deg, **context)
        R = rot_xyz(e.theta_rad[:, 0], e.theta_rad[:, 1], e.theta_rad[:, 2])
        return Rigid(R, e.d_mm).matrix()

    # ------------------------------------------------------------------ first order
    def sensitivity(self, z_mm, c_deg) -> np.ndarray:
        """First-order sensitivity at zero error: (N, 9, P) with rows
        (dx, dy, dz [mm], theta_x, theta_y, theta_z [rad], point displacement x, y, z [mm])
        per unit of each parameter in SI (mm or rad), P = len(parameter_names).

        Derived in closed form, not by differencing: an error X inserted in the tool
        chain after the ideal product A gives E - I = G X G^-1 with G = W^-1 A; in the
        workpiece chain, before the ideal product B, it gives E - I = -B^-1 X B.
        """
        z = np.atleast_1d(np.asarray(z_mm, dtype=float))
        c = np.atleast_1d(np.asarray(c_deg, dtype=float))
        z, c = np.broadcast_arrays(z, c)
        crad = np.radians(c)
        n = z.size
        tool = self._slots(self.topology.tool_chain, ideal=True)
        work = self._slots(self.topology.workpiece_chain, ideal=True)
        W = self._chain_product(work, z, crad, None, True)
        Winv = W.inverse()
        o_w = self.ideal_point_mm(z, c)
        cols = []
        eye6 = np.eye(6)

        def prefix(slots, k):
            return self._chain_product(slots[:k], z, crad, None, True)

        for k, s in enumerate(tool):
            if s.kind != "error":
                continue
            G = Winv @ prefix(tool, k)
            for i in range(6):
                cols.append(adjoint_apply(G, np.broadcast_to(eye6[i], (n, 6))))
        for k, s in enumerate(work):
            if s.kind != "error":
                continue
            B = self._chain_product(work[k + 1 :], z, crad, None, True)
            Binv = B.inverse()
            for i in range(6):
                cols.append(-adjoint_apply(Binv, np.broadcast_to(eye6[i], (n, 6))))
        S = np.stack(cols, axis=-1)  # (N, 6, P): (d, theta)
        point = S[:, :3, :] + np.cross(S[:, 3:, :], o_w[:, :, None], axis=1)
        return np.concatenate([S, point], axis=1)

    def parameter_values_si(self, z_mm, c_deg, **context) -> np.ndarray:
        """Every parameter's value at the poses, (N, P) in mm and rad, in the order
        of :attr:`parameter_names`."""
        z = np.atleast_1d(np.asarray(z_mm, dtype=float))
        c = np.atleast_1d(np.asarray(c_deg, dtype=float))
        z, c = np.broadcast_arrays(z, c)
        motions = self.motion_values_si(z, c, **context)
        cols = []
        for body, is_motion, _ in self.parameter_blocks():
            if is_motion:
                cols.append(motions[body])
            else:
                cols.append(np.broadcast_to(self.static_of(body).as_si(), z.shape + (6,)))
        return np.concatenate(cols, axis=-1)

    def first_order_errors(self, z_mm, c_deg, **context) -> np.ndarray:
        """First-order prediction of (d, theta, point displacement), (N, 9), SI."""
        S = self.sensitivity(z_mm, c_deg)
        p = self.parameter_values_si(z_mm, c_deg, **context)
        return np.einsum("nrp,np->nr", S, p)

    # ------------------------------------------------------------------ part frame
    def part_coordinates(self, point_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(axial mm, angle deg, radius mm) of points in the part frame M.

        The bore axis is the nominal C axis: in M it is the line through
        -(D - T)_xy parallel to z. The angle is measured so that the ideal detection
        point at command (z, C) has angle C and axial position z.
        """
        r = np.asarray(self.endoscope_offset_mm, dtype=float) - np.asarray(self.table_offset_mm, dtype=float)
        q = np.asarray(point_mm)[..., :2] + r[:2]
        phi0 = np.degrees(np.arctan2(r[1], r[0]))
        angle = phi0 - np.degrees(np.arctan2(q[..., 1], q[..., 0]))
        return np.asarray(point_mm)[..., 2], angle, np.hypot(q[..., 0], q[..., 1])

    def with_errors_scaled(self, factor: float) -> "StationModel":
        """The same model with every error (static and motion) multiplied by ``factor``."""
        def scale_curve(cv: ErrorCurve) -> ErrorCurve:
            effects = []
            for e in cv.effects:
                params = e.parameters
                for key in ("value", "ppm", "reversal", "amplitude", "coefficient"):
                    if key in params:
                        params[key] *= factor
                effects.append(e.with_parameters(**params))
            return replace(cv, deviation=tuple(v * factor for v in cv.deviation), effects=tuple(effects))

        return replace(
            self,
            static_errors={k: SixDof.from_values(v.values() * factor) for k, v in self.static_errors.items()},
            motions={k: ErrorMotions(*(scale_curve(cv) for cv in m.curves())) for k, m in self.motions.items()},
        )

    def without_errors(self) -> "StationModel":
        return replace(self, static_errors={}, motions={})


# ---------------------------------------------------------------------- files
def _curve_from(data: Any, kind: str, where: str) -> ErrorCurve:
    if not isinstance(data, dict):
        raise ModelConfigError(f"{where}: expected a table with target/deviation/effects")
    target = data.get("target", [])
    deviation = data.get("deviation", [])
    if len(target) != len(deviation):
        raise ModelConfigError(f"{where}: target has {len(target)} values, deviation {len(deviation)}")
    try:
        target_f = [float(v) for v in target]
        dev_f = [float(v) for v in deviation]
    except (TypeError, ValueError):
        raise ModelConfigError(f"{where}: target and deviation must be numbers") from None
    if any(b <= a for a, b in zip(target_f, target_f[1:])):
        raise ModelConfigError(f"{where}: target must be strictly increasing")
    effects = []
    for i, e in enumerate(data.get("effects", [])):
        try:
            effects.append(effect_from_dict(e, f"{where}.effects[{i}]"))
        except EffectSpecError as exc:
            raise ModelConfigError(str(exc)) from None
    try:
        return ErrorCurve(kind, tuple(target_f), tuple(dev_f), tuple(effects))
    except ValueError as exc:  # a rotary table over a whole turn that does not close
        raise ModelConfigError(f"{where}: {exc}") from None


def _merge(base: dict, over: dict) -> dict:
    """``over`` laid over ``base``, table by table (values and arrays replace)."""
    out = dict(base)
    for k, v in over.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def _default_model_data() -> dict:
    return tomllib.loads(resources.files("station").joinpath("data/default_station.toml").read_text(encoding="utf-8-sig"))


def model_from_dict(data: dict, source: str = "<dict>", topology: Topology | None = None) -> StationModel:
    """A model from its TOML data. ``extends = "default"`` starts from the built-in
    default station and changes only what the file names (a scenario that differs
    from the default in one installation error says just that)."""
    if "extends" in data:
        if data["extends"] != "default":
            raise ModelConfigError(f"{source}: extends must be \"default\", not {data['extends']!r}")
        data = _merge(_default_model_data(), {k: v for k, v in data.items() if k != "extends"})
    topo = topology or load_topology()
    geo = data.get("geometry", {})
    D = geo.get("endoscope_offset_mm", [0.0, 0.0, 0.0])
    if not (isinstance(D, list) and len(D) == 3):
        raise ModelConfigError(f"{source}: geometry.endoscope_offset_mm must be [Dx, Dy, Dz]")
    travel = geo.get("z_travel_mm", [0.0, 150.0])
    T = geo.get("table_offset_mm", [0.0, 0.0, 0.0])
    if not (isinstance(T, list) and len(T) == 3):
        raise ModelConfigError(f"{source}: geometry.table_offset_mm must be [Tx, Ty, Tz]")
    static: dict[str, SixDof] = {}
    keys = ("x_um", "y_um", "z_um", "a_arcsec", "b_arcsec", "c_arcsec")
    for section in ("installation", "alignment"):
        for body, vals in data.get(section, {}).items():
            try:
                topo.by_name(body)
            except KeyError:
                raise ModelConfigError(f"{source}: [{section}.{body}] names no body of the topology") from None
            unknown = set(vals) - set(keys)
            if unknown:
                raise ModelConfigError(f"{source}: [{section}.{body}] unknown fields {sorted(unknown)}; use {keys}")
            static[body] = SixDof(**{k: float(vals.get(k, 0.0)) for k in keys})
    motions: dict[str, ErrorMotions] = {}
    for body, comps in data.get("motions", {}).items():
        try:
            b = topo.by_name(body)
        except KeyError:
            raise ModelConfigError(f"{source}: [motions.{body}] names no body of the topology") from None
        if b.joint is None:
            raise ModelConfigError(f"{source}: [motions.{body}]: body {body} has no joint")
        kind = "rotary" if b.joint == "revolute_z" else "linear"
        curves = []
        for comp in COMPONENTS:
            key = motion_names(body)[COMPONENTS.index(comp)]
            curves.append(_curve_from(comps[key], kind, f"{source}: motions.{body}.{key}") if key in comps else ErrorCurve.zero(kind))
        unknown = set(comps) - set(motion_names(body))
        if unknown:
            raise ModelConfigError(f"{source}: [motions.{body}] unknown error motions {sorted(unknown)}")
        motions[body] = ErrorMotions(*curves)
    return StationModel(
        topology=topo,
        endoscope_offset_mm=tuple(float(v) for v in D),  # type: ignore[arg-type]
        table_offset_mm=tuple(float(v) for v in T),  # type: ignore[arg-type]
        static_errors=static,
        motions=motions,
        z_travel_mm=(float(travel[0]), float(travel[1])),
        name=str(data.get("name", "station")),
    )


def load_model(path: str | Path | None = None) -> StationModel:
    """Read a station model file; the default is ``station/data/default_station.toml``."""
    if path is None:
        text = resources.files("station").joinpath("data/default_station.toml").read_text(encoding="utf-8-sig")
        source = "station/data/default_station.toml"
    else:
        try:
            text = Path(path).read_text(encoding="utf-8-sig")
        except OSError as exc:
            raise ModelConfigError(f"{path}: {exc.strerror}") from None
        source = str(path)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ModelConfigError(f"{source}: not valid TOML: {exc}") from None
    return model_from_dict(data, source)
