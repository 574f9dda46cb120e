"""`station inspect` as the plant runs it: exit codes, JSON with the twin's truth, the stored row."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
DEFAULT_SCENARIO = REPO / "sim" / "scenarios" / "default.toml"


def station(*args, cwd):
    return subprocess.run([sys.executable, "-m", "station.cli", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=300)


def test_inspect_pass_json_and_stored(tmp_path):
    r = station("inspect", "--part", "ZDZG-22.2-12.3851", "--serial", "SN-CLI", "--data", str(tmp_path),
                "--time-scale", "50", "--json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["result"] == "pass" and len(out["characteristics"]) == 4
    assert all(abs(c["measured"] - c["true_value"]) < 3e-3 for c in out["characteristics"])
    listed = station("results", "list", "--data", str(tmp_path), "--json", cwd=tmp_path)
    assert listed.returncode == 0, listed.stderr
    assert out["id"] in listed.stdout


def test_inspect_fail_exits_1(tmp_path):
    text = DEFAULT_SCENARIO.read_text().replace("axial_mm = 85.19", "axial_mm = 85.33")
    assert "85.33" in text
    scen = tmp_path / "bad_part.toml"
    scen.write_text(text)
    r = station("inspect", "--part", "ZDZG-22.2-12.3851", "--serial", "SN-BAD", "--data", str(tmp_path / "var"),
                "--scenario", str(scen), "--time-scale", "50", cwd=tmp_path)
    assert r.returncode == 1, r.stderr
    assert "FAIL" in r.stdout and "OUT" in r.stdout


def test_inspect_bad_part_exits_2(tmp_path):
    r = station("inspect", "--part", "NO-SUCH-PART", "--serial", "X", "--data", str(tmp_path), cwd=tmp_path)
    assert r.returncode == 2
    assert "NO-SUCH-PART" in r.stderr and "Traceback" not in r.stderr
