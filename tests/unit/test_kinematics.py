"""The MBS error model: topology, exact E, first-order theory, inverse compensation."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from station.effects import Backlash, ErrorCurve
from station.kinematics.inverse import compensate
from station.kinematics.model import ModelConfigError, load_model, model_from_dict
from station.kinematics.parameters import ErrorMotions, SixDof
from station.kinematics.reference import error_matrix_loop
from station.kinematics.rigid import RAD_PER_ARCSEC, Rigid, angles_xyz, rot_xyz
from station.kinematics.topology import load_topology

ARC = RAD_PER_ARCSEC


@pytest.fixture(scope="module")
def model():
    return load_model()


@pytest.fixture(scope="module")
def clean(model):
    return model.without_errors()


def with_static(model, body, **values):
    return replace(model.without_errors(), static_errors={body: SixDof(**values)})


def with_motion(model, body, comp, curve):
    kind = "rotary" if body == "C" else "linear"
    m = ErrorMotions.zero(kind)
    m = replace(m, **{comp: curve})
    return replace(model.without_errors(), motions={body: m})


def const_curve(value, kind="linear"):
    return ErrorCurve.table([0.0], [value], kind=kind)


# ---------------------------------------------------------------- topology
def test_topology_is_the_corrected_table_1():
    topo = load_topology()
    assert [b.name for b in topo.bodies] == ["R", "P1", "Z", "N", "P2", "C", "J", "M"]
    rows = topo.lower_order_array()
    # L1 with Table 1's misprinted columns 4 and 5 corrected (error-model-notes.md)
    assert rows[1] == [None, 0, 1, 2, 0, 4, 5, 6]
    assert rows[2] == [None, None, 0, 1, None, 0, 4, 5]
    assert rows[3] == [None, None, None, 0, None, None, 0, 4]
    assert rows[4] == [None, None, None, None, None, None, None, 0]
    assert [topo.bodies[j].name for j in topo.tool_chain] == ["P1", "Z", "N"]
    assert [topo.bodies[j].name for j in topo.workpiece_chain] == ["P2", "C", "J", "M"]


# ---------------------------------------------------------------- exact E
def test_zero_errors_give_identity(clean):
    z = np.linspace(0, 150, 37)
    c = np.linspace(-180, 540, 37)
    e = clean.errors(z, c)
    assert np.max(np.abs(e.d_mm)) < 1e-12
    assert np.max(np.abs(e.theta_rad)) < 1e-15
    assert np.max(np.abs(e.displacement_mm)) < 1e-12
    E = clean.error_matrix(z, c)
    assert np.allclose(E, np.eye(4), atol=1e-12)


def test_vectorised_E_equals_per_pose_4x4_algebra(model):
    rng = np.random.default_rng(1)
    z = rng.uniform(0, 150, 40)
    c = rng.uniform(0, 360, 40)
    E_loop = error_matrix_loop(model, z, c)
    E_vec = model.error_matrix(z, c)
    assert np.max(np.abs(E_loop - E_vec)) < 1e-12
    # and the errors are not trivially small in this model: the check has teeth
    assert np.max(np.abs(E_loop[:, :3, 3])) > 1e-3


def test_rotation_reading_inverts_construction():
    rng = np.random.default_rng(2)
    ang = rng.uniform(-0.3, 0.3, (100, 3))
    R = rot_xyz(ang[:, 0], ang[:, 1], ang[:, 2])
    assert np.allclose(angles_xyz(R), ang, atol=1e-14)
    # first order is the paper's small-angle matrix [[1,-c,b],[c,1,-a],[-b,a,1]]
    a, b, c = 1e-5, -2e-5, 3e-5
    small = np.array([[1, -c, b], [c, 1, -a], [-b, a, 1]])
    assert np.max(np.abs(rot_xyz(a, b, c) - small)) < 1e-9


# ---------------------------------------------------------------- single parameters
def test_positioning_error_EZZ_moves_point_axially(model):
    m = with_motion(model, "Z", "z", const_curve(10.0))
    for c in (0.0, 90.0, 217.0):
        e = m.errors([80.0], [c])
        assert e.displacement_um[0] == pytest.approx([0.0, 0.0, 10.0], abs=1e-9)


def test_abbe_error_of_slide_pitch_times_endoscope_offset(model):
    """EBZ (rotation about y) of beta: the point at D from the slide moves by
    beta x D = (beta*Dz, 0, -beta*Dx): the Abbe effect of the endoscope's length."""
    beta = 10.0  # arcsec
    m = with_motion(model, "Z", "b", const_curve(beta))
    Dx, Dy, Dz = model.endoscope_offset_mm
    e = m.errors([50.0], [0.0])
    expected_um = np.array([beta * ARC * Dz, 0.0, -beta * ARC * Dx]) * 1e3
    assert Dz == -200.0 and abs(expected_um[0]) > 9.0  # a real Abbe arm
    # first-order theory to within its second-order remainder (beta^2/2 * |D| ~ 2e-4 um)
    assert e.displacement_um[0] == pytest.approx(expected_um, abs=1e-3)
    # and the exact rotation of D about y, to rounding
    b = beta * ARC
    exact = np.array([np.cos(b) * Dx + np.sin(b) * Dz - Dx, 0.0, -np.sin(b) * Dx + np.cos(b) * Dz - Dz]) * 1e3
    assert e.displacement_um[0] == pytest.approx(exact, abs=1e-9)
    # Eq. (13): d is the error of M's origin; the point's is d + theta x o_w (first order)
    o_w = e.ideal_point_mm[0]
    assert e.d_mm[0] + np.cross(e.theta_rad[0], o_w) == pytest.approx(e.displacement_mm[0], abs=1e-6)
    assert e.theta_arcsec[0] == pytest.approx([0.0, beta, 0.0], abs=1e-9)


def test_table_tilt_EAC_grows_with_height(model):
    """A tilt alpha of the table about x turns the part about the pivot: the point at
    height z above the pivot is displaced by (0, alpha*z, 0) in the part frame."""
    alpha = 10.0
    m = with_motion(model, "C", "a", const_curve(alpha, "rotary"))
    for z in (20.0, 100.0):
        e = m.errors([z], [0.0])
        # first order; the remainder is alpha^2/2 * 100 mm ~ 1e-4 um
        assert e.displacement_um[0] == pytest.approx([0.0, alpha * ARC * z * 1e3, 0.0], abs=1e-3)


def test_angular_positioning_ECC_reads_as_angle_error(model):
    eps = 10.0
    m = with_motion(model, "C", "c", const_curve(eps, "rotary"))
    e = m.errors([60.0, 60.0], [0.0, 123.0])
    _, angle, _ = m.part_coordinates(e.actual_point_mm)
    assert (angle - [0.0, 123.0]) * 3600 == pytest.approx([eps, eps], abs=1e-6)
    r = model.endoscope_offset_mm[0]
    assert e.displacement_um[0] == pytest.approx([0.0, -eps * ARC * r * 1e3, 0.0], abs=1e-3)


def test_installation_error_of_endoscope_turns_with_the_part(model):
    m = with_static(model, "N", x_um=5.0)
    e = m.errors([30.0, 30.0], [0.0, 90.0])
    assert e.displacement_um[0] == pytest.approx([5.0, 0.0, 0.0], abs=1e-9)
    # at C = 90 deg the part has turned: the machine's +x is the part's -y
    assert e.displacement_um[1] == pytest.approx([0.0, -5.0, 0.0], abs=1e-9)


def test_paper_eta_is_a_zero_offset_of_C(model):
    """Eq. (6)'s eta_ZC in the xy block is C0C: it shifts the angle, not a squareness."""
    m = with_static(model, "C", c_arcsec=7.0)
    e = m.errors([40.0, 120.0], [0.0, 0.0])
    _, angle, _ = m.part_coordinates(e.actual_point_mm)
    assert angle * 3600 == pytest.approx([7.0, 7.0], abs=1e-6)
    assert e.displacement_um[:, 2] == pytest.approx([0.0, 0.0], abs=1e-9)  # no axial effect
    # a real squareness (B0C) tilts the table: the lateral error grows with height
    sq = with_static(model, "C", b_arcsec=7.0).errors([40.0, 120.0], [0.0, 0.0])
    assert abs(sq.displacement_um[1, 0]) == pytest.approx(3 * abs(sq.displacement_um[0, 0]), rel=1e-3)


# ---------------------------------------------------------------- first order
def test_analytic_sensitivity_matches_differences_of_exact_model(model):
    clean = model.without_errors()
    z = np.array([12.0, 95.0])
    c = np.array([33.0, 250.0])
    S = clean.sensitivity(z, c)
    names = clean.parameter_names
    assert S.shape == (2, 9, len(names))
    blocks = clean.parameter_blocks()
    col = 0
    for body, is_motion, six in blocks:
        for i in range(6):
            h_user = 1e-3  # 1 nm or 1 milli-arcsec: second-order remainder negligible
            vals = np.zeros(6)
            vals[i] = h_user
            if is_motion:
                kind = "rotary" if body == "C" else "linear"
                curves = [const_curve(v, kind) for v in vals]
                m = replace(clean, motions={body: ErrorMotions(*curves)})
            else:
                m = replace(clean, static_errors={body: SixDof.from_values(vals)})
            e = m.errors(z, c)
            got = np.concatenate([e.d_mm, e.theta_rad, e.displacement_mm], axis=1)
            unit_si = (1e-3 if i < 3 else ARC) * h_user
            assert got / unit_si == pytest.approx(S[:, :, col], abs=1e-4), f"{six[i]}"
            col += 1
    assert col == len(names)


def test_exact_and_first_order_agree_to_second_order(model):
    z = np.linspace(5, 145, 15)
    c = np.linspace(0, 350, 15)
    residuals = []
    for lam in (4.0, 2.0, 1.0):
        m = model.with_errors_scaled(lam)
        e = m.errors(z, c)
        exact = np.concatenate([e.d_mm, e.theta_rad, e.displacement_mm], axis=1)
        first = m.first_order_errors(z, c)
        assert np.max(np.abs(exact - first)) < 1e-2 * np.max(np.abs(exact))
        residuals.append(np.max(np.abs(exact - first)))
    # halving every error quarters the difference: it is of second order
    assert residuals[0] / residuals[1] == pytest.approx(4.0, rel=0.1)
    assert residuals[1] / residuals[2] == pytest.approx(4.0, rel=0.1)


# ---------------------------------------------------------------- inverse
def test_inverse_compensation_round_trips(model):
    rng = np.random.default_rng(3)
    axial = rng.uniform(5, 145, 200)
    angle = rng.uniform(-180, 180, 200)
    sol = compensate(model, axial, angle)
    assert sol.converged.all()
    e = model.errors(sol.z_mm, sol.c_deg)
    ax, an, _ = model.part_coordinates(e.actual_point_mm)
    assert np.max(np.abs(ax - axial)) < 1e-6  # 1 nm
    assert np.max(np.abs(((an - angle + 180) % 360 - 180) * 3600)) < 0.01
    # the correction is real: micrometres and arcseconds, not zero
    assert np.max(np.abs(sol.dz_mm)) > 5e-3
    assert np.max(np.abs(sol.dc_deg * 3600)) > 10


def test_inverse_compensation_uses_direction_dependent_effects(model):
    z_backlash = ErrorCurve.table([0, 150], [0, 0], effects=[Backlash(reversal=6.0)])
    m = with_motion(model, "Z", "z", z_backlash)
    up = compensate(m, [71.03], [0.0], direction_z=+1)
    down = compensate(m, [71.03], [0.0], direction_z=-1)
    assert (up.z_mm - down.z_mm)[0] * 1e3 == pytest.approx(-6.0, abs=1e-6)


# ---------------------------------------------------------------- files
def test_model_file_errors_name_the_field():
    with pytest.raises(ModelConfigError, match=r"motions\.Z.*unknown error motions \['EQZ'\]"):
        model_from_dict({"motions": {"Z": {"EQZ": {"target": [0], "deviation": [1]}}}}, "m.toml")
    with pytest.raises(ModelConfigError, match=r"m.toml: \[installation.Q\]"):
        model_from_dict({"installation": {"Q": {"x_um": 1}}}, "m.toml")
    with pytest.raises(ModelConfigError, match="strictly increasing"):
        model_from_dict({"motions": {"Z": {"EZZ": {"target": [1, 0], "deviation": [0, 0]}}}}, "m.toml")


def test_rigid_inverse_is_exact():
    rng = np.random.default_rng(4)
    ang = rng.uniform(-1, 1, (10, 3))
    T = Rigid(rot_xyz(ang[:, 0], ang[:, 1], ang[:, 2]), rng.normal(size=(10, 3)))
    I = T @ T.inverse()
    assert np.allclose(I.R, np.eye(3), atol=1e-14) and np.allclose(I.p, 0, atol=1e-14)


# ---------------------------------------------------------------- budget and CLI
def test_budget_rows_are_first_order_contributions(model):
    from station.kinematics.budget import error_budget

    # one parameter alone: its budget row is the exact error, to second order
    m = with_motion(model, "Z", "z", ErrorCurve.table([0, 150], [0, 20]))
    rows = {r.parameter: r for r in error_budget(m, np.linspace(0, 150, 11), np.zeros(11))}
    assert rows["EZZ"].max_axial_um == pytest.approx(20.0, abs=1e-9)
    assert rows["EZZ"].worst_z_mm == 150.0
    assert all(r.max_axial_um == 0 for n, r in rows.items() if n != "EZZ")
    # a table tilt shows up tangentially, growing with height, and as an angle
    m = with_motion(model, "C", "a", const_curve(10.0, "rotary"))
    row = next(r for r in error_budget(m, [0.0, 100.0], [0.0, 0.0]) if r.parameter == "EAC")
    assert row.max_tangential_um == pytest.approx(10 * ARC * 100.0 * 1e3, rel=1e-9)
    assert row.max_angle_arcsec == pytest.approx(row.max_tangential_um * 1e-3 / 11.1 / ARC, rel=1e-9)


def test_cli_model_compensate_json(model):
    import json

    from typer.testing import CliRunner

    from station.cli import app

    res = CliRunner().invoke(app, ["model", "compensate", "--axial", "85.19", "--angle", "0", "--json"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    t = out["targets"][0]
    assert t["converged"] and abs(t["residual_nm"]) < 1.0 and abs(t["residual_arcsec"]) < 0.01
    direct = compensate(model, [85.19], [0.0])
    assert t["z_cmd_mm"] == pytest.approx(direct.z_mm[0], abs=1e-12)
