"""The certified master: its certificate file, the spec it is inspected with, the comparison."""

from __future__ import annotations

import json
import subprocess
import sys
from types import SimpleNamespace

import pytest

from sim.masters import master_part
from station.checks.master import compare, load_master, parse_master
from station.parts import load_part
from station.parts.loader import PartSpecError


def test_built_in_master_loads_and_gives_its_own_search_zones():
    cert = load_master("MC-22.2-A")
    family = load_part(cert.part_number)
    spec = cert.as_part_spec(family)
    assert spec.part_number == "MC-22.2-A" and spec.placement == family.placement
    h1 = spec.hole("hole_1")
    assert h1.position.nominal == cert.hole("hole_1").position_mm
    # the family's tolerance widths about the certified values
    assert h1.position.upper_limit - h1.position.nominal == pytest.approx(0.1)


def test_certificate_errors_name_the_file_line_and_field(tmp_path):
    text = ('master_id = "M-1"\npart_number = "ZDZG-22.2-12.3851"\ncertificate = "c"\n\n[[holes]]\nid = "hole_1"\n'
            'angle_deg = 0.0\nposition_mm = 71.0\nposition_U_um = -0.6\ndiameter_mm = 0.7\ndiameter_U_um = 0.5\n'
            'colour = "red"\n')
    with pytest.raises(PartSpecError) as e:
        parse_master(text, "m.toml")
    msg = str(e.value)
    assert "m.toml, line 9: holes[0].position_U_um" in msg and "m.toml, line 12: holes[0].colour: unknown key" in msg
    with pytest.raises(PartSpecError, match="no built-in master"):
        load_master("NOPE")
    (tmp_path / "dup.toml").write_text(text.replace("-0.6", "0.6").replace('colour = "red"\n', "")
                                       + '[[holes]]\nid = "hole_1"\nangle_deg = 0.0\nposition_mm = 85.0\n'
                                         'position_U_um = 0.6\ndiameter_mm = 0.7\ndiameter_U_um = 0.5\n')
    with pytest.raises(PartSpecError, match="hole ids appear twice: hole_1"):
        load_master(tmp_path / "dup.toml")


def test_compare_uses_standard_uncertainties_of_both():
    cert = load_master("MC-22.2-A")
    h = cert.hole("hole_1")
    c = SimpleNamespace(id="hole_1.position", measured=h.position_mm + 0.001, uncertainty_k2=0.0008)
    (chk,) = compare(cert, [c])
    assert chk.u_station == pytest.approx(0.0004) and chk.u_certificate == pytest.approx(0.0003)
    assert chk.z == pytest.approx(0.001 / 0.0005)


def test_the_twins_master_is_its_certificate_within_its_u():
    cert = load_master("MC-22.2-A")
    for seed in range(20):
        part = master_part(cert, bore_diameter_mm=22.2, seed=seed)
        for h in part.holes:
            c = cert.hole(h.name)
            assert abs(h.axial_mm - c.position_mm) <= c.position_U_um * 1e-3 + 1e-12
            assert abs(h.diameter_mm - c.diameter_mm) <= c.diameter_U_um * 1e-3 + 1e-12


def test_check_master_on_the_simulated_station(tmp_path):
    r = subprocess.run([sys.executable, "-m", "station.cli", "check", "master", "--json", "--time-scale", "50",
                        "--data", str(tmp_path / "var")], capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["master_id"] == "MC-22.2-A" and out["in_control"] and out["alarms"] == []
    assert {c["id"] for c in out["checks"]} == {"hole_1.position", "hole_1.diameter", "hole_2.position", "hole_2.diameter"}
    assert all(abs(c["z"]) < 4.5 for c in out["checks"])
