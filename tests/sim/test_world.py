"""The simulated world and instruments: the twin errs by the same model that compensation inverts."""

from __future__ import annotations

import numpy as np
import pytest

from sim.instruments import LaserInterferometer, RotaryCalibrator, iso230_sequence
from sim.world import Repeatability, World, world_from_dict
from station.kinematics.inverse import compensate
from station.kinematics.rigid import RAD_PER_ARCSEC


@pytest.fixture(scope="module")
def world():
    return World()


def test_iso230_sequence_is_bidirectional_and_timed():
    t, run, d, x = iso230_sequence([0, 50, 100], runs=2, dwell_s=1.0, speed=10.0)
    assert list(x[:6]) == [0, 50, 100, 100, 50, 0]
    assert list(d[:6]) == [1, 1, 1, -1, -1, -1]
    assert list(run) == [1] * 6 + [2] * 6
    assert np.all(np.diff(t) > 0)


def test_laser_reads_positioning_error_plus_abbe(world):
    """Noise-free, the laser on the endoscope reads EZZ plus the Abbe terms of the
    slide's tilts times the endoscope offset (first order: EAZ*Dy - EBZ*Dx), zeroed at
    the first target."""
    t, run, d, x = iso230_sequence(np.linspace(0, 150, 7), runs=1)
    rec = LaserInterferometer(world, sigma_um=0.0).measure_z(t, run, d, x)
    m = world.model.motions["Z"]
    Dx, Dy, _ = world.model.endoscope_offset_mm
    expected = m.z.evaluate(x, direction=d) + (m.a.evaluate(x) * Dy - m.b.evaluate(x) * Dx) * RAD_PER_ARCSEC * 1e3
    expected -= expected[0]
    assert rec.deviation == pytest.approx(expected, abs=2e-3)
    # the Abbe part is not negligible in this station: the check has teeth
    assert np.max(np.abs(m.b.evaluate(x) * Dx * RAD_PER_ARCSEC * 1e3)) > 0.1


def test_calibrator_reads_angular_positioning(world):
    t, run, d, x = iso230_sequence(np.arange(0.0, 360.0, 45.0), runs=1, speed=30.0)
    rec = RotaryCalibrator(world, sigma_arcsec=0.0).measure_c(t, run, d, x)
    ecc = world.model.motions["C"].c.evaluate(x)
    # to first order the table's tilts do not turn it about z
    assert rec.deviation == pytest.approx(ecc - ecc[0], abs=0.05)


def test_noise_has_the_configured_spread(world):
    t, run, d, x = iso230_sequence(np.linspace(0, 150, 11), runs=5)
    clean = LaserInterferometer(world, sigma_um=0.0).measure_z(t, run, d, x).deviation
    noisy = LaserInterferometer(world, sigma_um=0.5, seed=7).measure_z(t, run, d, x).deviation
    resid = noisy - clean
    assert np.std(resid) == pytest.approx(0.5, rel=0.25)


def test_compensated_command_lands_on_the_hole(world):
    """What compensation commands, the world executes: the true point is on target."""
    hole = world.part.holes[1]
    sol = compensate(world.model, [hole.axial_mm], [hole.angle_deg])
    p = world.true_point(float(sol.z_mm[0]), float(sol.c_deg[0]))
    assert p.axial_mm == pytest.approx(hole.axial_mm, abs=1e-6)
    assert p.angle_deg == pytest.approx(hole.angle_deg, abs=1e-5)
    # uncompensated, the same hole is missed by micrometres
    q = world.true_point(hole.axial_mm, hole.angle_deg)
    assert abs(q.axial_mm - hole.axial_mm) > 5e-3


def test_world_from_scenario_table(tmp_path):
    w = world_from_dict({"temperature": {"start_c": 21.0, "rise_c": 2.0, "tau_s": 100.0},
                         "holes": [{"name": "h", "axial_mm": 50.0, "diameter_mm": 0.8}]}, "s.toml")
    assert w.temperature.at([0.0, 1e9]) == pytest.approx([21.0, 23.0])
    assert w.part.holes[0].axial_mm == 50.0 and w.part.holes[0].angle_deg == 0.0
    with pytest.raises(ValueError, match=r"world.holes\[0\] lacks 'diameter_mm'"):
        world_from_dict({"holes": [{"name": "h", "axial_mm": 1.0}]}, "s.toml")


def test_repeatability_is_drawn_once_per_approach():
    from sim.twins import TwinStation, load_scenario

    class Clock:
        t = 0.0

        def __call__(self):
            return self.t

    clock = Clock()
    twins = TwinStation(load_scenario(), clock=clock)
    world = World(repeatability=Repeatability(z_um=0.5, seed=4))
    world.attach(twins)
    z = twins.physics["Z"]
    z.enable(True)
    errs = []
    for i in range(200):
        assert z.start_move(50.0 + (i % 2))
        clock.t += 30.0
        a = z.carriage_position() - z.motor_position()
        clock.t += 1.0
        assert z.carriage_position() - z.motor_position() == a  # held while the axis rests
        errs.append(a - world.model.motions["Z"].z.evaluate([z.motor_position()], direction=[z.direction])[0] * 1e-3)
    assert np.std(errs) * 1e3 == pytest.approx(0.5, rel=0.2)


def test_an_approachs_random_error_moves_the_detection_point_as_the_grating_sees_it():
    """The per-approach error moves the carriage (what the grating reads); the camera's
    detection point rides on that carriage and must move with it, or a station that
    corrects by the grating would take out an error the camera never saw."""
    w = World(repeatability=Repeatability(z_um=0.3, c_arcsec=0.5, seed=3))
    z, c = 85.0, 10.0
    before = w.true_point(z, c)
    carriage_before = w.z_offset_mm(z, 0, 0.0)
    w.new_approach("Z")
    w.new_approach("C")
    ae_z, ae_c = w.approach_error("Z"), w.approach_error("C")
    assert abs(ae_z) > 1e-5 and abs(ae_c) > 1e-6
    after = w.true_point(z, c)
    # the carriage moved by the approach error; the detection point with it, along the axis
    assert w.z_offset_mm(z, 0, 0.0) - carriage_before == pytest.approx(ae_z, abs=1e-12)
    assert after.axial_mm - before.axial_mm == pytest.approx(ae_z, abs=2e-3 * abs(ae_z) + 1e-9)
    # the table turned by its own error: the part's angle under the point changes by it
    # (the model's part angle follows the table's, as compensation's c = hole angle shows)
    assert after.angle_deg - before.angle_deg == pytest.approx(ae_c, abs=0.01 * abs(ae_c))
    # the model alone (true_points) does not hold them
    ax, _, _ = w.true_points([z], [c])
    assert ax[0] == pytest.approx(before.axial_mm, abs=1e-12)
