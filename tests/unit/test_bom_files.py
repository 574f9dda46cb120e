"""Files saved with a UTF-8 byte-order mark (spreadsheets, Notepad) read like any other.

Issue 18, defect 2: a recording whose first line is a ``# key: value`` metadata
comment was refused ("required column is missing; header is \\ufeff# axis: Z")."""

from __future__ import annotations

import json
from importlib import resources

import pytest
from typer.testing import CliRunner

from station.cli import app
from station.kinematics.model import load_model
from station.parts import load_part
from station.recording import read_recording

BOM = "\ufeff"
RECORDING = ("# axis: Z\n# kind: linear\ntime_s,run,direction,target,deviation\n"
             "0,1,+1,0,1.0\n1,1,+1,10,2.0\n2,1,-1,10,2.5\n3,1,-1,0,1.4\n"
             "4,2,+1,0,1.1\n5,2,+1,10,2.1\n6,2,-1,10,2.4\n7,2,-1,0,1.5\n")


def write(tmp_path, name, text, bom):
    p = tmp_path / name
    p.write_text((BOM if bom else "") + text, encoding="utf-8")
    return p


def test_recording_with_bom_and_metadata_first(tmp_path):
    plain = read_recording(write(tmp_path, "a.csv", RECORDING, False))
    marked = read_recording(write(tmp_path, "b.csv", RECORDING, True))
    assert marked.metadata == plain.metadata and marked.metadata.get("axis") == "Z"
    assert list(marked.deviation) == list(plain.deviation)


def test_iso230_cli_accepts_bom(tmp_path):
    p = write(tmp_path, "rec.csv", RECORDING, True)
    r = CliRunner().invoke(app, ["iso230", str(p), "--json"])
    assert r.exit_code == 0, r.output
    q = CliRunner().invoke(app, ["iso230", str(write(tmp_path, "plain.csv", RECORDING, False)), "--json"])
    assert json.loads(r.stdout) == json.loads(q.stdout)


@pytest.mark.parametrize("bom", [False, True])
def test_toml_readers_accept_bom(tmp_path, bom):
    part_text = resources.files("station").joinpath("data/parts/ZDZG-22.2-12.3851.toml").read_text(encoding="utf-8")
    spec = load_part(write(tmp_path, "ZDZG-22.2-12.3851.toml", part_text, bom))
    assert spec.holes[0].id == "hole_1"
    model_text = resources.files("station").joinpath("data/default_station.toml").read_text(encoding="utf-8")
    model = load_model(write(tmp_path, "model.toml", model_text, bom))
    assert model.motions == load_model().motions
