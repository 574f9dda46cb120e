"""Merged scan logs keep the order of the scans, whatever the inspection ids sort as."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from station.inspection.scanlog import merge_scan_logs, write_scan_log


def holes(offset_um: float):
    frame = lambda z: SimpleNamespace(grating_mm=z + offset_um * 1e-3, time_s=10.0 + z, z_cmd_mm=z)  # noqa: E731
    return [SimpleNamespace(frames=[frame(z)]) for z in (5.0, 20.0, 35.0)]


def test_runs_follow_the_scan_start_not_the_id(tmp_path):
    # ids that sort against the order of the scans
    write_scan_log(tmp_path, "ffff", holes(1.0))  # the first scan
    p1 = tmp_path / "scanlogs" / "ffff.csv"
    text = p1.read_text()
    assert "started_utc" in text
    write_scan_log(tmp_path, "0000", holes(2.0))  # the second
    p2 = tmp_path / "scanlogs" / "0000.csv"
    # make the order unambiguous: the first log started a day earlier
    p1.write_text(text.replace(text.split("started_utc:")[1].split("\n")[0], " 2026-01-01T00:00:00.000+00:00"))
    rec = merge_scan_logs([p2, p1])
    assert list(rec.run) == [1, 1, 1, 2, 2, 2]
    np.testing.assert_allclose(rec.deviation[:3], 1.0, atol=1e-9)
    np.testing.assert_allclose(rec.deviation[3:], 2.0, atol=1e-9)
    assert np.all(np.diff(rec.time_s) > 0)
