"""Scenarios, the TwinStation/TwinsThread life cycle and ``station sim up``."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from sim.faults import FaultKind, FaultSwitch, MODBUS_DRIVE_FAULTS
from sim.twins import ScenarioError, TwinStation, TwinsThread, load_scenario, scenario_from_dict

REPO = Path(__file__).resolve().parents[2]


def test_default_scenario_defines_both_drives_and_the_encoder():
    sc = load_scenario()
    assert set(sc.axes) == {"Z", "C"}
    assert (sc.axes["Z"].device_id, sc.axes["C"].device_id) == (1, 2)
    assert sc.axes["Z"].config.kind == "linear" and sc.axes["C"].config.kind == "rotary"
    assert sc.encoder.axis == "Z" and sc.encoder.resolution_um == 0.05
    assert sc.host == "127.0.0.1"


@pytest.mark.parametrize(
    "data, message",
    [
        ({"station": {"host": "0.0.0.0"}}, "loopback"),
        ({"axes": {"Z": {"max_velocity": 1, "colour": "red"}}}, "colour"),
        ({"axes": {}, "encoder": {"axis": "Z"}}, "not defined"),
    ],
)
def test_bad_scenarios_are_refused_with_the_key(data, message):
    with pytest.raises(ScenarioError, match=message):
        scenario_from_dict(data)


def test_missing_scenario_file(tmp_path):
    with pytest.raises(ScenarioError, match="not found"):
        load_scenario(tmp_path / "nope.toml")


def test_fault_switch_refuses_unsupported_kinds_and_notifies():
    seen = []
    fs = FaultSwitch(MODBUS_DRIVE_FAULTS, name="drive Z")
    fs.add_listener(lambda kind, fault: seen.append((kind, fault is not None)))
    with pytest.raises(ValueError, match="black_frame"):
        fs.activate(FaultKind.BLACK_FRAME)
    fs.activate("delay", delay_s=0.5)
    assert fs.get(FaultKind.DELAY).delay_s == 0.5
    fs.clear()
    assert seen == [(FaultKind.DELAY, True), (FaultKind.DELAY, False)] and not fs.active()


def test_twins_thread_serves_and_shuts_down_cleanly():
    runner = TwinsThread(TwinStation())
    try:
        eps = runner.start()
        assert eps["Z"]["port"] != eps["C"]["port"]
        assert os.path.exists(eps["encoder"]["path"])
        assert runner.call(lambda: runner.station.running)
    finally:
        runner.stop()
    assert not runner.station.running
    assert runner.station.encoder._master is None  # pty closed


def test_cli_sim_up_prints_endpoints_and_stops_on_ctrl_c():
    proc = subprocess.Popen(
        [sys.executable, "-c", "from station.cli import main; main()", "sim", "up", "--json"],
        cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        lines = []
        for line in proc.stdout:  # one indented JSON document, closed by "}" at column 0
            lines.append(line)
            if line.rstrip() == "}":
                break
        endpoints = json.loads("".join(lines))
        assert endpoints["Z"]["host"] == "127.0.0.1" and endpoints["Z"]["port"] > 0
        assert endpoints["C"]["device_id"] == 2
        assert endpoints["encoder"]["path"].startswith("/dev/")
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=20) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
