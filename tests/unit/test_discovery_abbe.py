"""Abbe error: found from the angle the laser recorded at each point."""

from __future__ import annotations

import numpy as np
import pytest

from station.discovery import discover
from station.discovery.synth import Campaign, linear_model, make_recording
from station.effects import ABBE_CHANNEL, AbbeError, EvalContext, effect_from_dict


def with_pitch(arm_mm: float, seed: int = 0):
    """A laser campaign whose reflector sits ``arm_mm`` off the scale's line, with the
    carriage's pitch (a bowed guideway) recorded in ``angle_arcsec``."""
    model = linear_model(0.4)
    rec = make_recording(model, (), Campaign(sigma=0.4, seed=seed))
    rng = np.random.default_rng(seed + 100)
    x = rec.target
    pitch = 4.0 * np.sin(np.pi * x / 120.0) + 1.5 * (x / 120.0) ** 2 + rng.normal(0, 0.05, x.size)
    rec.extra[ABBE_CHANNEL] = [f"{v:.3f}" for v in pitch]
    ctx = EvalContext.make(x, "linear", channels={ABBE_CHANNEL: np.round(pitch, 3)})
    rec.deviation = rec.deviation + AbbeError(arm_mm).evaluate(ctx)
    return model, rec


def test_abbe_formula_is_arm_times_angle():
    ctx = EvalContext.make(np.array([0.0, 50.0]), "linear", channels={ABBE_CHANNEL: [10.0, -2.0]})
    # 150 mm x 10 arcsec = 150 * 10 * pi/648000 mm = 7.27 um
    assert AbbeError(150.0).evaluate(ctx) == pytest.approx([150 * 10 * np.pi / 648000 * 1000,
                                                            150 * -2 * np.pi / 648000 * 1000])
    assert AbbeError(150.0).evaluate(EvalContext.make(np.array([1.0]))) == pytest.approx([0.0])
    assert effect_from_dict({"name": "abbe", "arm_mm": 80}) == AbbeError(80.0)


@pytest.mark.parametrize("seed", [0, 1])
def test_discovery_finds_the_abbe_arm(seed):
    model, rec = with_pitch(150.0, seed)
    report = discover(model, rec).report
    names = [e["name"] for e in report["effects"]]
    assert "abbe" in names, report["effects"]
    arm = next(e for e in report["effects"] if e["name"] == "abbe")["parameters"]["arm_mm"]
    assert arm == pytest.approx(150.0, rel=0.25)
    assert report["after"]["rms"] < 1.3 * 0.4


def test_no_abbe_claimed_when_the_angle_does_not_matter():
    model, rec = with_pitch(0.0, 3)
    report = discover(model, rec).report
    assert "abbe" not in [e["name"] for e in report["effects"]]
