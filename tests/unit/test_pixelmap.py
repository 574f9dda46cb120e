"""The camera's flawed pixels: the twin's sensor renders them, the station finds them from
frames of a moving wall (never from the twin's pattern) and mends them before measuring."""

from __future__ import annotations

import json
from dataclasses import replace

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from sim.camera.defects import random_defect_frame
from sim.camera.render import FrameParams, HoleSpec, random_frame, render_frame
from sim.camera.sensor import SensorFlaws, pattern
from station.bench.defects import match
from station.cli import app
from station.vision.defects import detect_defects
from station.vision.pixelmap import MIN_FRAMES, PixelMap, PixelMapBuilder, find_pixel_map

FLAWS = SensorFlaws(seed=7)
runner = CliRunner()


def walls(flaws, n=16, seed=7_100_000):
    """Clean frames of ``n`` other walls (a scan's frames: the wall moves between them)."""
    return [random_defect_frame(seed + i, {}, sensor=flaws).image for i in range(n)]


@pytest.fixture(scope="module")
def found():
    return find_pixel_map(walls(FLAWS))


def test_the_twins_sensor_flaws_are_the_same_pixels_in_every_frame():
    p = replace(FrameParams(width_px=320, height_px=256, groove_depth=0.0, grain=0.0, blotch=0.0, vignetting=0.0),
                sensor=SensorFlaws(seed=3, hot_share=2e-3, hot_median_dn=60, dead_share=1e-3, traps=1, trap_dn=20))
    flaws = pattern(p.sensor, 320, 256)
    assert flaws is pattern(p.sensor, 320, 256)
    a, b = (render_frame(p, [], seed=s).image.astype(float) for s in (1, 2))
    bare = render_frame(replace(p, sensor=None), [], seed=1).image.astype(float)
    hot = (flaws.hot_rows, flaws.hot_cols)
    strong = flaws.hot_dn > 30
    for img in (a, b):
        assert np.all(img[hot][strong] - bare[hot][strong] > 10)  # a dark signal of their own
    dead = (flaws.dead_rows, flaws.dead_cols)
    assert np.all(a[dead] < 0.5 * 150 + 10)
    (col, row, dn), = flaws.traps
    in_col = [r for r in range(256) if (r, col) not in set(zip(*hot)) | set(zip(*dead))]
    above = [r for r in in_col if r <= row]
    below = [r for r in in_col if r > row]
    # the column is short of the trap's charge from the trap up to row 0, not below it
    assert np.mean(bare[above, col] - a[above, col]) == pytest.approx(dn, abs=2.0)
    if below:
        assert abs(np.mean(bare[below, col] - a[below, col])) < 2.0
    # without flaws the frame is what it was before they existed
    assert np.array_equal(render_frame(replace(p, sensor=None), [], seed=1).image, bare.astype(np.uint8))


def test_the_map_finds_the_flaws_from_frames_of_a_moving_wall(found):
    truth = pattern(FLAWS, 1280, 1024)
    pixels = {(r, c): k for r, c, k in found.pixels}
    hot = dict(zip(zip(truth.hot_rows.tolist(), truth.hot_cols.tolist()), truth.hot_dn.tolist()))
    dead = set(zip(truth.dead_rows.tolist(), truth.dead_cols.tolist()))
    (col, row, dn), = truth.traps
    in_trap = {(r, c) for r, c in pixels if c == col}
    # every hot pixel of 20 DN or more (a few of the noise's sigmas) and nearly every dim one
    assert all(pixels.get(k) == "hot" for k, v in hot.items() if v >= 20.0)
    assert sum(pixels.get(k) == "dim" for k in dead if k not in in_trap) >= 0.95 * len(dead)
    # nothing else: no sound pixel is flagged
    assert set(pixels) <= set(hot) | dead
    # the trap's column, from row 0 to the trap (its end within a few rows), its charge
    ((c, r0, r1, offset),) = found.columns
    assert (c, r0) == (col, 0)
    assert abs(r1 - row) <= 6
    assert offset == pytest.approx(-dn, abs=1.0)


def test_a_flawless_sensor_gives_an_empty_map():
    m = find_pixel_map(walls(None, n=MIN_FRAMES, seed=7_150_000))
    assert m.pixels == [] and m.columns == []
    frame = random_frame(5)
    assert m.repair(frame.image) is frame.image


def test_mended_frames_give_no_false_defects_and_the_flawless_frames_defects(found):
    """The trap's column is a 4-5 mm "scratch" in every raw frame; mended, the frames read as
    the same frames from a flawless sensor."""
    raw_false = mended_false = 0
    for s in range(7_200_000, 7_200_004):
        for kinds in ({}, None):
            f = random_defect_frame(s, kinds, sensor=FLAWS)
            bare = random_defect_frame(s, kinds)
            raw = detect_defects(f.image, 0.01)
            mended = detect_defects(found.repair(f.image), 0.01)
            raw_false += len(match(f.defects, raw, 0.01)[1])
            mended_false += len(match(f.defects, mended, 0.01)[1])
            flawless = detect_defects(bare.image, 0.01)
            assert sorted(d.kind for d in mended) == sorted(d.kind for d in flawless)
    assert raw_false >= 4  # the column in most frames (26 of 40 frames of these seeds)
    assert mended_false == 0


def test_a_hole_under_flawed_pixels_is_measured_as_on_a_flawless_sensor():
    """Saturated and dead pixels on a hole's rim move its diameter by several u; mended, it
    is the flawless sensor's to a fraction of its u."""
    from station.vision.measure import measure_holes

    p = FrameParams()
    hole = HoleSpec(640.3, 512.6, 60.0)
    bare = render_frame(p, [hole], seed=11).image
    img = bare.copy()
    rng = np.random.default_rng(2)
    bad = []
    for k in range(8):
        a = rng.uniform(0, 2 * np.pi)
        r, c = int(round(512.6 + 30.0 * np.sin(a))), int(round(640.3 + 30.0 * np.cos(a)))
        img[r, c] = 255 if k % 2 else 0
        bad.append((r, c, "hot" if k % 2 else "dim"))
    pmap = PixelMap(1280, 1024, bad)
    (ref,), (raw,), (mended,) = (measure_holes(x) for x in (bare, img, pmap.repair(img)))
    assert abs(raw.diameter_px - ref.diameter_px) > 2 * ref.diameter_u_px
    assert abs(mended.diameter_px - ref.diameter_px) < 0.5 * ref.diameter_u_px


def test_the_map_file_round_trips_and_bad_files_are_named(tmp_path, found):
    path = tmp_path / "map.json"
    found.save(path)
    back = PixelMap.load(path)
    assert back.pixels == found.pixels and back.frames == found.frames
    assert [c[:3] for c in back.columns] == [c[:3] for c in found.columns]
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "station pixel map 1",\n "width": 10,\n')
    with pytest.raises(ValueError, match=r"bad.json: line 3"):
        PixelMap.load(bad)
    d = found.to_json()
    d["pixels"] = [[5, 2000, "hot"]]
    with pytest.raises(ValueError, match=r"pixels\[0\] \[5, 2000\] lies outside the 1280 x 1024 frame"):
        PixelMap.from_json(d)
    d = found.to_json()
    d["columns"] = [[3, 10, "x", 1.0]]
    with pytest.raises(ValueError, match=r"columns\[0\] must be"):
        PixelMap.from_json(d)
    with pytest.raises(ValueError, match="not a pixel map"):
        PixelMap.from_json({"width": 3})
    with pytest.raises(ValueError, match="this frame is 320 x 256"):
        found.repair(np.zeros((256, 320), np.uint8))
    b = PixelMapBuilder()
    b.add(np.zeros((64, 64), np.uint8))
    with pytest.raises(ValueError, match="frame 2 is 32 x 64 px"):
        b.add(np.zeros((64, 32), np.uint8))
    with pytest.raises(ValueError, match=f"at least {MIN_FRAMES} frames"):
        b.result()


def test_the_cli_builds_a_map_and_mends_the_frames_it_measures(tmp_path):
    files = []
    for i, img in enumerate(walls(FLAWS, n=MIN_FRAMES, seed=7_300_000)):
        files.append(tmp_path / f"wall{i:02d}.png")
        cv2.imwrite(str(files[-1]), img)
    out = tmp_path / "map.json"
    result = runner.invoke(app, ["vision", "pixel-map", *map(str, files), "--out", str(out), "--json"])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    truth = pattern(FLAWS, 1280, 1024)
    assert summary["frames"] == MIN_FRAMES and summary["hot"] >= 0.8 * len(truth.hot_rows)
    assert [c["col"] for c in summary["columns"]] == [truth.traps[0][0]]
    frame = tmp_path / "frame.png"
    cv2.imwrite(str(frame), random_defect_frame(7_400_000, {}, sensor=FLAWS).image)
    args = ["vision", "defects", str(frame), "--mm-per-px", "0.01", "--json"]
    raw = json.loads(runner.invoke(app, args).stdout)["defects"]
    mended = json.loads(runner.invoke(app, [*args, "--pixel-map", str(out)]).stdout)["defects"]
    assert any(d["kind"] == "scratch" and abs(d["x_px"] - truth.traps[0][0]) < 3 for d in raw)
    assert mended == []
    few = runner.invoke(app, ["vision", "pixel-map", *map(str, files[:3]), "--out", str(out)])
    assert few.exit_code != 0 and "at least 12 frames" in few.output
    missing = runner.invoke(app, [*args, "--pixel-map", str(tmp_path / "none.json")])
    assert missing.exit_code != 0 and "none.json" in missing.output
