"""A self-calibration's result as a model proposal (issue 21, stage 3): only the
observable parameters change (each with its u), the unobservable ones keep the
station's values, the picture is written, and the approval flow applies it."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from station.calibration.artefact import load_artefact
from station.calibration.identify import Observations, identify, predict
from station.calibration.observability import analyse
from station.calibration.planner import candidate_poses
from station.calibration.proposal import MIN_SIGNIFICANCE, apply_node_change, calibration_proposal, node_term
from station.calibration.run import artefact_parameterisation
from station.kinematics.model import load_model
from station.monitor.proposals import Change, ProposalBook, ProposalError, apply_changes


@pytest.fixture(scope="module")
def outcome():
    """Synthetic sightings of a world 2 um / 2 arcsec away from the station's model in
    every parameter, identified on the artefact's ring nodes (as a run does)."""
    model = load_model()
    cert = load_artefact("CA-22.2-5x8")
    par = artefact_parameterisation(model, cert)
    cand = candidate_poses(cert)
    rng = np.random.default_rng(7)
    truth = par.values_from_model(model) + rng.normal(0.0, 2.0, par.size)
    ax, ang = cert.certified_axial_mm(), cert.certified_angle_deg()
    y = predict(par, truth, cand, ax, ang, cert.radius_mm)
    M, K = cand.z_mm.size, cand.pose.size
    y = y + np.r_[rng.normal(0, 0.05, M), rng.normal(0, 1.0, 2 * K)]
    res = identify(par, model, cert, Observations(cand, y[:M], y[M:M + K], y[M + K:]))
    rep = analyse(par, cert, cand)
    return SimpleNamespace(par=par, result=res, report=rep), model


def test_only_observable_parameters_change(outcome, tmp_path):
    out, model = outcome
    par, res = out.par, out.result
    p = calibration_proposal(out, "base@0", artefact_id="CA-22.2-5x8")
    obs = res.observable[:par.size]
    seat = np.array([s[0] == "static" and s[1] == "M" for s in par.slots])
    before = par.values_from_model(model)
    dev = np.abs(res.value[:par.size] - before) / np.where(obs, res.u[:par.size], np.inf)
    changed = obs & ~seat & (dev > MIN_SIGNIFICANCE)
    # the world is 2 um / 2 arcsec off everywhere: EZZ's nodes (u ~0.1 um) are contradicted,
    # EAC's (u of tens of arcsec through the 11.1 mm arm) are confirmed and kept
    assert len(p.changes) == int(changed.sum()) >= 4
    assert any(n.startswith("EAC") for n in p.explanation["confirmed_parameters"])
    assert set(p.explanation["confirmed_parameters"]) == {n for n, o, c in zip(par.names, obs, changed)
                                                          if o and not c and not n.endswith("_M")}
    assert all(c.u is not None and c.u > 0 for c in p.changes)
    assert all(c.term.startswith(("node.", "installation.")) for c in p.changes)
    assert "keep the station's current values" in p.explanation["description"]

    after = par.values_from_model(apply_changes(model, p.changes))
    assert np.allclose(after[changed], res.value[:par.size][changed], atol=1e-6)
    assert np.allclose(after[~changed], before[~changed], atol=1e-6)  # unobservable, confirmed, the seat: unchanged
    # nothing contradicted: no proposal
    with pytest.raises(ProposalError, match="confirms the station's model"):
        calibration_proposal(out, "base@0", artefact_id="CA-22.2-5x8", min_significance=1e6)

    # the approval flow: kept with its picture, approved, applied at the next start
    book = ProposalBook(tmp_path)
    book.add(p)
    png = book.plot_path(p.id)
    assert png.is_file() and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert {c["name"] for c in p.explanation["curves"]} >= {"EZZ", "EBZ", "EAC"}
    book.decide(p.id, True, "engineer")
    again = par.values_from_model(apply_changes(model, book.approved_changes()))
    assert np.allclose(again, after, atol=1e-9)
    assert obs.sum() > changed.sum()


def test_node_change_is_the_nodes_hat(outcome):
    """A node change moves its node by delta, its neighbours' nodes not at all, and the
    curve between them linearly; on a rotary axis across the turn's end too."""
    out, model = outcome
    par = out.par
    z = model.motions_of(par.z_body).z
    m1 = apply_node_change(model, Change(node_term(par.z_body, "EZZ", 42.5, 10.0, 75.0), 2.0))
    z1 = m1.motions_of(par.z_body).z
    x = np.array([10.0, 26.25, 42.5, 75.0, 140.0])
    assert np.allclose(z1.evaluate(x) - z.evaluate(x), [0.0, 1.0, 2.0, 0.0, 0.0], atol=1e-9)
    m2 = apply_node_change(model, Change(node_term(par.z_body, "EZZ", 140.0, 107.5, None), 1.0))
    d = m2.motions_of(par.z_body).z.evaluate(np.array([107.5, 140.0, 150.0])) - z.evaluate(np.array([107.5, 140.0, 150.0]))
    assert np.allclose(d, [0.0, 1.0, 1.0], atol=1e-9)
    c = model.motions_of(par.c_body).a
    m3 = apply_node_change(model, Change(node_term(par.c_body, "EAC", 315.0, 270.0, 360.0), 4.0))
    xc = np.array([0.0, 270.0, 292.5, 315.0, 337.5, 359.0, 45.0])
    dc = m3.motions_of(par.c_body).a.evaluate(xc) - c.evaluate(xc)
    assert np.allclose(dc, [0.0, 0.0, 2.0, 4.0, 2.0, 4.0 / 45.0, 0.0], atol=1e-9)
    with pytest.raises(ProposalError):
        apply_node_change(model, Change("node.Z.EZZ(at=42.5)", 1.0))


def test_the_expected_change_is_given_at_the_last_master_checks_holes(outcome, tmp_path, monkeypatch):
    """Without holes named, the proposal's expected change is at the master's holes of
    the session's last check (what approving moves its history by), at their angles;
    without a master check there is none. (That the figure predicts what approval does
    to the readings: tests/e2e/test_calibration_adoption.py.)"""
    import asyncio

    import station.checks.axis
    from station.calibration.proposal import propose_from_calibration
    from station.monitor.evidence import MasterRecord

    out, model = outcome
    events, asked = [], []
    real = station.checks.axis.expected_change_um

    def spy(old, new, holes_mm, angle_deg=0.0):
        asked.append((dict(holes_mm), dict(angle_deg)))
        return real(old, new, holes_mm, angle_deg)

    monkeypatch.setattr(station.checks.axis, "expected_change_um", spy)
    session = SimpleNamespace(station=SimpleNamespace(model=model), model_version="base@0", history=[],
                              proposals=ProposalBook(tmp_path), store=SimpleNamespace(log_event=lambda *a: events.append(a)))
    none = asyncio.run(propose_from_calibration(session, out, "CA-22.2-5x8"))
    assert none.expected_change_um == {} and asked == []
    session.history.append(MasterRecord(0.0, 1, {"hole_1": 71.03, "hole_2": 74.98}, {"hole_1": 0.1, "hole_2": -0.2},
                                        {"hole_1": 0.4, "hole_2": 0.4}, {"hole_1": 0.0, "hole_2": 90.0}))
    p = asyncio.run(propose_from_calibration(session, out, "CA-22.2-5x8"))
    assert asked == [({"hole_1": 71.03, "hole_2": 74.98}, {"hole_1": 0.0, "hole_2": 90.0})]
    assert set(p.expected_change_um) == {"hole_1", "hole_2"}
    # this world's contradicted parameters are Z's positioning (EZZ), which the grating
    # reads: the holes' readings do not move (as an axis check's backlash proposal)
    assert all(abs(v) < 0.01 for v in p.expected_change_um.values()), p.expected_change_um
    assert [e[0] for e in events] == ["proposal", "proposal"]
