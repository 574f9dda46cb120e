"""Campaigns on worlds that depart from the station's model: the station notices.

A knocked calibration block (8 um along the bore) is invisible to every sensor of the
station but its master: the next master check raises the alarm, every alarm is in the
event log, and a world that agrees with its model raises none.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from station.bench.campaign import run_campaign
from station.store import Store

REPO = Path(__file__).resolve().parents[2]
DEFAULT = REPO / "sim" / "scenarios" / "default.toml"


def scenario(tmp_path: Path, name: str, extra: str = "", matched: bool = False) -> Path:
    text = DEFAULT.read_text()
    if matched:
        text = text.replace('model = "default_world.toml"', "").replace("enabled = true", "enabled = false")
    p = tmp_path / f"{name}.toml"
    p.write_text(text + extra)
    return p


def test_a_knocked_datum_is_caught_by_the_next_master_check_and_logged(tmp_path):
    # each part is about 14 s of the drives' clock at time scale 4: the knock falls after part 3
    knock = scenario(tmp_path, "knock", '\n[world.collision]\nat_s = 45.0\nbody = "J"\nshift = { z_um = 8.0 }\n')
    res = run_campaign(knock, parts=8, master_every=3, data=tmp_path / "var", time_scale=4.0)
    errs = [r["worst_error_um"] for r in res["inspections"]]
    first_bad = next(i for i, e in enumerate(errs, start=1) if e > 3.0)
    assert all(e < 3.0 for e in errs[:first_bad - 1]), errs
    assert all(7.0 < e < 10.0 for e in errs[first_bad - 1:]), errs  # the block's 8 um, unseen by the station
    assert res["checks"][0]["in_control"] or res["checks"][0]["index"] >= first_bad
    alarms = res["alarms"]
    assert alarms, res["checks"]
    assert alarms[0]["chart"] == "master" and first_bad <= alarms[0]["index"] <= first_bad + 3
    assert res["watch"]["needs_check"]
    with Store(data_dir=tmp_path / "var") as store:
        logged = [e.message for e in store.events(kind="alarm")]
    assert len(logged) == len(alarms) and all(m.startswith("station needs a check: master check") for m in logged)


def test_a_world_that_agrees_with_its_model_raises_no_alarm(tmp_path):
    res = run_campaign(scenario(tmp_path, "matched", matched=True), parts=8, master_every=4,
                       data=tmp_path / "var", time_scale=4.0)
    assert res["alarms"] == [] and not res["watch"]["needs_check"]
    assert all(c["in_control"] for c in res["checks"]) and len(res["checks"]) == 2
    assert all(r["worst_error_um"] < 1.0 and r["worst_error_um"] < r["u_um"] for r in res["inspections"])


def test_campaign_cli_prints_one_json_object_and_refuses_nonsense(tmp_path):
    r = subprocess.run([sys.executable, "-m", "station.cli", "campaign", "--parts", "2", "--json", "--time-scale", "8"],
                       capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert [i["index"] for i in out["inspections"]] == [1, 2]
    assert set(out) >= {"inspections", "alarms", "models"} and out["models"][0]["index"] == 1
    assert out["inspections"][0]["model_version"].startswith("default-station@")
    bad = subprocess.run([sys.executable, "-m", "station.cli", "campaign", "--parts", "0"],
                         capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert bad.returncode == 2 and "at least one part" in bad.stderr
