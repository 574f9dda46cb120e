"""The world's drift physics (sim/drift.py) against hand facts, and the world it moves on.

Hand facts: a first-order lag (63 % at one time constant, the steady state of a
steady input), linear expansion alpha * dT * L, wear linear in travel, a collision
that steps one body's installation errors from its instant on.
"""

from __future__ import annotations

import math

import pytest

from sim.drift import Ambient, Collision, Drift, ScrewHeating, Wear, drift_from_dict
from sim.world import World, world_from_dict
from station.kinematics.model import load_model


def test_screw_heating_settles_at_its_rise_per_speed_and_decays_with_its_time_constant():
    s = ScrewHeating(enabled=True, alpha_ppm_per_k=11.7, rise_k_per_mm_s=0.15, tau_s=1200.0, fixed_end_mm=0.0)
    # one move of 120 mm: a jump of r d / tau, then the lag's decay
    s.on_move(120.0, 0.0)
    assert s.rise_k(0.0) == pytest.approx(0.15 * 120.0 / 1200.0)
    assert s.rise_k(1200.0) == pytest.approx(0.015 * math.exp(-1.0))
    # 60 mm every 3 s (20 mm/s mean) for ten time constants: 0.15 K per mm/s -> 3 K
    s2 = ScrewHeating(enabled=True, rise_k_per_mm_s=0.15, tau_s=1200.0)
    t = 0.0
    while t < 12000.0:
        s2.on_move(60.0, t)
        t += 3.0
    assert s2.rise_k(t) == pytest.approx(3.0, rel=0.01)
    # growth from the fixed bearing: alpha dT (z - fixed), in um
    assert s2.growth_um(85.0, t) == pytest.approx(11.7e-6 * s2.rise_k(t) * 85.0 * 1e3)
    assert s2.growth_um(0.0, t) == 0.0
    off = ScrewHeating(enabled=False)
    off.on_move(1e6, 0.0)
    assert off.growth_um(85.0, 10.0) == 0.0


def test_ambient_step_lags_into_each_body_with_its_own_constant_and_coefficient():
    a = Ambient(start_c=20.0, step_c=5.0, at_s=100.0, part_tau_s=600.0, frame_tau_s=5400.0, grating_tau_s=1800.0)
    assert a.part_c(99.0) == 20.0
    assert a.part_c(700.0) == pytest.approx(20.0 + 5.0 * (1 - math.exp(-1)))
    assert a.frame_c(5500.0) == pytest.approx(20.0 + 5.0 * (1 - math.exp(-1)))
    late = 1e6
    # the part: its holes move away from the datum face by alpha dT a
    assert a.part_axial_mm(71.03, late) - 71.03 == pytest.approx(23e-6 * 5.0 * 71.03)
    # the frame loop (-150 mm of steel): the detection point goes down as it grows
    assert a.frame_shift_um(late) == pytest.approx(11.5e-6 * 5.0 * -150.0 * 1e3)
    # the warm grating reads short by alpha dT of the distance from its fixed end
    assert a.grating_error_um(85.0, late) == pytest.approx(-8e-6 * 5.0 * 85.0 * 1e3)
    # a shop already warm at the start: everything expanded, from the first instant
    warm = Ambient(start_c=22.0)
    assert warm.part_axial_mm(100.0, 0.0) == pytest.approx(100.0 * (1 + 23e-6 * 2.0))


def test_wear_grows_with_travel_and_turns():
    w = Wear(backlash_um_per_m=0.5, runout_um_per_kturn=2.0)
    for _ in range(10):
        w.on_move("Z", 100.0)
        w.on_move("Z", -100.0)
    assert w.backlash_extra_um() == pytest.approx(0.5 * 2.0)  # 2 m of travel, both ways
    w.on_move("C", 360.0 * 500)
    assert w.runout_extra_um() == pytest.approx(2.0 * 0.5)


def test_collision_steps_one_body_from_its_instant_on():
    base = load_model()
    world = World(base, drift=Drift(collision=Collision(at_s=50.0, body="J", shift={"z_um": 8.0})))
    assert world.effective_model(49.9) is base
    after = world.effective_model(50.0)
    assert after.static_errors["J"].z_um == pytest.approx(base.static_errors["J"].z_um + 8.0)
    assert after.static_errors["J"].x_um == base.static_errors["J"].x_um
    # the knocked block carries the part with it: the detection point lands 8 um off along the bore
    a0 = world.true_points([70.0], [0.0], 1, 1, 49.0)[0][0]
    a1 = world.true_points([70.0], [0.0], 1, 1, 51.0)[0][0]
    assert abs(abs(a1 - a0) - 8e-3) < 0.5e-3
    with pytest.raises(ValueError, match="not a body"):
        World(base, drift=Drift(collision=Collision(at_s=1.0, body="Q")))
    with pytest.raises(ValueError, match="unknown keys"):
        Collision(shift={"w_um": 1.0})


def test_world_carriage_grating_and_part_follow_the_drift():
    base = load_model()
    drift = Drift(screw=ScrewHeating(enabled=True, tau_s=100.0, rise_k_per_mm_s=1.0),
                  ambient=Ambient(start_c=25.0), wear=Wear(backlash_um_per_m=1000.0))
    w = World(base, drift=drift)
    plain = World(base)
    w.on_move("Z", 0.0, 0.0)
    w.on_move("Z", 100.0, 0.0)  # 100 mm: the screw jumps 1 K; 0.1 m of wear: 100 um of lost motion
    extra_um = 11.7e-6 * 1.0 * 100.0 * 1e3 + 100.0 / 2
    assert (w.z_offset_mm(100.0, +1, 0.0) - plain.z_offset_mm(100.0, +1, 0.0)) * 1e3 == pytest.approx(extra_um)
    # the grating: the true carriage, read short by its warm scale
    assert (w.grating_reading_mm(100.0, 0.0) - 100.0) * 1e3 == pytest.approx(-8e-6 * 5.0 * 100.0 * 1e3)
    # the warm part: a hole at 71.03 mm (20 degC) is seen where the part has grown it to
    pt = plain.true_point(71.0, 0.0)
    seen = [(h.name, dv) for h, du, dv in w.holes_near(pt, 5.0, 5.0)]
    dv_plain = [dv for h, du, dv in plain.holes_near(pt, 5.0, 5.0) if h.name == "hole_1"][0]
    dv_warm = [dv for name, dv in seen if name == "hole_1"][0]
    assert dv_warm - dv_plain == pytest.approx(71.03 * 23e-6 * 5.0, abs=1e-9)


def test_scenario_sections_are_read_and_bad_ones_named():
    d = drift_from_dict({"screw_heating": {"enabled": True, "tau_s": 600},
                         "ambient": {"step_c": 3.0, "at_s": 10},
                         "collision": {"at_s": 5.0, "body": "N", "shift": {"x_um": 2.0}}}, "s.toml")
    assert d.screw.enabled and d.screw.tau_s == 600.0 and d.ambient.step_c == 3.0
    assert d.collision.body == "N" and d.collision.shift == {"x_um": 2.0}
    with pytest.raises(ValueError, match=r"s.toml: \[world.ambient\] unknown keys \['step'\]"):
        drift_from_dict({"ambient": {"step": 3.0}}, "s.toml")
    with pytest.raises(ValueError, match=r"\[world.screw_heating\] tau_s must be positive"):
        drift_from_dict({"screw_heating": {"tau_s": 0}}, "s.toml")
    with pytest.raises(ValueError, match=r"\[world.screw_heating\] enabled = 'yes' is not valid"):
        drift_from_dict({"screw_heating": {"enabled": "yes"}}, "s.toml")
    with pytest.raises(ValueError, match="is not a body"):
        world_from_dict({"collision": {"at_s": 1.0, "body": "X9"}}, "s.toml")
    with pytest.raises(ValueError, match="no such file beside the scenario"):
        world_from_dict({"model": "nowhere.toml"}, "s.toml")
