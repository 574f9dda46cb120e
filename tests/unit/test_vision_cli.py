"""``station vision measure`` / ``calibrate``: JSON contract and clear errors."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from sim.camera.lens import BrownLens
from sim.camera.render import FrameParams, HoleSpec, render_frame
from sim.camera.target import board_views
from station.cli import app

runner = CliRunner()


@pytest.fixture(scope="module")
def frame_png(tmp_path_factory):
    p = FrameParams()
    holes = [HoleSpec(400.25, 300.5, 70.0), HoleSpec(900.0, 700.0, 40.0), HoleSpec(20.0, 500.0, 60.0)]
    f = render_frame(p, holes, seed=3)
    path = tmp_path_factory.mktemp("frames") / "frame.png"
    cv2.imwrite(str(path), f.image)
    return path, f


def test_measure_json_is_one_object_with_the_holes(frame_png):
    path, f = frame_png
    result = runner.invoke(app, ["vision", "measure", str(path), "--mm-per-px", "0.01", "--json"])
    assert result.exit_code == 0, result.output
    out = json.loads(result.stdout)  # the whole of stdout is one JSON document
    holes = out["holes"]
    assert len(holes) == 3
    for truth in f.holes:
        (h,) = [h for h in holes if np.hypot(h["x_px"] - truth.x_px, h["y_px"] - truth.y_px) < 1.0]
        assert h["partial"] is truth.partial
        assert 0.0 <= h["confidence"] <= 1.0
        if not truth.partial:
            assert h["x_px"] == pytest.approx(truth.x_px, abs=0.1)
            assert h["diameter_px"] == pytest.approx(truth.diameter_px, abs=0.15)
            assert h["diameter_mm"] == pytest.approx(truth.diameter_px * 0.01, abs=0.0015)


def test_measure_without_scale_has_no_mm(frame_png):
    result = runner.invoke(app, ["vision", "measure", str(frame_png[0]), "--json"])
    assert result.exit_code == 0
    assert all("diameter_mm" not in h for h in json.loads(result.stdout)["holes"])


def test_a_hole_too_large_to_seek_without_a_scale_is_named_not_passed_over(tmp_path, frame_png):
    """A finer camera shows a 1.05 mm hole 150 px across: without a scale the coarse stage
    seeks holes up to 120 px, so the hole is not measured, and the output says so (where,
    how large, what to give); with the scale it is measured and nothing is noted."""
    f = render_frame(FrameParams(), [HoleSpec(640.3, 480.6, 150.0)], seed=5)
    path = tmp_path / "large.png"
    cv2.imwrite(str(path), f.image)
    bare = runner.invoke(app, ["vision", "measure", str(path), "--json"])
    assert bare.exit_code == 0, bare.output
    out = json.loads(bare.stdout)
    assert out["holes"] == []
    (note,) = out["notes"]
    assert "--mm-per-px" in note and "(640, 481) px" in note
    assert 140 <= float(note.split("about ")[1].split(" px")[0]) <= 160
    table = runner.invoke(app, ["vision", "measure", str(path)])
    assert table.exit_code == 0 and "0 hole(s)" in table.stdout and "not measured" in table.stderr
    scaled = json.loads(runner.invoke(app, ["vision", "measure", str(path), "--mm-per-px", "0.007", "--json"]).stdout)
    (h,) = scaled["holes"]
    assert h["diameter_px"] == pytest.approx(150.0, abs=0.3) and scaled["notes"] == []
    assert json.loads(runner.invoke(app, ["vision", "measure", str(frame_png[0]), "--json"]).stdout)["notes"] == []


def test_measure_table(frame_png):
    result = runner.invoke(app, ["vision", "measure", str(frame_png[0])])
    assert result.exit_code == 0 and "3 hole(s)" in result.stdout


@pytest.mark.parametrize("content", [b"not an image at all\n", b""])
def test_bad_file_is_a_clear_error(tmp_path, content):
    bad = tmp_path / "bad.png"
    bad.write_bytes(content)
    result = runner.invoke(app, ["vision", "measure", str(bad), "--json"])
    assert result.exit_code != 0
    assert "not an image" in result.stderr
    assert "Traceback" not in result.output and result.stdout == ""


def test_missing_file_is_a_clear_error(tmp_path):
    result = runner.invoke(app, ["vision", "measure", str(tmp_path / "nope.png")])
    assert result.exit_code != 0 and "no such file" in result.stderr


def test_calibrate_writes_a_calibration_that_measure_uses(tmp_path, frame_png):
    lens = BrownLens(k1=-0.1)
    paths = []
    for i, v in enumerate(board_views(lens, n_views=5, seed=2)):
        paths.append(tmp_path / f"board{i}.png")
        cv2.imwrite(str(paths[-1]), v.image)
    out = tmp_path / "cal.json"
    result = runner.invoke(app, ["vision", "calibrate", *map(str, paths), "--out", str(out),
                                 "--working-distance-mm", "11", "--json"])
    assert result.exit_code == 0, result.output
    cal = json.loads(out.read_text())
    assert cal["camera_matrix"][0][0] == pytest.approx(1400.0, rel=0.01)
    assert cal["mm_per_px"] == pytest.approx(11.0 / 1400.0, rel=0.01)
    result = runner.invoke(app, ["vision", "measure", str(frame_png[0]), "--calibration", str(out), "--json"])
    assert result.exit_code == 0 and all("diameter_mm" in h for h in json.loads(result.stdout)["holes"])
    # a frame too small for the calibration is refused, not silently mis-measured
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), np.full((100, 100), 128, np.uint8))
    result = runner.invoke(app, ["vision", "measure", str(small), "--calibration", str(out)])
    assert result.exit_code != 0 and "calibration is for" in result.stderr


def test_calibrate_tells_where_its_map_can_be_trusted(tmp_path):
    """The summary names the coverage and the map's uncertainty; views that stayed near
    the centre draw a warning on stderr (the run still succeeds and writes the file)."""
    lens = BrownLens(k1=-0.22, k2=0.06)
    for spread, warned in ((1.0, False), (0.0, True)):
        paths = []
        for i, v in enumerate(board_views(lens, n_views=6, seed=3, spread=spread)):
            paths.append(tmp_path / f"s{spread}_{i}.png")
            cv2.imwrite(str(paths[-1]), v.image)
        out = tmp_path / f"cal{spread}.json"
        result = runner.invoke(app, ["vision", "calibrate", *map(str, paths), "--out", str(out)])
        assert result.exit_code == 0, result.output
        assert "covered" in result.stdout and "uncertainty" in result.stdout
        assert ("warning" in result.stderr) == warned, result.stderr
        assert "map_uncertainty" in json.loads(out.read_text())


@pytest.mark.parametrize("layout", ["lsb12", "msb12"])
def test_16_bit_frames_are_scaled_by_the_bits_they_use(tmp_path, frame_png, layout):
    """12-bit data in a 16-bit PNG, at the bottom of the range (max <= 4095) or at the
    top: both read back as the 8-bit frame and measure the same holes.  A fixed shift by
    8 made the bottom-aligned frame 0-15 DN, with no hole in it."""
    from station.vision import measure_holes
    from station.vision.imageio import read_grey

    _, f = frame_png
    rng = np.random.default_rng(1)
    twelve = f.image.astype(np.uint16) * 16 + rng.integers(0, 16, f.image.shape, dtype=np.uint16)
    data = twelve if layout == "lsb12" else twelve << 4
    path = tmp_path / f"{layout}.png"
    cv2.imwrite(str(path), data)
    back = read_grey(path)
    assert back.dtype == np.uint8
    np.testing.assert_array_equal(back, f.image)
    if layout == "lsb12":
        assert (data >> 8).max() < 16  # what the fixed shift by 8 gave
    ref = [(m.x_px, m.y_px, m.diameter_px) for m in measure_holes(f.image)]
    got = [(m.x_px, m.y_px, m.diameter_px) for m in measure_holes(data)]  # arrays too
    assert len(ref) == 3 and got == ref
    result = runner.invoke(app, ["vision", "measure", str(path), "--json"])
    assert result.exit_code == 0, result.output
    assert len(json.loads(result.stdout)["holes"]) == 3


def test_a_float_image_is_refused_with_its_type(tmp_path):
    from station.vision.imageio import ImageReadError, read_grey

    path = tmp_path / "float.tiff"
    cv2.imwrite(str(path), np.full((64, 64), 0.5, np.float32))
    with pytest.raises(ImageReadError, match="float32"):
        read_grey(path)


def test_a_colour_frame_reads_the_same_from_a_file_and_from_memory(tmp_path, frame_png):
    """A BGR frame whose channels differ (a tinted ring light): the file path
    (``read_grey``) and a frame handed to ``measure_holes`` in memory take the same grey,
    the mean of the channels, and measure the same holes."""
    from station.vision import measure_holes
    from station.vision.imageio import read_grey, to_grey

    _, f = frame_png
    g = f.image.astype(np.int32)
    bgr = np.clip(np.stack([g * 0.8, g, g * 1.1 + 3], axis=2), 0, 255).astype(np.uint8)
    path = tmp_path / "colour.png"
    cv2.imwrite(str(path), bgr)
    grey = read_grey(path)
    expected = (bgr.astype(np.int32).sum(axis=2) + 1) // 3
    np.testing.assert_array_equal(grey, expected)
    np.testing.assert_array_equal(to_grey(np.dstack([bgr, np.full(g.shape, 255, np.uint8)])), expected)  # BGRA
    from_file = [(m.x_px, m.y_px, m.diameter_px) for m in measure_holes(grey)]
    in_memory = [(m.x_px, m.y_px, m.diameter_px) for m in measure_holes(bgr)]
    assert len(from_file) == 3 and in_memory == from_file


def test_grey_with_alpha_reads_its_grey_channel(tmp_path, frame_png):
    """A grey + alpha PNG (OpenCV decodes it as BGRA) and a grey + alpha array both give
    the grey channel, not its mean with the alpha."""
    from PIL import Image

    from station.vision.imageio import read_grey, to_grey

    _, f = frame_png
    la = np.dstack([f.image, np.full(f.image.shape, 255, np.uint8)])
    path = tmp_path / "grey_alpha.png"
    Image.fromarray(la).save(path)  # (h, w, 2) uint8: mode LA
    np.testing.assert_array_equal(read_grey(path), f.image)
    np.testing.assert_array_equal(to_grey(la), f.image)
    with pytest.raises(ValueError, match="shape"):
        to_grey(np.zeros((4, 4, 5), np.uint8))


def test_a_frame_from_a_camera_with_a_gamma_is_measured_linear_in_light(tmp_path, frame_png):
    """A camera that encodes light with a gamma of 0.6 (pixel = 255 (light / 255)^0.6):
    the blurred edge is no longer symmetric, and the holes read ~0.3 px small. Given
    ``--gamma`` the frame is made linear first, and the holes read as the linear frame's;
    a gamma no camera has is refused, naming the file."""
    path, f = frame_png
    encoded = np.clip(np.round(255.0 * (f.image / 255.0) ** 0.6), 0, 255).astype(np.uint8)
    enc_path = tmp_path / "gamma.png"
    cv2.imwrite(str(enc_path), encoded)

    def diameters(p, *extra):
        result = runner.invoke(app, ["vision", "measure", str(p), "--mm-per-px", "0.01", "--json", *extra])
        assert result.exit_code == 0, result.output
        holes = json.loads(result.stdout)["holes"]
        return {round(t.x_px): [h["diameter_px"] for h in holes if np.hypot(h["x_px"] - t.x_px, h["y_px"] - t.y_px) < 1.0][0]
                for t in f.holes if not t.partial}

    linear, raw, mended = diameters(path), diameters(enc_path), diameters(enc_path, "--gamma", "0.6")
    for k, d in linear.items():
        assert raw[k] < d - 0.15  # the encoded edge reads the hole small
        assert abs(mended[k] - d) < 0.05, (k, mended[k], d)
    result = runner.invoke(app, ["vision", "defects", str(enc_path), "--mm-per-px", "0.01", "--gamma", "0"])
    assert result.exit_code != 0 and "gamma.png" in result.output and "--gamma" in result.output
