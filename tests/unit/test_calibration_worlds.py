"""Self-calibration on worlds that differ from the station's model (issue 21, stage 4).

* ``sim.worlds`` draws machines off the station's model by each term's laser-campaign
  uncertainty and some wear, with structure the node model has not (finer tables, a
  screw-lead error); written as a scenario, the twin's world is that machine;
* the identification's noise model (per-approach carriage errors read by the grating
  and seen by the camera, the grating reference's error common to every row, the
  camera's scale at the view offsets, variances estimated from the residuals) states
  honest u on such worlds from synthetic sightings, where independent rows with a
  guessed sigma do not;
* the parameterisation shaped by the station's model keeps its curves between the
  nodes, and is the model a proposal makes.
"""

from __future__ import annotations

import numpy as np
import pytest

from sim.world import load_world
from sim.worlds import WorldSizes, _axial_datum_um, draw_world_model, write_world_scenario
from station.calibration.artefact import load_artefact
from station.calibration.identify import NoiseModel, Observations, carriage_effects, identify, predict_with_model
from station.calibration.measure import SIGMA_GRATING_RUN_UM
from station.calibration.planner import candidate_poses, plan_poses, subset
from station.calibration.proposal import apply_node_change, node_term
from station.calibration.run import artefact_parameterisation
from station.kinematics.model import load_model
from station.monitor.proposals import Change


@pytest.fixture(scope="module")
def setup():
    model = load_model()
    cert = load_artefact("CA-22.2-5x8")
    par = artefact_parameterisation(model, cert)
    cand = candidate_poses(cert)
    design = subset(cand, plan_poses(par, cert, cand, 40, sigma_grating_um=SIGMA_GRATING_RUN_UM,
                                     free_carriage_off_nodes=True))
    return model, cert, par, design


def test_a_drawn_world_is_the_twins_and_differs_by_its_sizes(setup, tmp_path):
    model, cert, par, _ = setup
    x0 = par.values_from_model(model)
    ezz = [j for j, n in enumerate(par.names) if n.startswith("EZZ@")]
    dev, datum = [], []
    for seed in range(12):
        w = draw_world_model(seed)
        dev.append((par.values_from_model(w) - x0)[ezz])
        datum.append(_axial_datum_um(w, model))
    dev = np.array(dev)
    # EZZ off by the laser's U (0.3 um + 1 ppm, the scale and the lead error on top): a few
    # tenths of a um at the nodes, never zero, never tens
    assert 0.1 < dev.std() < 1.0
    # the axial datum within the master's U (a draw of 0.6 um), whatever the single errors add up to
    assert 0.2 < np.std(datum) < 1.2 and np.max(np.abs(datum)) < 3.0
    # finer than any node model: tables every 5 mm and 10 deg, and a lead error
    w = draw_world_model(1)
    assert len(w.motions_of("Z").x.target) == 31 and len(w.motions_of("C").a.target) == 36
    assert any(e.name == "periodic" for e in w.motions_of("Z").z.effects)
    # the scenario's world is that machine (its repeatability seeded with the world's seed)
    scen = write_world_scenario(tmp_path, 1, overrides={"screw_heating": {"enabled": False}})
    world = load_world(scen)
    assert np.allclose(par.values_from_model(world.model), par.values_from_model(w), atol=1e-9)
    assert world.repeatability.seed == 1 and world.drift.screw.enabled is False
    # and further off on request
    far = draw_world_model(1, sizes=WorldSizes().scaled(4.0))
    assert np.abs(par.values_from_model(far) - x0).max() > np.abs(par.values_from_model(w) - x0).max()


def test_shaped_parameterisation_keeps_the_models_curves_and_is_the_proposals_model(setup):
    model, cert, par, design = setup
    x0 = par.values_from_model(model)
    m0 = par.to_model(x0)
    z = np.linspace(0.0, 150.0, 61)
    c = np.linspace(0.0, 359.0, 73)
    # the station's own model, between the nodes too (its finer tables, its effects)
    zero = np.zeros_like(z)
    assert np.allclose(m0.errors(z, zero).actual_point_mm, model.errors(z, zero).actual_point_mm, atol=1e-9)
    assert np.allclose(m0.motions_of("C").x.evaluate(c), model.motions_of("C").x.evaluate(c))
    # a node's change is its hat, as the proposal applies it
    j = par.names.index("EZZ@75mm")
    x = x0.copy()
    x[j] += 2.0
    prop = apply_node_change(model, Change(node_term("Z", "EZZ", 75.0, 42.5, 107.5), 2.0))
    assert np.allclose(par.to_model(x).motions_of("Z").z.evaluate(z), prop.motions_of("Z").z.evaluate(z), atol=1e-9)
    assert np.allclose(par.values_from_model(par.to_model(x)), x, atol=1e-9)


def _sightings(par, cert, design, world, rng, *, vision_um=0.17, repeat_um=0.3, scale=-3e-4):
    """What a run sees of ``world``: each approach's carriage error (grating and camera
    alike), the reference's, the camera's scale and noise; the certificate's targets made
    within U/2."""
    ax = cert.certified_axial_mm() + rng.normal(0, 1, len(cert.targets)) * cert.axial_u_um() * 1e-3
    ang = cert.certified_angle_deg() + np.degrees(
        rng.normal(0, 1, len(cert.targets)) * cert.tangential_u_um() * 1e-3 / cert.radius_mm)
    y = predict_with_model(world, par.z_body, design, ax, ang, cert.radius_mm, z_reference_mm=par.z_nodes_mm[0])
    M, K = design.z_mm.size, design.pose.size
    e = rng.normal(0, repeat_um, M)
    ref = rng.normal(0, repeat_um / np.sqrt(10))
    ce = carriage_effects(par, design.z_mm, design.c_deg, cert.radius_mm)
    y[:M] += e - ref + rng.normal(0, 0.02, M)
    y[M:M + K] += -ce["tangential_um"][design.pose] * e[design.pose] + rng.normal(0, vision_um, K)
    y[M + K:] += -ce["axial_um"][design.pose] * e[design.pose] + rng.normal(0, vision_um, K)
    y[M:] *= 1.0 + scale
    u = np.full(K, 0.18)  # what the vision stage states for such holes
    return Observations(design, y[:M], y[M:M + K], y[M + K:], reference_approaches=10,
                        tangential_u_um=u, axial_u_um=u)


def test_noise_model_states_honest_u_on_drawn_worlds(setup):
    model, cert, par, design = setup
    honest, guessed = [], []
    for seed in range(12):
        rng = np.random.default_rng(500 + seed)
        world = draw_world_model(700 + seed)
        truth = par.values_from_model(world)
        obs = _sightings(par, cert, design, world, rng)
        res = identify(par, model, cert, obs, noise=NoiseModel())
        o = res.observable[:par.size]
        assert o.sum() >= 13
        honest.extend(np.abs(res.model_vector() - truth)[o] / res.u[:par.size][o])
        assert 0.5 < res.noise["variance_factors"]["repeatability"] < 2.0
        assert abs(res.noise["image_scale_permille"] + 0.3) < 3 * res.noise["image_scale_u_permille"]
        # independent rows with the nominal sigmas, the reference and the scale no terms
        old = identify(par, model, cert, obs, sigma_grating_um=SIGMA_GRATING_RUN_UM)
        guessed.extend(np.abs(old.model_vector() - truth)[o] / old.u[:par.size][o])
    honest, guessed = np.array(honest), np.array(guessed)
    assert 0.5 < np.median(honest) < 1.5, np.median(honest)
    assert np.mean(honest <= 2.0) >= 0.9 and np.mean(honest <= 3.0) >= 0.98
    # the guessed sigma (1 um for a vision stage that does 0.17) inflates every u
    assert np.median(guessed) < 0.5, np.median(guessed)


def test_report_and_identification_agree_on_ezz_seen_only_off_its_node(setup):
    """Off the z nodes the carriage is the run's free nuisance: a ring seen only from axial
    offsets tells nothing of EZZ at its node, and the report says so, as the fit finds."""
    model, cert, par, _ = setup
    from station.calibration.observability import analyse

    cand = candidate_poses(cert)
    top = max(par.z_nodes_mm)
    at_top = np.isclose(cand.z_mm, top)
    design = subset(cand, np.nonzero(~at_top)[0])  # the top ring only from its axial offsets
    rep = analyse(par, cert, design, free_carriage_off_nodes=True, candidate_poses=subset(cand, np.nonzero(at_top)[0]))
    j = par.names.index(f"EZZ@{top:g}mm")
    assert not rep.observable[j]
    combo = next(c for c in rep.unobservable if c.terms == [(par.names[j], 1.0)])
    assert "off the z nodes" in combo.description
    assert combo.suggestions and all(f"z = {top:.2f} mm" in x for x in combo.suggestions)
    assert rep.observable[par.names.index("EZZ@75mm")]
    obs = _sightings(par, cert, design, draw_world_model(11), np.random.default_rng(11))
    res = identify(par, model, cert, obs, noise=NoiseModel())
    assert np.array_equal(res.observable[:par.size], rep.observable)
    assert res.rank == rep.rank
    # without the noise model's structure the node would look seen (through the interpolation)
    assert analyse(par, cert, design).observable[j]
