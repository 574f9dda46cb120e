"""The station's own check of its camera's sensor, on the real twins over loopback.

The world's camera has flawed pixels (``[world.camera_sensor]``: hot and dim pixels, a
charge trap in one column) and its window three specks of dust. The station knows
nothing of them: the check finds the sensor's flaws in frames of the bore wall turning
under the camera, writes the map, and once the config names it, a second check finds
the map up to date, and a surface inspection of the good part passes with no defect
(without the map the trapped column is a scratch in every frame:
tests/unit/test_pixelmap.py). The specks are no pixels' flaws: each reads as a small
pore in every frame, at one place of the image, and the scan sets them aside as marks
that move with the camera. The world's flaw pattern is only the test's annotation.
"""

from __future__ import annotations

import asyncio
import re
from pathlib import Path

import numpy as np

from sim.camera.sensor import SensorFlaws, pattern
from station.parts import load_part
from station.runtime import open_session

REPO = Path(__file__).resolve().parents[2]
DEFAULT = REPO / "sim" / "scenarios" / "default.toml"
FAMILY = "ZDZG-22.2-12.3851"
FLAWS = SensorFlaws(seed=11, hot_share=2e-4, traps=1, specks=3, speck_px=4.0, speck_depth=0.6)


def flawed_scenario(tmp_path: Path) -> Path:
    text = DEFAULT.read_text()
    assert text.count("[world.temperature]") == 1
    table = "".join(f"{k} = {getattr(FLAWS, k)}\n" for k in ("seed", "hot_share", "traps", "specks", "speck_px",
                                                                "speck_depth"))
    text = text.replace("[world.temperature]", f"[world.camera_sensor]\n{table}\n[world.temperature]")
    p = tmp_path / "flawed.toml"
    p.write_text(text)
    return p


def test_the_check_finds_the_sensors_flaws_and_the_mended_scan_passes_the_good_part(tmp_path):
    scen = flawed_scenario(tmp_path)
    fam = load_part(FAMILY)

    async def first():
        async with open_session(scenario=scen, time_scale=20.0, data_dir=tmp_path / "var") as s:
            assert s.station.pixel_map is None
            return await s.check_camera(fam, out_dir=tmp_path / "first")

    res = asyncio.run(asyncio.wait_for(first(), 180))
    assert res.state == "complete" and not res.up_to_date and not res.had_map
    truth = pattern(FLAWS, res.found.width, res.found.height)
    found = {(r, c): k for r, c, k in res.found.pixels}
    hot = dict(zip(zip(truth.hot_rows.tolist(), truth.hot_cols.tolist()), truth.hot_dn.tolist()))
    dead = set(zip(truth.dead_rows.tolist(), truth.dead_cols.tolist()))
    strong = [k for k, v in hot.items() if v >= 20.0]
    assert sum(found.get(k) == "hot" for k in strong) >= 0.95 * len(strong)
    assert sum(found.get(k) == "dim" for k in dead) >= 0.9 * len(dead)
    assert set(found) <= set(hot) | dead  # no sound pixel flagged
    ((col, row, dn),) = truth.traps
    ((c, r0, r1, offset),) = res.found.columns
    assert (c, r0) == (col, 0) and abs(r1 - row) <= 6 and abs(offset + dn) < 1.5
    assert (tmp_path / "first" / "pixel_map.json").is_file() and (tmp_path / "first" / "check.json").is_file()
    assert "as the camera's pixel_map" in res.summary()

    config = tmp_path / "station.toml"
    config.write_text(f'[station]\nmode = "simulated"\n[simulation]\nscenario = "{scen}"\n'
                      f'pixel_map = "{tmp_path / "first" / "pixel_map.json"}"\n')

    async def mended():
        async with open_session(config, time_scale=20.0, data_dir=tmp_path / "var") as s:
            assert s.station.pixel_map is not None
            again = await s.check_camera(fam, out_dir=tmp_path / "second")
            outcome = await s.inspect(fam, "GOOD-1", surface=True)
            return again, outcome

    again, outcome = asyncio.run(asyncio.wait_for(mended(), 400))
    assert again.up_to_date and again.had_map and not again.new_pixels and not again.new_columns
    surface = outcome.surface
    assert outcome.state == "complete" and surface is not None and surface.frames > 0
    assert surface.defects == [], [(d.kind, d.length_mm) for d in surface.defects]
    assert outcome.result == "pass"
    marks = [n for n in surface.notes if "moves with the camera" in n]
    assert len(marks) == len(truth.specks), surface.notes
    at = [tuple(float(v) for v in re.search(r"a pore about .* image px \((\d+), (\d+)\)", n).groups()) for n in marks]
    for x, y in truth.specks:
        assert min(np.hypot(x - ax, y - ay) for ax, ay in at) <= 2.0, (x, y, marks)
