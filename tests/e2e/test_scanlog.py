"""The station's own scan logs feed discovery: what the grating saw, against the model."""

from __future__ import annotations

import asyncio
from pathlib import Path

from station.axis_model import AxisModel
from station.discovery.engine import discover
from station.inspection.scanlog import SCANLOG_DIR, merge_scan_logs
from station.runtime import open_session
from station.kinematics.model import load_model
from station.parts import load_part

REPO = Path(__file__).resolve().parents[2]
N = 6


def inspect_n(data: Path, scenario: Path | None):
    async def go():
        async with open_session(scenario=scenario, time_scale=100.0, data_dir=data) as s:
            for i in range(N):
                out = await s.inspect(load_part("ZDZG-22.2-12.3851"), f"SN-{i}")
                assert out.result == "pass"
    asyncio.run(asyncio.wait_for(go(), 300))
    return merge_scan_logs(sorted((data / SCANLOG_DIR).glob("*.csv")))


def belief():
    return AxisModel(name="Z", kind="linear", curve=load_model().motions_of("Z").z)


def matched_scenario(tmp_path: Path) -> Path:
    """The default scenario with a world that agrees with the station's model: its
    model is the station's shipped one (no ``model`` key) and its screw stays cool."""
    text = (REPO / "sim" / "scenarios" / "default.toml").read_text()
    assert 'model = "default_world.toml"' in text and "enabled = true" in text
    text = text.replace('model = "default_world.toml"', "").replace("enabled = true", "enabled = false")
    (tmp_path / "matched.toml").write_text(text)
    return tmp_path / "matched.toml"


def test_scan_logs_agree_with_the_model_where_the_world_does(tmp_path):
    rec = inspect_n(tmp_path / "var", matched_scenario(tmp_path))
    assert len(rec) == 2 * N and set(rec.run) == set(range(1, N + 1))
    report = discover(belief(), rec).report
    assert report["verdict"] == "no-mismatch", report["effects"]


def test_scan_logs_reveal_an_error_the_model_lacks(tmp_path):
    # the world's screw reads 6 um long everywhere (a shifted reference mark); the model does not know
    (tmp_path / "drifted_model.toml").write_text(
        'extends = "default"\n[motions.Z.EZZ]\n'
        'target = [0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 90.0, 105.0, 120.0, 135.0, 150.0]\n'
        'deviation = [0.0, 1.8, 3.9, 6.1, 8.0, 10.2, 12.1, 14.2, 16.1, 18.2, 20.0]\n'
        '[[motions.Z.EZZ.effects]]\nname = "backlash"\nreversal = 1.5\n'
        '[[motions.Z.EZZ.effects]]\nname = "offset"\nvalue = 6.0\n')
    scen = matched_scenario(tmp_path).read_text().replace("[world]\n", '[world]\nmodel = "drifted_model.toml"\n', 1)
    assert 'model = "drifted_model.toml"' in scen
    (tmp_path / "scenario.toml").write_text(scen)
    rec = inspect_n(tmp_path / "var", tmp_path / "scenario.toml")
    report = discover(belief(), rec).report
    assert report["verdict"] in ("explained", "partly-explained")
    offsets = [e for e in report["effects"] if e["name"] == "offset"]
    assert offsets and abs(offsets[0]["parameters"]["value"] - 6.0) < 1.5
