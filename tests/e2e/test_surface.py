"""The whole-surface inspection on the simulated station (issue 23, part B): seeded
defects in the twin's world are found by the coverage scan at their true places
(within 0.05 mm), judged against the part spec's surface criteria, shown in the
unrolled picture where they are, and kept with the record."""

from __future__ import annotations

import asyncio
import math
from types import SimpleNamespace

import numpy as np
import pytest

from sim.world import STANDARD_SAMPLE, HoleTruth, PartTruth, SurfaceDefect, defect_truth_place
from station.parts.loader import parse_part
from station.runtime import open_session
from station.store import Store
from surface_cases import band_spec

TIME_SCALE = 50.0

SPEC = band_spec("ZDZG-22.2-12.3851")

#: a pore over the seal's limit, pores elsewhere (one where four frames' cells meet, one
#: small, two close together), a scratch across a seam between rings, and a burr and a
#: chip at the holes (the
#: band's 4 rings are centred at 67.12, 73.71, 80.29 and 86.88 mm, its 6 columns at 0,
#: 60, ... deg: cells meet at 70.41, 77.0 and 83.59 mm and at 30, 90, ... deg)
DEFECTS = (
    SurfaceDefect("seal_pore", "pore", 0.28, 0.21, axial_mm=66.4, angle_deg=40.0, seed=3),
    SurfaceDefect("corner_pore", "pore", 0.25, 0.2, axial_mm=70.45, angle_deg=30.3, seed=7),
    SurfaceDefect("small_pore", "pore", 0.15, 0.12, axial_mm=78.2, angle_deg=200.0, seed=4),
    SurfaceDefect("seam_scratch", "scratch", 1.2, 0.035, axial_mm=83.6, angle_deg=300.0, orientation_deg=75.0,
                  seed=5),
    # two pores closer than the sightings' merging distance: told apart re-centred
    SurfaceDefect("pair_pore_a", "pore", 0.18, 0.15, axial_mm=75.0, angle_deg=150.0, seed=11),
    SurfaceDefect("pair_pore_b", "pore", 0.18, 0.15, axial_mm=75.4, angle_deg=150.0, seed=12),
    SurfaceDefect("burr", "burr", 0.15, 0.05, hole="hole_1", at_deg=90.0, seed=6),
    SurfaceDefect("chip", "chip", 0.08, 0.04, hole="hole_2", at_deg=200.0, seed=8),
)


@pytest.mark.parametrize("calibrated", [True, False], ids=["calibrated lens", "no calibration: re-centred"])
def test_a_part_with_seeded_defects_is_scanned_whole_and_every_defect_is_at_its_place(tmp_path, calibrated):
    """With the camera's calibration (the simulated station's default) each defect is
    measured where a coverage frame saw it, undistorted; without one (``[simulation]
    calibration = false``) each is measured again in a frame centred on it. Either way
    within 0.05 mm; the picture's pixels are right to 0.05 mm only with the lens known
    (without, a seam may show the distortion: ~0.15 mm)."""
    truth, out = _inspect(tmp_path, calibrated, DEFECTS)
    sf = out.surface
    assert sf is not None and sf.coverage == 1.0 and sf.frames == 4 * 6
    # every seeded defect found once, of its kind, within 0.05 mm of its true place
    by_truth = {d.truth["name"]: d for d in sf.defects if d.truth}
    assert sorted(by_truth) == sorted(t.name for t in DEFECTS), [d.to_json(True) for d in sf.defects]
    assert len(sf.defects) == len(DEFECTS), "a defect reported twice, or a false one"
    for t in DEFECTS:
        d = by_truth[t.name]
        assert d.kind == t.kind
        assert d.truth["place_error_mm"] <= 0.05, d.to_json(True)
        assert abs(d.length_mm - t.length_mm) <= max(0.1 * t.length_mm, 0.02), d.to_json(True)
        assert d.truth["place_error_mm"] <= d.position_u_mm + 0.01
    assert by_truth["burr"].hole == "hole_1" and by_truth["chip"].hole == "hole_2"
    assert by_truth["seal_pore"].zone == "seal" and by_truth["small_pore"].zone is None
    # the criteria: the seal's pore and hole_1's burr break theirs, nothing else
    chars = {c.id: c for c in out.characteristics}
    assert not chars["surface.seal.pore"].passed and chars["surface.seal.pore"].measured == by_truth["seal_pore"].length_mm
    assert not chars["hole_1.burr"].passed
    assert chars["surface.pore"].passed and chars["hole_2.chip"].passed and chars["surface.scratch"].passed
    assert out.result == "fail" and "surface.seal.pore" in out.reason and "hole_1.burr" in out.reason
    assert sorted(d.rejects for d in sf.defects if d.rejects) == ["hole_1.burr", "surface.seal.pore"]
    # the pore under 0.55 mm was never taken for a hole
    assert not [f for f in out.findings if f.kind == "unexpected_hole"], out.findings
    # the picture shows each pore where it really is: the centroid of the dark pixels
    # round its true place (a scratch is thinner than the picture's pixel)
    pic = sf.picture
    img = pic.image.astype(np.float32)
    level = float(np.median(img))
    for t in DEFECTS:
        if t.kind != "pore":
            continue
        ax, an = defect_truth_place(truth, t)
        x, y = pic.px_of(ax, an)
        r = int(round(0.19 / pic.mm_per_px))  # the pair's pores lie 0.4 mm apart
        x0, y0 = int(round(x)) - r, int(round(y)) - r
        win = img[y0:y0 + 2 * r + 1, x0:x0 + 2 * r + 1]
        dark = np.clip(level - 45 - win, 0, None)
        assert dark.sum() > 0, t.name  # the pore is in the picture
        yy, xx = np.mgrid[0:win.shape[0], 0:win.shape[1]]
        off_mm = np.hypot(x0 + (dark * xx).sum() / dark.sum() - x, y0 + (dark * yy).sum() / dark.sum() - y) \
            * pic.mm_per_px
        assert off_mm <= (0.05 if calibrated else 0.2), (t.name, off_mm)
    # the cycle: the coverage scan's machine time against its physical limit. Its figure
    # is the bench's (``station bench surface``: ~1.1-1.2 on a quiet machine); here the
    # bound only catches a stall, since the ratio follows the machine's load (a loaded CI
    # run read 3.27 on the re-centred scan, every defect found at its place)
    sc = out.cycle["surface"]
    assert sc["limit_frames"] == sf.frames and 1.0 < sc["ratio"] < 6.0
    # kept with the record
    store = Store.open(None, data_dir=tmp_path / "data")
    try:
        rec = store.get(out.id)
        assert rec.surface is not None and len(rec.surface["defects"]) == len(DEFECTS)
        assert {d["id"] for d in rec.surface["defects"]} == {d.id for d in sf.defects}
        assert [i.subject for i in rec.images].count("surface") == 1
    finally:
        store.close()


#: two dark discs of a hole's size at none of the part's holes: a 1.1 mm pore and a
#: 0.7 mm drilling the drawing does not have (half the bore away from the holes)
STRAY_PORE = SurfaceDefect("large_pore", "pore", 1.1, 0.9, axial_mm=75.0, angle_deg=100.0, orientation_deg=30.0,
                           seed=31)
STRAY_HOLE = HoleTruth("stray", 82.0, 200.0, 0.7)


@pytest.mark.parametrize("calibrated", [True, False], ids=["calibrated lens", "no calibration: re-centred"])
def test_a_dark_disc_at_none_of_the_part_s_holes_is_reported_as_a_pore(tmp_path, calibrated):
    """The coverage frames are told where the part's holes are (the bore scan found
    them): a 1.1 mm pore, over the least hole's size, and a 0.7 mm drilling where the
    drawing has none are each reported as a pore of their size at their place, with a
    note, and fail the pore criterion; the part's own holes are no pores, and the pore's
    outline gives no burr or chip. Without the lens's calibration the holes' places in a
    frame carry its distortion (up to ~0.2 mm in a corner), within their reach."""
    truth, out = _inspect(tmp_path, calibrated, (STRAY_PORE,), extra_holes=(STRAY_HOLE,))
    sf = out.surface
    pores = {d.truth["name"] if d.truth else "drilling": d for d in sf.defects if d.kind == "pore"}
    assert sorted(pores) == ["drilling", "large_pore"] and len(sf.defects) == 2, [d.to_json(True) for d in sf.defects]
    big = pores["large_pore"]
    assert big.truth["place_error_mm"] <= 0.05, big.to_json(True)
    assert abs(big.length_mm - big.truth["length_mm"]) <= 0.1 * big.truth["length_mm"], big.to_json(True)
    hole = pores["drilling"]
    assert abs(hole.axial_mm - 82.0) <= 0.05 and abs(math.radians(hole.angle_deg - 200.0) * 11.1) <= 0.05
    assert abs(hole.length_mm - 0.7) <= 0.07 and abs(hole.width_mm - 0.7) <= 0.07, hole.to_json(True)
    assert sum("the size of a hole, lies at none of the part's holes" in n for n in sf.notes) == 2, sf.notes
    chars = {c.id: c for c in out.characteristics}
    assert not chars["surface.pore"].passed and chars["surface.pore"].measured == big.length_mm
    assert chars["hole_1.burr"].passed and chars["hole_2.chip"].passed
    assert [h.name for h in out.holes if h.found] == ["hole_1", "hole_2"]


def _inspect(tmp_path, calibrated: bool, defects, extra_holes=()):
    """The standard sample with ``defects`` in the twin's world (and ``extra_holes``
    drilled where the drawing has none), inspected whole with its surface on the
    simulated station, with the lens's calibration or without one."""
    spec = parse_part(SPEC, "surface-test.toml")
    truth = PartTruth(STANDARD_SAMPLE.part_number, STANDARD_SAMPLE.bore_diameter_mm,
                      STANDARD_SAMPLE.holes + tuple(extra_holes), defects)
    config = None
    if not calibrated:
        config = tmp_path / "station.toml"
        config.write_text('[station]\nmode = "simulated"\n[simulation]\ncalibration = false\n')

    async def go():
        async with open_session(config, time_scale=TIME_SCALE, data_dir=tmp_path / "data",
                                world=SimpleNamespace(part=truth)) as s:
            assert (s.station.camera_calibration is not None) == calibrated
            return await s.inspect(spec, "SN-SURFACE")

    out = asyncio.run(asyncio.wait_for(go(), timeout=400))
    assert out.state == "complete", out.reason
    return truth, out


#: scratches no frame sees whole (a frame is 12.8 x 10.24 mm): one round the bore across
#: 0 deg and three columns' seams, one along it across two rings' seams, and one that
#: runs out of the band (62-92 mm) at its far end
LONG = (
    SurfaceDefect("round", "scratch", 20.0, 0.04, axial_mm=73.0, angle_deg=0.0, orientation_deg=5.0, seed=21),
    SurfaceDefect("along", "scratch", 15.0, 0.035, axial_mm=77.0, angle_deg=100.0, orientation_deg=80.0, seed=22),
    SurfaceDefect("out", "scratch", 12.0, 0.04, axial_mm=90.0, angle_deg=200.0, orientation_deg=70.0, seed=23),
)


@pytest.mark.parametrize("calibrated", [True, False], ids=["calibrated lens", "no calibration: ends re-centred"])
def test_a_scratch_longer_than_a_frame_is_reported_once_with_its_whole_length(tmp_path, calibrated):
    """Each long scratch is one defect joined from the pieces the frames' borders cut, its
    length within the issue's 10 % and its centre line's middle within 0.05 mm; the one that leaves the
    band is measured as far as the band shows, and the result says so."""
    truth, out = _inspect(tmp_path, calibrated, LONG)
    sf = out.surface
    by_truth = {d.truth["name"]: d for d in sf.defects if d.truth}
    assert sorted(by_truth) == sorted(t.name for t in LONG) and len(sf.defects) == len(LONG), \
        [d.to_json(True) for d in sf.defects]
    for name in ("round", "along"):
        d = by_truth[name]
        assert d.kind == "scratch" and d.frames >= 3
        assert abs(d.length_mm - d.truth["length_mm"]) <= 0.1 * d.truth["length_mm"], d.to_json(True)
        assert abs(d.width_mm - d.truth["width_mm"]) <= max(0.1 * d.truth["width_mm"], 0.02), d.to_json(True)
        # its place is the middle of its centre line, as for any scratch; the truth's
        # centroid of area lies along it by what the width's variation moves (~0.05 mm)
        assert d.truth["middle_error_mm"] <= 0.05 and d.truth["place_error_mm"] <= d.position_u_mm, d.to_json(True)
    out_d = by_truth["out"]
    t = next(t for t in LONG if t.name == "out")
    start = t.axial_mm - 0.5 * t.length_mm * math.sin(math.radians(t.orientation_deg))
    seen = (92.0 - start) / math.sin(math.radians(t.orientation_deg))  # what of it lies in the band
    assert abs(out_d.length_mm - seen) <= 0.3, (out_d.length_mm, seen)
    assert any("runs out of the scanned band" in n for n in sf.notes), sf.notes
    assert not any("not seen again re-centred" in n for n in sf.notes), sf.notes
    chars = {c.id: c for c in out.characteristics}
    assert not chars["surface.scratch"].passed and chars["surface.scratch"].measured == max(d.length_mm for d in sf.defects)
