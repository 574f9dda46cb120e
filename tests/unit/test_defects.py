"""Surface defects (issue 23): the twin renders them with their truth, the vision stage
finds and measures them, clean walls and clean rims give none, the CLI's JSON.

Frames are 640 x 512 (a quarter of the station's) to keep the file fast; the bench
(``station bench defects``) judges the full envelope on full frames.
"""

from __future__ import annotations

import asyncio
import hashlib
import json
from dataclasses import replace

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from sim.camera.defects import DefectSpec, geometry, random_defect_frame, random_defects
from sim.camera.render import (FrameParams, HoleSpec, psf_kernel, random_frame, random_params, render_frame,
                               wall_patch)
from station.bench.defects import above_limit, match
from station.cli import app
from station.vision.defects import detect_defects
from station.vision.defects.common import on_groove_line
from station.vision.defects.config import Defect, DefectConfig
from station.vision.defects.rims import groove_cover
from station.vision.defects.wall import groove_profiles
from station.vision.grooves import honing_directions

MM_PER_PX = 0.010
SMALL = dict(width_px=640, height_px=512)


def _within(measured_mm: float, truth_mm: float) -> bool:
    """The issue's size tolerance: 10 % or 0.02 mm, whichever is larger."""
    return abs(measured_mm - truth_mm) <= max(0.1 * truth_mm, 0.02)


# ---------------------------------------------------------------- the renderer
def test_a_honing_whose_grooves_stop_short_breaks_out_that_share_of_them():
    """``groove_breaks``: the share of each groove family's length missing, cut off at steps
    (a random field on cells across and along the lines, thresholded); 0 leaves the frame
    as it was, and a share outside [0, 1) is refused."""
    base = FrameParams(**SMALL)
    f0 = render_frame(base, [], seed=5, keep_grooves=True)
    again = render_frame(FrameParams(**SMALL, groove_breaks=0.0), [], seed=5, keep_grooves=True)
    assert np.array_equal(f0.image, again.image)
    grooved0 = float((f0.grooves < -0.02).mean())
    for share in (0.25, 0.5):
        f = render_frame(FrameParams(**SMALL, groove_breaks=share), [], seed=5, keep_grooves=True)
        kept = float((f.grooves < -0.02).mean()) / grooved0
        # two families, each (1 - share) of its length left; where they cross either will do
        assert abs(kept - (1.0 - share)) < 0.12, (share, kept)
    with pytest.raises(ValueError, match="groove_breaks"):
        render_frame(FrameParams(**SMALL, groove_breaks=1.0), [], seed=5)


def test_the_twin_spreads_the_light_by_a_defocus_disc_or_a_smear_on_top_of_the_gaussian():
    """``FrameParams.psf_disc_px`` / ``psf_smear_px``: a lens whose spread is no Gaussian (a
    defocused lens's uniform disc, a smear from motion during the exposure), convolved
    with the frame after the Gaussian blur and the holes' exact edges; none by default."""
    assert psf_kernel(FrameParams()) is None

    def moments(k):
        k = k.astype(np.float64)
        y, x = np.mgrid[0:k.shape[0], 0:k.shape[1]]
        mx, my = (k * x).sum(), (k * y).sum()
        return (k.sum(), mx - (k.shape[1] - 1) / 2, my - (k.shape[0] - 1) / 2, (k * (x - mx) ** 2).sum(),
                (k * (y - my) ** 2).sum(), (k * (x - mx) * (y - my)).sum())

    for r in (1.5, 2.5, 4.0):
        total, dx, dy, vx, vy, cxy = moments(psf_kernel(FrameParams(psf_disc_px=r)))
        # a uniform disc's variance per axis, r^2 / 4, and what its sampling by the pixels'
        # areas adds (0.02-0.14 px^2 with the disc's edge's phase on the grid; 1/12 on average)
        assert total == pytest.approx(1.0, abs=1e-5) and abs(dx) < 1e-6 and abs(dy) < 1e-6 and abs(cxy) < 1e-6
        assert r * r / 4 <= vx <= r * r / 4 + 1 / 6 and vy == pytest.approx(vx, rel=1e-6), (r, vx)
    for length, deg in ((5.0, 90.0), (4.0, 0.0)):
        total, dx, dy, vx, vy, cxy = moments(psf_kernel(FrameParams(psf_smear_px=length, psf_smear_deg=deg)))
        along, across = (vy, vx) if deg == 90.0 else (vx, vy)
        # a uniform line's variance, length^2 / 12, spread onto the pixels (at most 1/6 more)
        assert length**2 / 12 <= along <= length**2 / 12 + 1 / 6 + 1e-6 and across < 1e-9, (length, along, across)
    _, _, _, vx, vy, cxy = moments(psf_kernel(FrameParams(psf_smear_px=6.0, psf_smear_deg=30.0)))
    assert np.degrees(0.5 * np.arctan2(2 * cxy, vx - vy)) == pytest.approx(30.0, abs=1.5)
    with pytest.raises(ValueError, match="psf_disc_px"):
        psf_kernel(FrameParams(psf_disc_px=-1.0))

    # the frame: noise-free, the disc's frame is the Gaussian frame convolved with the disc
    # (holes, wall and defects alike), to the 8-bit rounding of the two
    p = FrameParams(**SMALL, gain_e_per_dn=1e9, read_noise_dn=0.0, vignetting=0.0)
    holes = [HoleSpec(300.4, 250.7, 60.0)]
    disc = FrameParams(**{**p.__dict__, "psf_disc_px": 2.5})
    plain = render_frame(p, holes, seed=3).image.astype(np.float32)
    spread = render_frame(disc, holes, seed=3).image.astype(np.float32)
    expected = cv2.filter2D(plain, -1, psf_kernel(disc), borderType=cv2.BORDER_REFLECT)
    assert np.abs(spread - expected).max() <= 1.0
    assert np.abs(spread - plain).max() > 10.0  # ... and it is not the plain frame


@pytest.mark.parametrize("psf", [dict(psf_disc_px=2.5), dict(psf_smear_px=4.0, psf_smear_deg=60.0)],
                         ids=["defocus-disc", "smear"])
def test_defects_are_found_and_clean_walls_stay_clean_under_a_lens_spread_that_is_no_gaussian(psf):
    """The detector's blur is a Gaussian's sigma, read from the marks' and holes' edges; a
    defocused lens (a uniform disc of 2.5 px on top of the 0.8-2 px Gaussian) or a 4 px
    smear spreads the light otherwise. Every defect above the limits is still found as
    its kind, all but one with its length in tolerance (91014's 0.173 mm chip reads 0.153
    under the disc), and the clean walls and rims give nothing."""
    found_n = total = in_tol = 0
    for seed in range(91010, 91016):
        f = random_defect_frame(seed, {"pore": 1, "scratch": 1, "burr": 1, "chip": 1}, n_holes=1, **SMALL, **psf)
        pairs, false = match(f.defects, detect_defects(f.image, MM_PER_PX), MM_PER_PX)
        assert not false, (seed, false)
        for t, d in pairs:
            if above_limit(t.kind, t.length_mm, t.width_mm):
                total += 1
                assert d is not None and d.kind == t.kind, (seed, t, d)
                found_n += 1
                in_tol += _within(d.length_mm, t.length_mm)
    assert total >= 18 and found_n == total and in_tol >= total - 1
    for seed in range(92010, 92014):
        f = random_defect_frame(seed, {}, **SMALL, **psf)
        found = detect_defects(f.image, MM_PER_PX)
        assert found == [], (seed, [(d.kind, d.x_px, d.y_px, d.length_mm) for d in found])


def test_frames_without_defects_are_byte_identical_to_before_defects_existed(monkeypatch):
    # sha1 of random_frame's images before defects were added to the renderer (the vision
    # benches' frames): any change to the wall, the holes or the noise's random stream fails.
    # Frame 1 has no hole; frame 1000's holes have been blurred before the pixels integrate
    # them since round 17 (``render.EDGE_FINE``), so its hash is that of the renderer before,
    # which the same module still is with the edge's fine grid off and 16 supersamples
    import sim.camera.render as render

    assert hashlib.sha1(random_frame(1).image.tobytes()).hexdigest() == "05c8661898c5fbd25b1022b9515d8658141753eb"
    now = random_frame(1000)
    monkeypatch.setattr(render, "EDGE_FINE", 1)
    monkeypatch.setattr(render, "SUPERSAMPLE", 16)
    before = random_frame(1000)
    assert hashlib.sha1(before.image.tobytes()).hexdigest() == "ae9d3b4b06dbb0ffddbf2592676f8d6ce68d0d3a"
    # ... and round 17 changed only the pixels within the blur's reach of a hole's rim
    changed = now.image != before.image
    assert changed.any()
    yy, xx = np.mgrid[0 : changed.shape[0], 0 : changed.shape[1]]
    reach = 4 * now.params.blur_sigma_px + 3
    near = np.zeros_like(changed)
    for h in now.holes:
        near |= np.abs(np.hypot(xx - h.image_x_px, yy - h.image_y_px) - h.diameter_px / 2) <= reach
    assert not (changed & ~near).any()
    assert np.abs(now.image.astype(int) - before.image.astype(int)).max() <= 2


def test_defects_change_only_their_own_pixels():
    p = FrameParams(**SMALL)
    holes = [HoleSpec(200.3, 250.7, 70.0)]
    defects = [DefectSpec("pore", 450.2, 150.6, 25.0, 20.0, 30.0, 0.3, shape_seed=4),
               DefectSpec("burr", length_px=15.0, width_px=5.0, angle_deg=40.0, hole=0, shape_seed=5)]
    plain = render_frame(p, holes, seed=9)
    with_defects = render_frame(p, holes, seed=9, defects=defects)
    changed = np.argwhere(plain.image != with_defects.image)
    assert changed.size
    # the blur (1.2 px) spreads a change ~4 sigma; nothing moves further from a defect's box
    boxes = [geometry(d, holes).bbox_ideal(5.0) for d in defects]
    inside = [any(x0 <= x <= x1 and y0 <= y <= y1 for x0, y0, x1, y1 in boxes) for y, x in changed]
    assert all(inside)


def test_random_pores_may_lie_on_a_scratchs_line_and_by_default_keep_clear():
    """``random_defects(pores_on_scratches=...)``: each pore drawn on a scratch lies on its
    chord's middle 70 % and is painted over it; by default every pore keeps clear of every
    scratch, and the draw is what it was."""
    params = FrameParams(**SMALL)
    kinds = {"pore": 2, "scratch": 1}
    for seed in range(8):
        on = random_defects(np.random.default_rng(seed), params, [], kinds, MM_PER_PX, pores_on_scratches=1.0)
        (scratch,) = [d for d in on if d.kind == "scratch"]
        pores = [d for d in on if d.kind == "pore"]
        assert pores and on.index(scratch) < min(on.index(p) for p in pores)  # painted after it
        a = np.deg2rad(scratch.angle_deg)
        for p in pores:
            dx, dy = p.x_px - scratch.x_px, p.y_px - scratch.y_px
            assert abs(-dx * np.sin(a) + dy * np.cos(a)) < 1e-6
            assert abs(dx * np.cos(a) + dy * np.sin(a)) <= 0.35 * scratch.length_px + 1e-6
        clear = random_defects(np.random.default_rng(seed), params, [], kinds, MM_PER_PX)
        assert clear == random_defects(np.random.default_rng(seed), params, [], kinds, MM_PER_PX,
                                       pores_on_scratches=0.0)
        boxes = {id(d): geometry(d, []).bbox_ideal(0.0) for d in clear}
        for p in (d for d in clear if d.kind == "pore"):
            for q in (d for d in clear if d.kind == "scratch"):
                bp, bq = boxes[id(p)], boxes[id(q)]
                assert bp[2] < bq[0] or bq[2] < bp[0] or bp[3] < bq[1] or bq[3] < bp[1]
    with pytest.raises(ValueError, match="pores_on_scratches"):
        random_defects(np.random.default_rng(0), params, [], kinds, MM_PER_PX, pores_on_scratches=1.5)


def test_pore_truth_is_its_outline():
    spec = DefectSpec("pore", 100.0, 80.0, 30.0, 22.0, 20.0, shape_seed=7)
    g = geometry(spec, [])
    t = g.truth()
    # the outline is scaled so its greatest dimension is the spec's, its centroid on the spec's centre
    assert t.length_px == pytest.approx(30.0, abs=0.05)
    yy, xx = np.mgrid[40:121, 50:151].astype(float)
    sub = (np.arange(8) + 0.5) / 8 - 0.5
    area = sum(g.inside(xx + dx, yy + dy).sum() for dx in sub for dy in sub) / 64.0
    assert area == pytest.approx(t.area_px2, rel=0.01)
    inside = g.inside(xx, yy)
    assert xx[inside].mean() == pytest.approx(100.0, abs=0.2) and yy[inside].mean() == pytest.approx(80.0, abs=0.2)


# ---------------------------------------------------------------- detection and measurement
@pytest.fixture(scope="module")
def one_of_each():
    """A station-like frame (blur 1.4 px, grooves 6 %, grain 2 %, 30 e-/DN) with a hole
    and one defect of each kind above the bench's limits."""
    p = FrameParams(wall_level_dn=150.0, hole_level_dn=50.0, groove_depth=0.06, grain=0.02, blotch=0.03,
                    blur_sigma_px=1.4, gain_e_per_dn=30.0, read_noise_dn=1.5, vignetting=0.2, **SMALL)
    holes = [HoleSpec(220.4, 300.2, 75.0)]
    defects = [
        DefectSpec("pore", 470.3, 120.6, 30.0, 24.0, 35.0, 0.35, shape_seed=11),
        DefectSpec("scratch", 480.0, 380.0, 90.0, 3.0, 100.0, 0.6, shape_seed=12),
        DefectSpec("burr", length_px=14.0, width_px=4.0, angle_deg=300.0, reflectance=1.0, hole=0, shape_seed=13),
        DefectSpec("chip", length_px=12.0, width_px=3.5, angle_deg=120.0, hole=0, shape_seed=14),
    ]
    f = render_frame(p, holes, seed=21, defects=defects)
    f.defects = [d.with_scale(MM_PER_PX) for d in f.defects]
    return f, detect_defects(f.image, MM_PER_PX)


@pytest.mark.parametrize("kind", ["pore", "scratch", "burr", "chip"])
def test_each_kind_is_found_and_measured(one_of_each, kind):
    f, found = one_of_each
    pairs, false = match(f.defects, found, MM_PER_PX)
    assert not false, [(found[i].kind, found[i].x_px, found[i].y_px) for i in false]
    ((truth, d),) = [(t, d) for t, d in pairs if t.kind == kind]
    assert d is not None and d.kind == kind
    assert _within(d.length_mm, truth.length_mm), (d.length_mm, truth.length_mm)
    assert _within(d.width_mm, truth.width_mm), (d.width_mm, truth.width_mm)
    # and within the stated uncertainty (k = 3), which is tighter than the tolerance for
    # small defects: a rim height off by 30 % passes 0.02 mm but not this
    assert abs(d.length_px - truth.length_px) <= 3 * d.length_u_px, (d.length_px, truth.length_px, d.length_u_px)
    assert abs(d.width_px - truth.width_px) <= 3 * d.width_u_px, (d.width_px, truth.width_px, d.width_u_px)
    assert np.hypot(d.x_px - truth.x_px, d.y_px - truth.y_px) < 3.0
    assert d.size_mm == d.length_mm and d.size_u_mm > 0 and 0.5 < d.confidence <= 1.0
    if kind in ("burr", "chip"):
        assert d.hole == 0
        # the height from the area-true rim profile: on this frame within 0.8 px (0.008 mm);
        # an integral that lost 30 % of a defect's area reads the chip 1.1 px shallow
        assert abs(d.width_px - truth.width_px) <= 0.8


def _found_as_itself(params: FrameParams, holes: list, spec: DefectSpec, seed: int):
    """One defect rendered alone, found as its own kind with nothing else: (truth, detection)."""
    f = render_frame(params, holes, seed=seed, defects=[spec])
    f.defects = [d.with_scale(MM_PER_PX) for d in f.defects]
    found = detect_defects(f.image, MM_PER_PX)
    pairs, false = match(f.defects, found, MM_PER_PX)
    assert not false, [(found[i].kind, found[i].width_px) for i in false]
    ((truth, d),) = pairs
    assert d is not None and d.kind == spec.kind, d
    return truth, d


@pytest.mark.parametrize("floor_share", [1.0, 0.7])
def test_a_deep_chip_is_as_deep_as_it_is_whatever_its_floors_light(floor_share):
    """A chip's broken face slopes into the hole in shadow, but may be lit above the
    hole's level: its floor then stands at 0.7 of the wall-to-hole step, below the rim
    edge's crossing (0.75), and an area-true height that took the floor at the hole's
    level and integrated only to the edge read a 7 px notch 3-4 px shallow (dev frames:
    6.5 px read 3.2). The floor's own level is read where the notch is deep enough."""
    p = FrameParams(wall_level_dn=150.0, hole_level_dn=50.0, groove_depth=0.05, grain=0.02, blotch=0.02,
                    blur_sigma_px=1.3, gain_e_per_dn=30.0, read_noise_dn=1.5, vignetting=0.1, **SMALL)
    holes = [HoleSpec(300.4, 256.2, 90.0)]
    # the chip's level as a share of the wall's: the hole's (50/150) or 70 % of the step
    refl = (150.0 - floor_share * 100.0) / 150.0
    chip = DefectSpec("chip", length_px=10.0, width_px=7.0, angle_deg=35.0, reflectance=refl, hole=0, shape_seed=3)
    truth, d = _found_as_itself(p, holes, chip, seed=5)
    assert abs(d.width_px - truth.width_px) <= 1.0, (d.width_px, truth.width_px)
    assert _within(d.length_mm, truth.length_mm), (d.length_mm, truth.length_mm)


@pytest.mark.parametrize("reflectance", [0.9, 1.15])
def test_a_burrs_height_does_not_scale_with_its_brightness(reflectance):
    """A burr's torn metal is 0.9-1.15 of the wall's level: at a hole of 40 % contrast that
    is a share of 0.25 to -0.4 of the wall-to-hole step, and a height read from the darkness
    it takes out of the hole (area-true) scaled with it (0.77-1.4x). Its rays' edges move by
    a quarter of the blur at most: the height is their mean depth between its ends."""
    p = FrameParams(wall_level_dn=150.0, hole_level_dn=90.0, groove_depth=0.05, grain=0.02, blotch=0.02,
                    blur_sigma_px=1.3, gain_e_per_dn=30.0, read_noise_dn=1.5, vignetting=0.1, **SMALL)
    holes = [HoleSpec(300.4, 256.2, 90.0)]
    burr = DefectSpec("burr", length_px=20.0, width_px=7.0, angle_deg=215.0, reflectance=reflectance, hole=0,
                      shape_seed=8)
    truth, d = _found_as_itself(p, holes, burr, seed=6)
    assert abs(d.width_px - truth.width_px) <= 0.8, (d.width_px, truth.width_px)
    assert abs(d.width_px - truth.width_px) <= 2 * d.width_u_px


def test_small_faint_pores_on_deep_grooves_keep_their_size():
    """A small pore's contrast, size and edge blur trade off: on 4 % grain and 8 % grooves,
    12 px pores of 46 % contrast fitted an edge blur of 2.3-2.7 px with the blur free, their
    contrast ran to its bound and they read 30-40 % small (fresh bench seeds). The frame's
    hole gives the camera's blur, and the outline is read with it held: every length within
    the tolerance (two of these twelve read 7.1 and 8.5 px before)."""
    p = FrameParams(wall_level_dn=120.0, hole_level_dn=45.0, groove_depth=0.08, grain=0.04, blotch=0.03,
                    blur_sigma_px=1.35, gain_e_per_dn=30.0, read_noise_dn=1.5, vignetting=0.2, **SMALL)
    holes = [HoleSpec(160.4, 300.2, 80.0)]
    width_errors = []
    for k in range(12):
        pore = DefectSpec("pore", 420.3 + 40 * (k % 3), 120.6 + 90 * (k // 3), 12.0, 9.0, 20.0 * k, 0.54,
                          shape_seed=30 + k)
        truth, d = _found_as_itself(p, holes, pore, seed=40 + k)
        assert _within(d.length_mm, truth.length_mm), (k, d.length_px, truth.length_px)
        width_errors.append(abs(d.width_px - truth.width_px))
    assert np.median(width_errors) <= 1.0, width_errors


def test_random_frames_above_the_limits_are_found_within_tolerance():
    """Frames of the bench's kind (seeds apart from the dev seeds and the bench's), each
    defect above the limits found with its kind and its length right."""
    found_n = total = 0
    for seed in (91001, 91002, 91003):
        f = random_defect_frame(seed, {"pore": 1, "scratch": 1, "burr": 1, "chip": 1}, n_holes=1, **SMALL)
        pairs, false = match(f.defects, detect_defects(f.image, MM_PER_PX), MM_PER_PX)
        assert not false
        for t, d in pairs:
            limit = {"pore": (0.2, 0), "scratch": (0.2, 0), "burr": (0.05, 0.02), "chip": (0.05, 0.02)}[t.kind]
            if t.length_mm >= limit[0] and t.width_mm >= limit[1]:
                total += 1
                if d is not None and d.kind == t.kind and _within(d.length_mm, t.length_mm):
                    found_n += 1
    assert total >= 6 and found_n == total


def test_sizes_are_sub_pixel_not_pixel_counts():
    """Pores 0.5 px apart in size measure 0.5 px apart (within 0.25 px): the size comes
    from the integrated darkening, which a thresholded blob's pixel count cannot give."""
    p = FrameParams(groove_depth=0.0, grain=0.01, blotch=0.0, blur_sigma_px=1.5, gain_e_per_dn=60.0,
                    read_noise_dn=0.5, vignetting=0.0, width_px=256, height_px=256)
    lengths = []
    for length in (20.0, 20.5, 21.0, 21.5):
        spec = DefectSpec("pore", 128.3, 127.8, length, length * 0.8, 10.0, 0.3, shape_seed=2)
        f = render_frame(p, [], seed=5, defects=[spec])
        (d,) = detect_defects(f.image, MM_PER_PX, holes=[])
        lengths.append(d.length_px)
    steps = np.diff(lengths)
    assert np.all(np.abs(steps - 0.5) < 0.25), lengths


def test_a_ragged_pores_greatest_diameter_is_read_through_the_blur():
    """The blur spreads a pore's darkening across directions round its centre, which
    keeps only part of its outline's harmonics (h_k ~ exp(-k^2 s^2 / 2 R^2)): read as
    blurred, ragged pores of 14-35 px read their greatest Feret diameter 0.5 px short
    on average and their width 0.2 px short, with their area right. Each harmonic is
    now divided by what the blur kept of it: over 48 pores, half with a hole giving the
    blur, the mean errors are within 0.25 px of nothing."""
    p = FrameParams(wall_level_dn=120.0, hole_level_dn=40.0, groove_depth=0.04, grain=0.02, blotch=0.02,
                    blur_sigma_px=1.4, gain_e_per_dn=40.0, read_noise_dn=1.0, vignetting=0.1, **SMALL)
    length_err, width_err = [], []
    for k in range(6):
        size = 14.0 + k
        pores = [DefectSpec("pore", 140.3 + 120 * (j % 4), 110.6 + 140 * (j // 4), size + 2 * j, (size + 2 * j) * 0.75,
                            25.0 * k + 40 * j, 0.4, shape_seed=500 + 10 * k + j) for j in range(8)]
        f = render_frame(p, [HoleSpec(560.0, 440.0, 80.0)] if k % 2 else [], seed=700 + k, defects=pores)
        truths = [d.with_scale(MM_PER_PX) for d in f.defects]
        pairs, false = match(truths, detect_defects(f.image, MM_PER_PX), MM_PER_PX)
        assert not false, k
        for t, d in pairs:
            assert d is not None and d.kind == "pore", (k, t.x_px, t.y_px)
            length_err.append(d.length_px - t.length_px)
            width_err.append(d.width_px - t.width_px)
    assert len(length_err) == 48
    assert abs(np.mean(length_err)) <= 0.25, np.mean(length_err)
    assert abs(np.mean(width_err)) <= 0.25, np.mean(width_err)


def _the_one_scratch_found(p: FrameParams, spec: DefectSpec, seed: int):
    """``spec`` rendered alone on a wall of ``p``: (its truth, the one defect found), which
    must be a scratch matched to it with nothing else reported."""
    f = render_frame(p, [], seed=seed, defects=[spec])
    (t,) = [d.with_scale(MM_PER_PX) for d in f.defects]
    found = detect_defects(f.image, MM_PER_PX)
    pairs, false = match([t], found, MM_PER_PX)
    d = pairs[0][1]
    assert d is not None and d.kind == "scratch" and not false, (seed, [(e.kind, e.length_mm) for e in found])
    return t, d


def test_a_square_ended_scratch_is_as_long_as_it_is():
    """A scratch's end is where its amplitude along it crosses half its local height. That
    height was read 1.2 blur inside the end, where the blurred step has reached only
    88-97 % of its plateau, so the crossing sat outside the end: sixteen square-ended
    scratches of 40-190 px on a clean wall read 0.55 px long on average (sd 0.16 px).
    The height is now divided by what the step reaches there: the mean within 0.2 px."""
    p = FrameParams(wall_level_dn=120.0, hole_level_dn=40.0, groove_depth=0.0, grain=0.005, blotch=0.0,
                    blur_sigma_px=1.3, gain_e_per_dn=60.0, read_noise_dn=0.5, vignetting=0.0, **SMALL)
    errors = []
    for k in range(16):
        spec = DefectSpec("scratch", 320.3, 256.2, 40.0 + 10 * k, 3.0 + (k % 4), 75.0 + 7 * k, 0.6, shape_seed=900 + k)
        f = render_frame(p, [HoleSpec(80.0, 80.0, 70.0)], seed=50 + k, defects=[spec])
        (t,) = [d.with_scale(MM_PER_PX) for d in f.defects]
        pairs, false = match([t], detect_defects(f.image, MM_PER_PX), MM_PER_PX)
        d = pairs[0][1]
        assert d is not None and d.kind == "scratch" and not false, k
        errors.append(d.length_px - t.length_px)
    assert abs(np.mean(errors)) <= 0.2, errors


def test_long_scratches_in_frames_without_a_hole_keep_their_ends_width_and_place():
    """The camera twin's condition (``FrameParams()``: grooves 10 % deep, 10 e-/DN, blur
    1.2 px), no hole to give the blur, one scratch of 1.5-2 mm near the centre crossing
    the hatch by >= 10 deg: its length within 10 %, its width within 10 % or 0.02 mm, its
    centroid within 0.05 mm. The whole-surface scan found such scratches with an end lost
    or carried on along a groove (lengths 10-30 % off, centroids 0.1-0.26 mm along the
    scratch) and widths a third of the truth (the blur read from the scratch's ends 0.4 px
    high); the first version failed 2 of these 12 frames (lengths 10 % and 43 % short)."""
    from sim.camera.defects import random_scratch_angle

    p = FrameParams(**SMALL)
    for seed in range(91100, 91112):
        rng = np.random.default_rng(seed)
        length, width, angle = rng.uniform(150.0, 200.0), rng.uniform(1.5, 6.0), random_scratch_angle(rng)
        spec = DefectSpec("scratch", 319.5 + rng.uniform(-30, 30), 255.5 + rng.uniform(-30, 30), length, width, angle,
                          None, None, seed)
        t, d = _the_one_scratch_found(p, spec, seed)
        assert abs(d.length_mm - t.length_mm) <= 0.1 * t.length_mm, (seed, d.length_mm, t.length_mm)
        assert _within(d.width_mm, t.width_mm), (seed, d.width_mm, t.width_mm)
        assert np.hypot(d.x_px - t.x_px, d.y_px - t.y_px) * MM_PER_PX <= 0.05, (seed, d.x_px, d.y_px, t.x_px, t.y_px)


def test_a_scratch_along_the_hatch_is_found_and_measured():
    """A real part's scratch may run along the honing grooves. Such a mark was dropped as
    the hatch's residue whatever its darkness and ends (0 of 75 above the limits at 0-6
    deg off a groove family found, session 45): it is a scratch when it ends in a cut.
    Clear scratches (2.5-5 px wide, 0.4-0.7 of the wall's level) 0-6 deg off either
    family, on the station envelope's walls: each found once, its length within 10 % or
    0.02 mm and its place within 0.05 mm, and nothing else reported."""
    for seed in range(93300, 93308):
        rng = np.random.default_rng(seed)
        p = FrameParams(**SMALL, groove_depth=float(rng.uniform(0.03, 0.08)))
        family = p.hatch_deg if seed % 2 else 180.0 - p.hatch_deg
        angle = family + float(rng.uniform(-6.0, 6.0))
        length, width = float(rng.uniform(60.0, 180.0)), float(rng.uniform(2.5, 5.0))
        spec = DefectSpec("scratch", 319.5 + rng.uniform(-60, 60), 255.5 + rng.uniform(-60, 60), length, width, angle,
                          reflectance=float(rng.uniform(0.4, 0.7)), shape_seed=seed)
        t, d = _the_one_scratch_found(p, spec, seed)
        assert _within(d.length_mm, t.length_mm), (seed, d.length_mm, t.length_mm)
        assert np.hypot(d.x_px - t.x_px, d.y_px - t.y_px) * MM_PER_PX <= 0.05, (seed, d.x_px, d.y_px, t.x_px, t.y_px)


def test_a_scratch_along_the_hatch_is_found_on_a_wall_whose_grooves_stop_short():
    """Where the honing's grooves stop short (``groove_breaks``), groove pieces end in cuts
    as a furrow does, and a mark along the hatch must also be darker than the frame's own
    darkest groove stretches (``aligned_min_stretch_share``). The clear scratches of the
    test above, on such walls (a third of the grooves' length broken out), are still each
    found, their length within 10 % or 0.02 mm. (Groove pieces as dark as the frame's
    darkest grooves may be reported beside them: one in 93307's frame, two without the
    darkness test; the clean walls' test below counts them.)"""
    for seed in range(93300, 93308):
        rng = np.random.default_rng(seed)
        p = FrameParams(**SMALL, groove_depth=float(rng.uniform(0.03, 0.08)), groove_breaks=0.33)
        family = p.hatch_deg if seed % 2 else 180.0 - p.hatch_deg
        angle = family + float(rng.uniform(-6.0, 6.0))
        length, width = float(rng.uniform(60.0, 180.0)), float(rng.uniform(2.5, 5.0))
        spec = DefectSpec("scratch", 319.5 + rng.uniform(-60, 60), 255.5 + rng.uniform(-60, 60), length, width, angle,
                          reflectance=float(rng.uniform(0.4, 0.7)), shape_seed=seed)
        f = render_frame(p, [], seed=seed, defects=[spec])
        (t,) = [d.with_scale(MM_PER_PX) for d in f.defects]
        ((_, d),), _ = match([t], detect_defects(f.image, MM_PER_PX), MM_PER_PX)
        assert d is not None and d.kind == "scratch", seed
        assert _within(d.length_mm, t.length_mm), (seed, d.length_mm, t.length_mm)


@pytest.mark.parametrize("seed", [1780000, 1780002, 1780006, 1780010, 1780015, 1780017])
def test_groove_pieces_with_cut_ends_on_a_clean_wall_are_no_scratches(seed):
    """A honing whose grooves stop short (40 % of their length broken out, the station's
    envelope) leaves groove pieces whose darkness steps down within the blur at both ends,
    which the ends' test takes for a furrow's: on 40 such clean frames (seeds 1780000-
    1780039) 15 "scratches" along the hatch of 0.19-2.2 mm were reported, one or two in
    each of these. A mark along the hatch no darker than the frame's own darkest groove
    stretches is one of them: nothing is reported."""
    f = random_defect_frame(seed, {}, groove_breaks=0.4)
    found = detect_defects(f.image, MM_PER_PX)
    assert not found, [(d.kind, round(d.x_px), round(d.y_px), round(d.length_mm, 3)) for d in found]


def test_a_marks_line_runs_on_as_a_groove_where_its_family_darkens_beyond_its_ends():
    """``line_runs_on``: the share of the family's line through a mark, beyond its ends and
    on the wall, at least half as dark as the mark, less the share of the whole wall's
    places that are, and that excess in standard deviations of a line's share (its
    stretches, 10 half-res px each, independent draws at the wall's share, read as at
    least one stretch's worth). A wall of 41 x 400 half-res px, the mark (80 px full-res,
    40 half-res) in the middle of row 20: pieces of a groove at 0.6 of the mark's darkness
    on 201 of the 343 px of its line beyond it read 201 / 343 less what the wall's places
    reach (the three rows round row 20, whose best they are, on 242 of the 41 x 400
    places); pieces at 0.4 of it run on no more than the wall does; a faint mark whose
    every line is as dark runs on less than the wall; a line with less than 0.5 mm of wall
    beyond the mark is not judged. Pieces on 60 px of the line (0.16 over the wall's share)
    stand out on a bare wall (z 5.4), and not where four other lines are as dark over a
    quarter of their length (z 1.7)."""
    from station.vision.defects.wall import GrooveStretches, line_runs_on

    cfg = DefectConfig()
    darkness = np.zeros((41, 400), np.float32)
    darkness[20, 180:221] = 1.0
    darkness[20, :101] = darkness[20, 300:] = 0.6
    identity = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    on_wall = np.ones(darkness.shape, bool)
    at = dict(x_px=400.5, y_px=40.5, length_px=80.0, mm_per_px=0.010, cfg=cfg)
    draws = 343 / 10

    def z(excess, wall_share):
        p = max(wall_share, 1 / draws)
        return excess / np.sqrt(p * (1 - p) / draws)

    stretches = GrooveStretches(identity, darkness, None, on_wall, 10)
    run = line_runs_on(stretches, own=1.0, **at)
    assert run.share == pytest.approx(201 / 343 - 3 * 242 / (41 * 400))
    assert run.z == pytest.approx(z(run.share, 3 * 242 / (41 * 400)))  # 15.4
    # at 1.6 the bar is 0.8: only the mark's own 41 columns reach it, within the line's reach
    run = line_runs_on(stretches, own=1.6, **at)
    assert run.share == pytest.approx(-3 * 41 / (41 * 400))
    assert run.z == pytest.approx(z(run.share, 3 * 41 / (41 * 400))) and run.z < 0.0
    bare = darkness.copy()
    bare[20, :101] = bare[20, 300:] = 0.0
    assert line_runs_on(GrooveStretches(identity, bare, None, on_wall, 10), own=1.0, **at).share == pytest.approx(
        -3 * 41 / (41 * 400))
    grooved = (np.where(np.arange(41)[:, None] % 2 == 0, np.float32(0.6), np.float32(0.0))
               * np.ones((1, 400), np.float32))
    grooved[20] = darkness[20]
    assert line_runs_on(GrooveStretches(identity, grooved, None, on_wall, 10), own=1.0, **at).share < 0.0
    holed = on_wall.copy()
    holed[:, :160] = holed[:, 236:] = False  # 12 + 11 px of wall beyond the mark: 0.46 mm
    assert line_runs_on(GrooveStretches(identity, darkness, None, holed, 10), own=1.0, **at) is None
    assert line_runs_on(stretches, own=0.0, **at) is None
    # pieces on 60 px of the line beyond: under the share's bar, over the z's on a bare wall
    short = bare.copy()
    short[20, :60] = 0.6
    run = line_runs_on(GrooveStretches(identity, short, None, on_wall, 10), own=1.0, **at)
    assert run.share == pytest.approx(60 / 343 - 3 * 101 / (41 * 400)) and run.share < cfg.groove_run_on_share
    assert run.z == pytest.approx(z(run.share, 3 * 101 / (41 * 400))) and run.z > cfg.groove_run_on_z  # 5.4
    # ... and where lines 5, 15, 25 and 35 are as dark over their last 100 px, any line's
    among = short.copy()
    among[5::10, 300:] = 0.6
    run = line_runs_on(GrooveStretches(identity, among, None, on_wall, 10), own=1.0, **at)
    wall_share = (3 * 101 + 4 * 3 * 100) / (41 * 400)
    assert run.share == pytest.approx(60 / 343 - wall_share)
    assert run.z == pytest.approx(z(run.share, wall_share)) and run.z < cfg.groove_run_on_z  # 1.7


@pytest.mark.parametrize("seed", [2650002, 2650045, 2650068, 2650077, 2680064])
def test_a_groove_piece_whose_line_runs_on_beyond_it_is_no_scratch(seed):
    """Where the grooves stop short (30 % of their length broken out), a deep groove's piece
    with cut ends is as dark as a scratch and ends as one; a short one, or two pieces side
    by side, reads its direction 8-14 deg off the hatch and escapes the tests along it.
    These clean frames of the groove-breaks benches (seeds 1650000 and 1680000) each
    reported one such "scratch" (0.29-0.93 mm; 1.3, 8.1, 9.5, 0.4 and 8.7 deg off a
    family; the last 60 x 3.2 px, its chord crossing 9 px of the family's lines). Each
    keeps to one line of its family, and that line runs on beyond it as a groove (a
    quarter to two thirds of it at half the piece's darkness, where the true scratches
    near the hatch read at most 0.12): nothing is reported."""
    f = random_defect_frame(seed, {}, groove_breaks=0.3)
    found = detect_defects(f.image, MM_PER_PX)
    assert not found, [(d.kind, round(d.x_px), round(d.y_px), round(d.length_mm, 3)) for d in found]


@pytest.mark.parametrize("seed, mm_per_px, wall", [
    (4140005, 0.007, dict(hatch_deg=20.0, groove_breaks=0.3, texture_scale=10 / 7)),
    (4100030, 0.007, dict(hatch_deg=20.0, groove_breaks=0.3, texture_scale=10 / 7)),
    (4210002, 0.010, dict(hatch_deg=25.0, groove_breaks=0.2, psf_smear_px=4.0, psf_smear_deg=30.0)),
])
def test_a_groove_piece_whose_line_runs_on_more_than_any_lines_does_is_no_scratch(seed, mm_per_px, wall):
    """A groove's piece, not along the hatch as the ends' tests take it (read 7.5-8 deg off
    its family, or 1.6 deg off but crossing 12.6 px of its lines), whose line runs on beyond it
    over less than a fifth of its length more than the wall's lines do, but on a wall where
    hardly any line reaches half its darkness, so that the excess is 5.5-7.6 standard
    deviations of a line's share. Clean frames with grooves stopping short: a 20 deg hatch
    seen at 0.007 mm/px (the texture at its size in mm: pieces of 0.39 and 3.2 mm, shares
    0.18), a smeared lens on a 25 deg hatch (a 0.25 mm piece, share 0.14). Each reported a
    scratch before session 74."""
    f = random_defect_frame(seed, {}, mm_per_px=mm_per_px, **wall)
    found = detect_defects(f.image, mm_per_px)
    assert not [d for d in found if d.kind == "scratch"], [
        (d.kind, round(d.x_px), round(d.y_px), round(d.length_mm, 3)) for d in found]


@pytest.mark.parametrize("seed", [4220008, 4220021, 4220084])
def test_a_groove_piece_cut_by_the_frames_border_is_no_pore(seed):
    """Where the grooves stop short, a groove's piece may end a few px inside the frame; the
    grooves' means along the lines, one-sided at the border, leave it out, and its 14-20 x
    7-10 px were measured as a pore. Its long axis lies along its family (2-4.5 deg off),
    where a round pore cut by a straight border lies along the border, and its line runs on
    beyond it by 0.69-0.71. Clean wide frames, grooves 20 % broken (the bench's clean set
    for 3220000): each reported a "pore" of 0.14-0.2 mm at the border before session 75."""
    f = random_defect_frame(seed, {}, envelope="wide", groove_breaks=0.2)
    found = detect_defects(f.image, MM_PER_PX)
    assert not [d for d in found if d.kind == "pore" and d.partial], [
        (d.kind, round(d.x_px), round(d.y_px), round(d.length_mm, 3)) for d in found]


@pytest.mark.parametrize("seed, envelope, breaks", [
    (4230034, "wide", 0.2),  # a groove meets the border
    (4230091, "wide", 0.2),  # two grooves cross at the border
    (4230093, "wide", 0.2),
    (4660070, "station", 0.3),
])
def test_a_grooves_stub_lying_along_the_border_is_no_pore(seed, envelope, breaks):
    """Where a groove meets the border, or two cross there, the darkness the one-sided means
    along the lines leave is cut by the border and lies along it (81-107 deg at the left
    border), as a cut pore's visible part does: 10-12 x 6-7 px, which a pore shows too
    little of itself to be sized by, on a line of one family or both that runs on into the
    frame by 0.53-0.79. Clean frames, grooves 20 % (wide) or 30 % (station) broken: each
    reported a 0.10-0.12 mm "pore" at the border before session 76."""
    f = random_defect_frame(seed, {}, envelope=envelope, groove_breaks=breaks)
    found = detect_defects(f.image, MM_PER_PX)
    assert not [d for d in found if d.kind == "pore" and d.partial], [
        (d.kind, round(d.x_px), round(d.y_px), round(d.length_mm, 3)) for d in found]


def _lines_and_disc(shape=(160, 160), lines=((30.0, 0.3), (150.0, 0.3)), disc=None, sigma=1.5):
    """Relative darkness of straight grooves through the centre (angle deg, depth; a
    Gaussian profile of ``sigma`` px across) and, over them, a disc (radius px, darkness)
    that takes the wall's place, grooves and all, as a pore does."""
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    cx, cy = (w - 1) / 2.0, (h - 1) / 2.0
    dark = np.zeros(shape, np.float32)
    for angle, depth in lines:
        a = np.deg2rad(angle)
        across = -(xx - cx) * np.sin(a) + (yy - cy) * np.cos(a)
        dark += depth * np.exp(-0.5 * (across / sigma) ** 2)
    if disc is not None:
        radius, darkness = disc
        inside = np.hypot(xx - cx, yy - cy) <= radius
        dark[inside] = darkness
    return cv2.GaussianBlur(dark, (0, 0), 1.0), (cx, cy)


def test_two_grooves_crossing_explain_their_crossings_darkness_and_a_pore_on_one_does_not():
    """``_crossing_shares``: at a crossing of two grooves each family's line through the
    mark, read beside it, explains about half of the mark's darkness; a 24 px pore (0.5
    dark) on one of the grooves, with the other family's groove passing 40 px away, is
    explained a little by its own groove and not at all by the other family."""
    from station.vision.defects.frame import _crossing_shares
    dark, (cx, cy) = _lines_and_disc()
    mark = Defect("pore", cx, cy, length_px=14.0, width_px=7.0, confidence=1.0, angle_deg=0.0, length_u_px=0.5,
                  width_u_px=0.5, significance=10.0)
    reading = _crossing_shares(dark, mark, (30.0, 150.0), 1.4, 20.0)
    assert sum(reading.shares) > 0.8 and min(reading.shares) > 0.35, reading
    assert reading.follows > 0.8, reading  # its darkness is the lines'
    dark, _ = _lines_and_disc(lines=((30.0, 0.3),), disc=(12.0, 0.5))
    yy, xx = np.mgrid[0:160, 0:160].astype(np.float32)
    a = np.deg2rad(150.0)
    dark += 0.3 * np.exp(-0.5 * ((-(xx - cx) * np.sin(a) + (yy - cy) * np.cos(a) - 40.0) / 1.5) ** 2)
    pore = replace(mark, length_px=24.0, width_px=24.0)
    shares = _crossing_shares(dark, pore, (30.0, 150.0), 1.4, 20.0).shares
    assert sum(shares) < 0.3 and shares[1] < 0.02, shares


def test_a_pale_pore_on_a_crossing_of_deep_grooves_does_not_follow_their_lines():
    """A pore takes the wall's place, grooves and all, and its floor is even: a pale pore
    (0.25 dark, 30 px across) on a crossing of two deep, broad grooves (0.25 dark, a
    Gaussian of 4 px across) is explained by their lines over both of the crossing rule's
    bars, as the lines lay 0.5 where they cross, but its darkness does not follow theirs,
    as a crossing's does (above); it stays a pore (``_drop_crossings``:
    ``crossing_min_follows``)."""
    from station.vision.defects.frame import _crossing_shares

    cfg = DefectConfig()
    dark, (cx, cy) = _lines_and_disc(lines=((30.0, 0.25), (150.0, 0.25)), disc=(15.0, 0.25), sigma=4.0)
    pore = Defect("pore", cx, cy, length_px=30.0, width_px=30.0, confidence=1.0, angle_deg=0.0, length_u_px=0.5,
                  width_u_px=0.5, significance=10.0)
    reading = _crossing_shares(dark, pore, (30.0, 150.0), 1.4, 20.0)
    assert sum(reading.shares) >= cfg.crossing_min_explained, reading
    assert min(reading.shares) >= cfg.crossing_min_family_share, reading
    assert reading.follows < cfg.crossing_min_follows, reading
    # the same lines crossing with no pore over them: their darkness follows the lines'
    mark = replace(pore, length_px=16.0, width_px=10.0)
    crossing = _crossing_shares(_lines_and_disc(lines=((30.0, 0.25), (150.0, 0.25)), sigma=4.0)[0], mark,
                                (30.0, 150.0), 1.4, 20.0)
    assert crossing.follows > cfg.crossing_min_follows + 0.3, crossing


def _the_large_pore_is_found_once_and_its_length_in_tolerance(seed: int) -> None:
    """The wide bench frame ``seed`` holds one pore over 0.4 mm: it is reported once, as a
    pore, and its length is within 10 % or 0.02 mm."""
    f = random_defect_frame(seed, None, envelope="wide")
    truths = [t for t in f.defects if t.kind == "pore" and t.length_mm > 0.4]
    assert len(truths) == 1
    t = truths[0]
    found = detect_defects(f.image, MM_PER_PX)
    near = [d for d in found
            if d.kind == "pore" and np.hypot(d.x_px - t.image_x_px, d.y_px - t.image_y_px) < 0.5 * t.length_px]
    assert len(near) == 1, [(d.kind, round(d.x_px), round(d.y_px), round(d.length_mm, 3)) for d in found]
    assert abs(near[0].length_mm - t.length_mm) <= max(0.1 * t.length_mm, 0.02), (near[0].length_mm, t.length_mm)

def test_a_pale_pore_where_two_deep_grooves_cross_is_found():
    """Wide frame 4510084: a 0.43 mm pore, 0.35 dark, where two deep grooves cross. Their
    lines explain 0.36 and 0.21 of its darkness (over the crossing rule's 0.5 and 0.2),
    and until session 81 it was dropped as their crossing and not reported at all; its
    darkness follows their lines' at 0.20. It is found and sized as a pore."""
    _the_large_pore_is_found_once_and_its_length_in_tolerance(4510084)


@pytest.mark.parametrize("seed, at", [
    (3220013, (969, 740)),
    (4220058, (379, 816)),
    (4220077, (1139, 769)),
])
def test_a_crossing_of_two_groove_pieces_is_no_pore(seed, at):
    """Where a honing's grooves stop short, the means along the lines hold the pieces' depth
    too low, and where two pieces cross the two shortfalls add up to a dark spot of a pore's
    size: 0.21-0.39 x 0.11-0.20 mm, the lines through it explaining 0.70-1.02 of its
    darkness, the lesser family 0.32-0.49. Wide frames, grooves 20 % broken (the bench's
    3220000): each reported such a "pore" before session 78."""
    f = random_defect_frame(seed, {} if seed >= 4220000 else None, envelope="wide", groove_breaks=0.2)
    found = detect_defects(f.image, MM_PER_PX)
    assert not [d for d in found if d.kind == "pore" and np.hypot(d.x_px - at[0], d.y_px - at[1]) < 10], [
        (d.kind, round(d.x_px), round(d.y_px), round(d.length_mm, 3)) for d in found]


def test_a_pore_where_two_grooves_cross_is_still_a_pore():
    """The true pore the crossing rule comes nearest to (``_crossing_shares``): a 0.32 mm
    pore on a wide wall, grooves 20 % broken, where two grooves cross under it; the lines
    through it explain 0.37 of its darkness, the lesser family 0.13. It is found and
    measured as a pore."""
    f = random_defect_frame(3220015, None, envelope="wide", groove_breaks=0.2)
    truths = [t for t in f.defects if t.kind == "pore" and t.length_mm > 0.3]
    assert truths
    found = detect_defects(f.image, MM_PER_PX)
    for t in truths:
        near = [d for d in found if d.kind == "pore"
                and np.hypot(d.x_px - t.image_x_px, d.y_px - t.image_y_px) < 0.5 * t.length_px]
        assert near, (round(t.length_mm, 3), [(d.kind, round(d.x_px), round(d.y_px)) for d in found])


def test_a_pore_is_sized_without_the_grooves_it_cuts():
    """A pore takes the wall's place, grooves and all: its floor is one level. With the
    grooves' model subtracted over it as well, a 36 px pore (0.35 dark) on three lines of
    each family (0.25 deep) read light stripes along the lines through it and an outline
    25 % long (45 x 35 px). ``measure_pore`` puts the grooves back under its fitted
    ellipse for its size; the tests still read the mark against the wall as modelled (its
    contrast is the same either way)."""
    from station.vision.defects.pores import measure_pore
    from station.vision.defects.wall import Patch

    h = w = 120
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    cx, cy, radius, blur = 60.3, 59.6, 18.0, 1.4
    grooves = np.zeros((h, w), np.float32)
    for angle in (30.0, 150.0):
        a = np.deg2rad(angle)
        for offset in (-14.0, 0.0, 14.0):
            across = -(xx - cx) * np.sin(a) + (yy - cy) * np.cos(a) - offset
            grooves += 0.25 * np.exp(-0.5 * (across / 2.0) ** 2)
    grooves -= grooves.mean()  # the level holds the grooves: the wall's mean darkness is 0
    disc = (np.hypot(xx - cx, yy - cy) <= radius).astype(np.float32)
    world = cv2.GaussianBlur((1.0 - disc) * grooves + disc * 0.35, (0, 0), blur)
    model = cv2.GaussianBlur(grooves, (0, 0), blur)  # the grooves as the wall model has them
    residual = (world - model + np.random.default_rng(1).normal(0.0, 0.01, (h, w))).astype(np.float32)
    region = cv2.GaussianBlur(disc, (0, 0), blur) > 0.2
    excluded = cv2.dilate(region.astype(np.uint8), np.ones((9, 9), np.uint8)) > 0
    patch = Patch(0, 0, residual, np.full((h, w), 150.0, np.float32), excluded, np.zeros((h, w), bool), model,
                  0.01, 0.004)
    m = measure_pore(patch, region, DefectConfig(), blur_hint=blur)
    assert m is not None and not m.get("faint"), m
    assert abs(m["length"] - 2 * radius) <= 0.05 * 2 * radius, m
    assert abs(m["width"] - 2 * radius) <= 0.1 * 2 * radius, m
    assert m["contrast"] < 0.3, m  # the tests' contrast: the stripes left in


def test_the_level_is_taken_again_round_a_large_pale_mark():
    """The frame's level leaves out only what it found clearly dark; a large pale mark it
    did not find so pulls the level down under itself (a Gaussian mean of 16 px over a
    40 px disc, 0.35 dark, reads it ~0.2 dark). ``local_patch`` with the level's Gaussian
    takes the level again with the candidate left out, and the higher of the two stands."""
    from station.vision.defects.wall import local_patch

    h = w = 140
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    disc = np.hypot(xx - 70.0, yy - 70.0) <= 20.0
    img = np.where(disc, 150.0 * 0.65, 150.0).astype(np.float32)
    img = np.clip(img + np.random.default_rng(2).normal(0.0, 2.0, img.shape), 0, 255).astype(np.uint8)
    followed = cv2.GaussianBlur(img.astype(np.float32), (0, 0), 16.0, borderType=cv2.BORDER_REFLECT)
    seed = np.hypot(xx - 70.0, yy - 70.0) <= 22.0
    zone = np.zeros((h, w), bool)
    core = np.hypot(xx - 70.0, yy - 70.0) <= 12.0
    as_it_was = local_patch(img, (0, 0, w, h), seed, zone, (30.0, 150.0), followed)
    again = local_patch(img, (0, 0, w, h), seed, zone, (30.0, 150.0), followed, 16.0)
    assert float(as_it_was.residual[core].mean()) < 0.27
    assert abs(float(again.residual[core].mean()) - 0.35) < 0.03
    clear = ~cv2.dilate(seed.astype(np.uint8), np.ones((41, 41), np.uint8)).astype(bool)
    assert abs(float(again.residual[clear].mean())) < 0.01  # the wall beside it stays level


def test_a_large_pale_pore_that_the_frames_level_followed_is_found():
    """Wide frame 4540016: a 0.45 x 0.32 mm pore, 0.37 dark, its long axis 15 deg off a
    groove family, where deep grooves run into it. The frame's coarse grooves' means took
    its darkness into the lines through it, it stood under the dark floor, and the frame's
    level followed it down by a fifth; its fitted floor read 0.199, under the pores' 0.2,
    and until session 82 it was not reported at all. It is examined again with the level
    taken round it, found once, and its length read within tolerance."""
    _the_large_pore_is_found_once_and_its_length_in_tolerance(4540016)


@pytest.mark.parametrize("seed", [0, 5, 6])
def test_a_large_pale_pore_that_the_frames_level_dipped_under_is_measured_whole(seed):
    """A 0.5 mm pore at 0.6 of the wall's reflectance (the renderer's palest) on the twin's
    wall (grooves 10 % deep): found, but its darkness shared with the grooves' coarse means
    through it, so not clearly dark where the frame's level was taken; the level dipped by
    up to 16 % under it, and it read 13-18 % short on these seeds. Measured again under the
    level taken round it, it is within 5 % in length and width."""
    spec = DefectSpec("pore", 640.3, 512.2, 50.0, 45.0, 30.0 + 20 * seed, reflectance=0.6, shape_seed=seed)
    f = render_frame(FrameParams(groove_depth=0.1), [], seed=seed, defects=[spec])
    (t,) = f.defects
    found = detect_defects(f.image, MM_PER_PX)
    pairs, false = match([t.with_scale(MM_PER_PX)], found, MM_PER_PX)
    assert false == [], [(d.kind, d.x_px, d.y_px) for d in found]
    d = pairs[0][1]
    assert d is not None and d.kind == "pore"
    assert abs(d.length_px / t.length_px - 1.0) <= 0.05, (d.length_px, t.length_px)
    assert abs(d.width_px / t.width_px - 1.0) <= 0.05, (d.width_px, t.width_px)


def _pores_across_the_border(seed: int, envelope: str = "station", **overrides):
    """A frame of ``random_params``' envelope with three random pores, each drawn with its
    centre within 0.3 of its length of one of the frame's borders (a side drawn at random)."""
    rng = np.random.default_rng(seed)
    params = random_params(rng, envelope, **overrides)
    specs = []
    for spec in random_defects(rng, params, [], {"pore": 3}, MM_PER_PX):
        side, f = int(rng.integers(4)), float(rng.uniform(-0.3, 0.3)) * spec.length_px
        w, h = params.width_px, params.height_px
        if side < 2:
            x, y = (f if side == 0 else w - 1 - f), rng.uniform(50, h - 50)
        else:
            x, y = rng.uniform(50, w - 50), (f if side == 2 else h - 1 - f)
        specs.append(replace(spec, x_px=float(x), y_px=float(y)))
    frame = render_frame(params, [], seed=int(rng.integers(2**31)), defects=specs)
    return frame, [d.with_scale(MM_PER_PX) for d in frame.defects]


@pytest.mark.parametrize("seed, envelope, wall", [
    (5000099, "station", {}),
    (5300057, "wide", dict(groove_breaks=0.2)),
    (5400026, "station", dict(groove_breaks=0.3)),
])
def test_a_pore_cut_by_the_border_along_a_grooves_line_is_still_a_pore(seed, envelope, wall):
    """The pores the border cuts that lie most like a groove's piece: 0.38-0.49 mm pores on
    a groove whose line runs on beyond them (by 0.37-0.73), their visible part read 1.3-1.6
    times as long as wide and within 6.5-15 deg of the family. They are 0.23-0.30 mm wide,
    which no groove is: each is found, cut by the border, and measured as a pore."""
    f, truths = _pores_across_the_border(seed, envelope, **wall)
    found = detect_defects(f.image, MM_PER_PX)
    big = max(truths, key=lambda t: t.length_mm)
    near = [d for d in found if d.kind == "pore" and d.partial
            and np.hypot(d.x_px - big.image_x_px, d.y_px - big.image_y_px) < 0.5 * big.length_px + 0.5 * d.width_px]
    assert near, (round(big.length_mm, 3), [(d.kind, round(d.x_px), round(d.y_px)) for d in found])
    assert near[0].width_mm > 0.2


def test_a_pore_over_the_limit_cut_by_the_border_on_a_running_on_line_is_still_a_pore():
    """The groove stub's rule (``_border_stub``) leaves what shows enough of a pore to size
    it: a 0.21 mm pore, the border through it, on a wide wall with grooves 20 % broken,
    shows 0.18 x 0.17 mm of itself on a line that runs on by 0.53. It is found, cut by the
    border, and measured as a pore."""
    f, truths = _pores_across_the_border(5300004, "wide", groove_breaks=0.2)
    found = detect_defects(f.image, MM_PER_PX)
    (t,) = [t for t in truths if 0.2 <= t.length_mm <= 0.23]
    near = [d for d in found if d.kind == "pore" and d.partial
            and np.hypot(d.x_px - t.image_x_px, d.y_px - t.image_y_px) < 0.5 * t.length_px + 0.5 * d.width_px]
    assert near, (round(t.length_mm, 3), [(d.kind, round(d.x_px), round(d.y_px)) for d in found])
    assert near[0].length_mm > 0.14


def test_a_long_scratch_a_few_degrees_off_the_hatch_crosses_its_lines_and_is_found():
    """A scratch 3.5-7 deg off a groove family was judged as the hatch's residue (kept
    only when both its ends were square cuts), though over 1.5-2 mm it crosses 10-25 px
    of the family's lines, which a groove never does; one whose end runs into a deep
    groove was lost (dev frames drawn within 7.5 deg of the hatch: 92 of 114 found,
    100 after). Thin dark scratches of 1.5-2.1 mm on walls with deep grooves (6-9 %): the
    old rule found and measured 9 of these 24 within 10 % and 0.05 mm; now at least 17,
    and nothing else is reported."""
    ok = 0
    for seed in range(93400, 93424):
        rng = np.random.default_rng(seed)
        p = FrameParams(**SMALL, groove_depth=float(rng.uniform(0.06, 0.09)))
        family = p.hatch_deg if seed % 2 else 180.0 - p.hatch_deg
        off = float(rng.uniform(3.5, 7.0)) * (1 if rng.random() < 0.5 else -1)
        length, width = float(rng.uniform(150.0, 210.0)), float(rng.uniform(1.7, 3.0))
        spec = DefectSpec("scratch", 319.5 + rng.uniform(-40, 40), 255.5 + rng.uniform(-40, 40), length, width,
                          family + off, reflectance=float(rng.uniform(0.5, 0.7)), shape_seed=seed)
        f = render_frame(p, [], seed=seed, defects=[spec])
        (t,) = [d.with_scale(MM_PER_PX) for d in f.defects]
        found = detect_defects(f.image, MM_PER_PX)
        pairs, false = match([t], found, MM_PER_PX)
        # 93420: a deep groove's 1 mm piece along the hatch at the frame's corner, reported
        # by the old rule as well (its ends read square there); nothing else
        assert not false or (seed == 93420 and len(false) == 1), (seed, [(e.kind, e.length_mm) for e in found])
        d = pairs[0][1]
        ok += bool(d is not None and d.kind == "scratch" and _within(d.length_mm, t.length_mm)
                   and np.hypot(d.x_px - t.x_px, d.y_px - t.y_px) * MM_PER_PX <= 0.05)
    assert ok >= 17, ok


def test_a_long_faint_scratch_is_followed_across_the_deep_grooves_that_cross_it():
    """A thin, faint scratch of 6-8.5 mm on deep grooves (6-9 %): where a deep groove
    crosses it at the hatch's angle its flanks darken as much as its core, and the
    following of its furrow past the measured piece stopped at the first such dip (6 px
    below half its contrast), leaving the rest unread: a 17.3 mm scratch of a
    whole-surface part stood 3.7 mm short with its end piece a false scratch. It is
    followed over dips of up to ``track_gap_px`` now: 25 of these 30 within 10 % before,
    28 now (the other two cut in two pieces), and at most two pieces reported besides
    (four before)."""
    ok, extra = 0, 0
    for seed in range(96000, 96030):
        rng = np.random.default_rng(seed)
        p = FrameParams(width_px=960, height_px=640, groove_depth=float(rng.uniform(0.06, 0.09)))
        length, width = float(rng.uniform(600, 850)), float(rng.uniform(1.2, 2.0))
        angle = float(rng.uniform(-8, 8)) + (0 if rng.random() < 0.5 else 90)
        spec = DefectSpec("scratch", 479.5 + rng.uniform(-20, 20), 319.5 + rng.uniform(-20, 20),
                          length if angle < 45 else 560.0, width, angle, reflectance=float(rng.uniform(0.6, 0.8)),
                          shape_seed=seed)
        f = render_frame(p, [], seed=seed, defects=[spec])
        (t,) = [d.with_scale(MM_PER_PX) for d in f.defects]
        found = detect_defects(f.image, MM_PER_PX)
        pairs, false = match([t], found, MM_PER_PX)
        d = pairs[0][1]
        ok += bool(d is not None and d.kind == "scratch" and _within(d.length_mm, t.length_mm))
        extra += len(false)
    assert ok >= 28, ok
    assert extra <= 2, extra


def _the_twin_scratch_found(seed: int):
    """A bench frame of the camera twin (``twin_scratch_frame``): its one scratch found as
    a scratch, its length within 10 % and its place within 0.05 mm, and nothing else
    reported. (truth, found)."""
    from station.bench.defects import twin_scratch_frame

    f = twin_scratch_frame(seed)
    (t,) = f.defects
    found = detect_defects(f.image, MM_PER_PX)
    pairs, false = match([t], found, MM_PER_PX)
    d = pairs[0][1]
    assert d is not None and d.kind == "scratch", found
    assert abs(d.length_mm - t.length_mm) <= 0.1 * t.length_mm, (d.length_mm, t.length_mm)
    assert np.hypot(d.x_px - t.image_x_px, d.y_px - t.image_y_px) * MM_PER_PX <= 0.05
    assert not false, [found[k] for k in false]
    return t, d


def test_a_scratch_whose_region_a_grooves_residue_joins_is_examined_along_its_own_line():
    """A frame of the camera twin (the bench's seed 2086604): a bent 1.66 mm scratch, plain
    to see, crosses a deep groove that darkens along its length more than the wall model
    holds. The groove's residue joined the scratch's region, which was then no line: it
    was measured as a pore, failed, and the scratch was not reported. A candidate whose
    seed is one furrow and whose region was no defect is examined again confined to its
    own line, and kept only as a scratch."""
    t, d = _the_twin_scratch_found(2086604)
    assert _within(d.width_mm, t.width_mm), (d.width_mm, t.width_mm)


def test_a_bent_scratch_with_a_grooves_spur_at_its_end_is_examined_along_its_own_line():
    """A frame of the camera twin (the bench's seed 2260004): a bent 1.18 mm scratch,
    plain to see, ends on a deep groove, and the groove's residue there joined its seed as
    a spur (0.21 of it). Its principal axis, tilted by the spur, held 0.79 of the seed
    (0.85 needed), so it was not taken for one furrow, its unconfined region was no
    defect, and nothing was reported. The axis of the points within reach of it holds
    enough of the seed, and the scratch is examined along it."""
    from station.vision.defects.wall import one_furrow

    seed = np.zeros((220, 140), bool)
    rr = np.arange(40, 210)
    cols = (40 + 0.25 * (rr - 40) + 4e-4 * (rr - 40) ** 2).astype(int)  # a bent furrow 170 px long
    for r, c in zip(rr, cols):
        seed[r, c - 2:c + 3] = True
    ref = one_furrow(seed)  # one furrow without the spur
    assert ref is not None
    spur = seed.copy()
    for k in range(50):  # a groove's stretch 7 px wide at 30 deg from its top end
        r, c = int(42 - 0.5 * k), int(40 + 0.87 * k)
        spur[r - 3:r + 4, c:c + 2] = True
    line = one_furrow(spur)
    assert line is not None
    # the furrow's own direction, not one the spur tilts
    assert abs((np.degrees(line[2] - ref[2]) + 90.0) % 180.0 - 90.0) < 4.0, (line, ref)
    t, d = _the_twin_scratch_found(2260004)
    assert _within(d.width_mm, t.width_mm), (d.width_mm, t.width_mm)


def test_a_group_that_is_no_defect_has_its_dominant_member_judged_alone():
    """A frame of the camera twin (the bench's seed 2180009): a bent 1.63 mm scratch, 5.9
    px wide and plain to see, has a groove's stretch on its line beyond one end; the two
    candidates were grouped as pieces of one scratch, the region grown from both was no
    line (222 x 85 px) and no pore, and nothing was reported. A group that is no defect
    has its dominant member (peak 32.6 against the stretch's 6.5) examined on its own, as
    any candidate is. (Members alike in strength are not: pieces of groove residue each
    examined alone read as a false scratch, frame 93401 of
    ``test_a_long_scratch_a_few_degrees_off_the_hatch_crosses_its_lines_and_is_found``.)"""
    import station.vision.defects.frame as D

    calls = []
    real = D.group_collinear

    def spy(candidates, *a, **k):
        groups = real(candidates, *a, **k)
        calls.append(groups)
        return groups

    D.group_collinear = spy
    try:
        t, d = _the_twin_scratch_found(2180009)
    finally:
        D.group_collinear = real
    assert any(len(g) > 1 for g in calls[0])  # the frame still groups the scratch with the stretch
    assert _within(d.width_mm, t.width_mm), (d.width_mm, t.width_mm)


def test_a_scratch_that_ends_on_a_deep_groove_is_not_followed_along_the_groove():
    """A frame of the camera twin (the bench's seed 2087087): a 1.57 mm scratch, 12 deg off
    the hatch, ends where a deep groove runs on from it. The following of its furrow
    (``_track_on``, on the raw darkness) turned onto the groove and went along it for
    2.6 mm, to where the groove faded: one 4.16 mm scratch, the true one unmatched. A run
    on along the hatch whose far end fades, as a groove does, is not taken."""
    _the_twin_scratch_found(2087087)


def _the_scan_frames_scratch(spec: DefectSpec, seed: int, wall_seed: int):
    """A frame of a whole-surface scan through the camera twin, rendered again from the
    scan's draws (its one scratch ``spec``, the frame's seed and its wall patch's): the one
    scratch found within 60 px of the truth, each of its ends within 2 px of the truth's
    (the lens's distortion applied). (truth in mm, found)."""
    from sim.camera.twin import CameraOptics

    p = CameraOptics().params
    f = render_frame(p, [], seed=seed, wall=wall_patch(p, wall_seed), defects=[spec])
    truth = f.defects[0].with_scale(MM_PER_PX)
    found = [d for d in detect_defects(f.image, MM_PER_PX) if d.kind == "scratch"
             and np.hypot(d.x_px - truth.image_x_px, d.y_px - truth.image_y_px) < 60.0]
    assert len(found) == 1, found
    d = found[0]
    ends = np.array(geometry(spec, []).scratch_ends_px())
    ex, ey = p.lens.distort_px(ends[:, 0], ends[:, 1])
    line = np.array(d.line_px)
    for px, py in zip(ex, ey):
        assert float(np.min(np.hypot(line[[0, -1], 0] - px, line[[0, -1], 1] - py))) <= 2.0, ((px, py), line[[0, -1]])
    return truth, d


def test_a_scratch_ending_on_a_deep_groove_across_it_keeps_its_end():
    """A frame of a whole-surface scan through the camera twin (bench seed 25300, part 0):
    a 0.88 mm scratch ends on a deep groove 30 deg off it, which the wall model reads at
    half its darkness. Scaling the residual for the grooves a scratch's smooth floor cuts
    away (c / (c - G)) lifted the model's misfit there too, and the end ran on across the
    groove: 1.06 mm, its middle 9 px off. Past the raw end, an amplitude that rises with
    the groove is the groove's (``_groove_beyond_end``): the end stays where the furrow
    stops."""
    spec = DefectSpec("scratch", 762.5159943699219, 485.84110074797, 88.40636391653848, 1.648476601492594,
                      -2.5387004904315402, None, None, 55980413)
    truth, d = _the_scan_frames_scratch(spec, seed=1389828893, wall_seed=1197323378)
    assert abs(d.length_px - truth.length_px) <= 2.0, (d.length_px, truth.length_px)
    assert np.hypot(d.x_px - truth.image_x_px, d.y_px - truth.image_y_px) <= 2.0, (d, truth)


def test_a_scratch_ending_on_a_groove_deeper_than_it_keeps_its_end():
    """A frame of a whole-surface scan through the camera twin (bench seed 23400, part 0):
    a thin 1.86 mm scratch (1.75 px) 5.5 deg off the frame's rows ends on a deep groove
    that crosses it. The grooves' scaling, clipped at 2.5 where the modelled groove through
    the scratch's filter is 1.2-2.5 times the scratch's level, lifted the model's misfit
    of the groove to the scratch's level, and its end was read 12.5 px on, at the groove's
    far side (1.96 mm; the part's record placed it 0.067 mm off). The raw amplitude there
    does not rise with the groove, and the stretch is no shelf; but it lies far above what
    the scratch's smooth floor would leave through so deep a groove (its level less the
    groove's, under zero), so it is the groove's (``_misfit_beyond_end``): the end stays
    where the furrow stops."""
    spec = DefectSpec("scratch", 587.6016558375272, 958.1096484133544, 185.87774064574361, 1.7460944204496067,
                      -5.542872896112307, None, None, 985449586)
    truth, d = _the_scan_frames_scratch(spec, seed=156652361, wall_seed=1813401533)
    assert _within(d.length_mm, truth.length_mm), (d.length_mm, truth.length_mm)
    assert np.hypot(d.x_px - truth.image_x_px, d.y_px - truth.image_y_px) * MM_PER_PX <= 0.02, (d, truth)


def test_a_stretch_past_a_scratchs_end_far_above_its_smooth_floor_through_a_deep_groove_is_the_grooves():
    """``_misfit_beyond_end``: where a scratch runs through a groove its floor is smooth, so
    its raw amplitude is its own level less the modelled groove, whatever the model's
    misfit of the groove; past its end, on a groove the model under-reads, the raw
    amplitude is that misfit, which lies above the floor's read by more than
    ``MISFIT_BEYOND_END_SHARE`` of the scratch's level when the groove is deeper than the
    scratch. A stretch under 4 px says nothing."""
    from station.vision.defects.scratches import MISFIT_BEYOND_END_SHARE, _misfit_beyond_end

    rng = np.random.default_rng(23400)
    step, own = 0.5, 0.94
    groove = np.linspace(1.15, 2.35, 40)  # through the scratch's filter, deeper than the scratch
    noise = rng.normal(0.0, 0.05, groove.size)
    # the scratch through it: its floor's read, however deep the groove
    assert not _misfit_beyond_end(own - groove + noise, groove, 0, groove.size, own, step)
    # the groove alone, the model reading two thirds of it: a misfit of half the model's
    assert _misfit_beyond_end(0.5 * groove + noise, groove, 0, groove.size, own, step)
    # ... a misfit just past the bar over the floor, and just short of it
    assert _misfit_beyond_end(own - groove + (MISFIT_BEYOND_END_SHARE + 0.05) * own, groove, 0, groove.size, own,
                              step)
    assert not _misfit_beyond_end(own - groove + (MISFIT_BEYOND_END_SHARE - 0.05) * own, groove, 0, groove.size,
                                  own, step)
    # too short to say
    assert not _misfit_beyond_end(0.5 * groove, groove, 0, 7, own, step)


def test_a_scratch_is_not_followed_straight_on_through_a_groove_that_diverges_from_it():
    """A frame of the camera twin (the bench's seed 2088050): a 1.65 mm scratch 12 deg off
    the hatch ends on a deep groove. Following the furrow past its end on the raw
    darkness went straight on inside the groove's band for 34 px, until the groove had
    left the path: 2.01 mm, its place 0.18 mm off. The stretch's far end fades over 10
    px, as no cut does: not taken, whichever way it runs (``_run_on_fades``)."""
    t, d = _the_twin_scratch_found(2088050)
    assert abs(d.length_mm - t.length_mm) <= 0.03, (d.length_mm, t.length_mm)


def test_a_pore_a_grooves_stretch_grew_over_is_reported_once():
    """A bench frame (wide envelope, 40 deg hatch, seed 89055): a 0.30 mm pore of low
    contrast on a deep groove. Its own seed measured it; the seed of the groove's stretch
    beside it grew a region over it and measured it again, as a 0.47 mm pore 7 px off.
    A pore whose region covers half of one already measured is that pore again
    (``measured_again``): one pore, where the first measurement put it."""
    f = random_defect_frame(89055, None, mm_per_px=MM_PER_PX, envelope="wide", hatch_deg=40.0)
    (t,) = [t for t in f.defects if t.kind == "pore" and abs(t.image_x_px - 121.3) < 3.0]
    found = detect_defects(f.image, MM_PER_PX)
    near = [d for d in found if np.hypot(d.x_px - t.image_x_px, d.y_px - t.image_y_px) < 0.6 * t.length_px + 10.0]
    assert len(near) == 1 and near[0].kind == "pore", near
    assert np.hypot(near[0].x_px - t.image_x_px, near[0].y_px - t.image_y_px) < 4.0
    pairs, false = match(f.defects, found, MM_PER_PX)
    assert not [found[k] for k in false if found[k].kind == "pore"]


def test_a_scratch_across_the_frame_keeps_its_ends_where_the_lens_bends_it():
    """The camera twin's lens (barrel, -2.7 % at the corner) bends a straight furrow that
    crosses the frame away from its centre as r^3 and r^5 do. With a long scratch's own
    modes, a cubic centre line over ~950 px stood 2-4.5 px off its last 40 px, the matched
    filter read nothing there, and the end came 45 px short (a whole-surface part's 12.2
    mm scratch: joined, its middle 0.24 mm off). Beyond ``QUINTIC_BEND_PX`` the line is a
    quintic: each end where the lens puts the truth's."""
    from sim.camera.twin import CameraOptics

    p = CameraOptics().params
    lens = p.lens
    for seed in range(97000, 97006):
        rng = np.random.default_rng(seed)
        length, width = float(rng.uniform(900.0, 1000.0)), float(rng.uniform(2.0, 4.0))
        angle = float(rng.uniform(-6.0, 6.0))
        x = 639.5 + float(rng.uniform(-30.0, 30.0))
        y = 511.5 + (1 if seed % 2 else -1) * float(rng.uniform(300.0, 370.0))
        spec = DefectSpec("scratch", x, y, length, width, angle, None, None, seed)
        f = render_frame(p, [], seed=seed, wall=wall_patch(p, seed), defects=[spec])
        found = [d for d in detect_defects(f.image, MM_PER_PX) if d.kind == "scratch" and d.length_px > 500]
        assert len(found) == 1, (seed, found)
        ends = np.array(geometry(spec, []).scratch_ends_px())
        ex, ey = lens.distort_px(ends[:, 0], ends[:, 1])
        line = np.array(found[0].line_px)
        for px, py in zip(ex, ey):
            if not (2.0 < px < 1277.0):
                continue  # the frame cuts this end
            assert float(np.min(np.hypot(line[[0, -1], 0] - px, line[[0, -1], 1] - py))) <= 5.0, \
                (seed, (px, py), line[[0, -1]])


def test_a_mark_runs_along_the_hatch_when_it_crosses_few_of_its_lines_and_the_hatch_is_a_mirrored_pair():
    """``is_along_hatch``: within 7.5 deg of a family and crossing at most 8 px of its lines
    over its length; when the two families read are no mirrored pair (a scratch drew one
    reading to itself), every mark within 7.5 deg is along it, as before."""
    from station.vision.defects import DefectConfig
    from station.vision.defects.common import is_along_hatch

    cfg = DefectConfig()
    hatch = (30.0, 150.0)
    assert is_along_hatch(25.0, 50.0, hatch, cfg)  # 4.4 px across
    assert not is_along_hatch(25.0, 200.0, hatch, cfg)  # 17 px across
    assert is_along_hatch(29.0, 200.0, hatch, cfg) and is_along_hatch(151.5, 200.0, hatch, cfg)
    assert not is_along_hatch(40.0, 20.0, hatch, cfg)  # off the hatch
    assert is_along_hatch(30.0, 200.0, (24.3, 150.0), cfg)  # no mirrored pair: the angle alone


def test_a_groove_that_fades_is_no_scratch_and_a_cut_furrow_is():
    """``_square_end``: along a line of the hatch, a dark band that fades over tens of
    px (a groove's amplitude along its length) has no square end; the same band cut off
    square (a furrow), blurred by the camera alone, has."""
    from station.vision.defects import DefectConfig
    from station.vision.defects.examine import _square_end

    h, w = 120, 400
    level = np.full((h, w), 150.0, np.float32)
    xs = np.arange(w, dtype=np.float32)
    across = np.exp(-0.5 * ((np.arange(h, dtype=np.float32) - 60.0) / 1.5) ** 2)[:, None]
    fade = 0.25 * np.exp(-0.5 * ((xs - 200.0) / 45.0) ** 2)[None, :]
    cut = 0.25 * ((xs >= 140) & (xs <= 260)).astype(np.float32)[None, :]
    line = (np.linspace(140.0, 260.0, 25), np.full(25, 60.0))
    m = dict(line=line, blur=1.5, width=3.0)
    for band, square in ((fade, False), (cut, True)):
        dark = cv2.GaussianBlur((across * band).astype(np.float32), (0, 0), 1.5)
        img = level * (1.0 - dark)
        assert _square_end(img, level, 0, 0, m, DefectConfig()) == (square, False)


def test_a_piece_of_a_longer_scratch_is_not_reported_beside_it_but_a_crossing_scratch_is():
    """``drop_scratch_pieces``: a scratch whose cover lies mostly in a longer one's is a
    piece of it, measured from its own candidate first; a scratch crossing it is not."""
    from station.vision.defects import Defect
    from station.vision.defects.tracking import drop_scratch_pieces
    from station.vision.defects.examine import ExaminedCandidate

    def scratch(x0, y0, x1, y1, length):
        cover = np.zeros((200, 300), np.uint8)
        cv2.line(cover, (x0, y0), (x1, y1), 1, 9)
        d = Defect("scratch", (x0 + x1) / 2, (y0 + y1) / 2, length, 3.0, 0.9, 30.0, 1.0, 0.5, 20.0, False)
        return ExaminedCandidate(d, cover.astype(bool), (0, 0, 300, 200), cover.astype(bool))

    whole, piece = scratch(20, 20, 260, 160, 278.0), scratch(80, 55, 160, 102, 93.0)
    crossing = scratch(60, 180, 200, 20, 212.0)
    kept = drop_scratch_pieces([piece, whole, crossing])
    assert [ex.defect.length_px for ex in kept] == [278.0, 212.0]


@pytest.mark.parametrize("angles, lengths", [((0.0, 50.0), (180.0, 140.0)), ((80.0, 130.0), (150.0, 150.0)),
                                              ((5.0, 60.0), (400.0, 300.0)), ((-5.0, 45.0), (1000.0, 500.0))],
                         ids=["X", "X both steep", "long X", "across the frame"])
def test_two_scratches_crossing_are_both_found_and_measured(angles, lengths):
    """Two scratches that cross are one candidate (an X); measured as one it read their
    bisector and neither, or one of them (13 of 36 found over these four crossings on
    three walls each before ``split_furrows``): each is now found, its length in tolerance."""
    p = FrameParams(groove_depth=0.06, grain=0.02, blotch=0.03, blur_sigma_px=1.3, gain_e_per_dn=20.0)
    for seed in range(3):
        rng = np.random.default_rng(int(angles[1]) * 10 + seed)
        cx, cy = 640 + rng.uniform(-100, 100), 512 + rng.uniform(-100, 100)
        specs = [DefectSpec("scratch", cx, cy, lengths[0], 3.5, angles[0], 0.6, None, 1000 + seed),
                 DefectSpec("scratch", cx + rng.uniform(-10, 10), cy + rng.uniform(-10, 10), lengths[1], 3.0,
                            angles[1], 0.6, None, 2000 + seed)]
        f = render_frame(p, [], seed=700 + seed, defects=specs)
        truths = [d.with_scale(MM_PER_PX) for d in f.defects]
        found = detect_defects(f.image, MM_PER_PX)
        pairs, false = match(truths, found, MM_PER_PX)
        assert not false and all(d is not None and d.kind == "scratch" for _t, d in pairs), \
            (seed, [(e.kind, round(e.length_px), round(e.angle_deg)) for e in found])
        for t, d in pairs:
            assert _within(d.length_mm, t.length_mm), (seed, t.length_mm, d.length_mm)


@pytest.mark.parametrize("scratch, pore, frame_seed, sized", [
    ((320.0, 256.0, 250.0, 3.0, 70.0, 0.5, 1), (330.3, 284.2, 40.0, 30.0, 10.0, 0.35, 2), 7, False),
    ((287.0, 253.6, 204.0, 4.64, 125.5, 0.68, 12), (280.7, 262.4, 34.3, 31.3, 43.4, 0.22, 112), 1012, True),
    ((308.3, 267.6, 248.9, 5.7, 92.1, 0.65, 19), (309.8, 225.7, 47.5, 31.1, 46.3, 0.22, 119), 1019, True),
    ((353.6, 254.6, 240.6, 5.62, 159.6, 0.52, 24), (332.0, 262.6, 30.9, 23.4, 129.8, 0.4, 124), 1024, True),
], ids=["0.40 mm pore", "0.34 mm pore", "0.48 mm pore", "0.31 mm pore"])
def test_a_pore_on_a_scratchs_line_is_found_and_the_scratch_kept_whole(scratch, pore, frame_seed, sized):
    """A pore on a scratch's line is one candidate with it. The scratch measured, the pore
    was never read, and the scratch's part beyond it went with it (the first case: a
    2.5 mm scratch read 1.47 mm; all four pores lost, each 0.3-0.5 mm, over the limit). What
    a seed's scratch leaves is examined on its own (``frame._seed_rest``), and the pieces
    are joined through the pore (``_scratch_gap``): both found, the scratch's length in
    tolerance and, where the pore is the darker by far, the pore's too (the first pore,
    barely darker than the scratch, takes a little of it in: 0.46 mm)."""
    specs = [DefectSpec("scratch", *scratch[:6], None, scratch[6]), DefectSpec("pore", *pore[:6], None, pore[6])]
    f = render_frame(FrameParams(**SMALL), [], seed=frame_seed, defects=specs)
    truths = [d.with_scale(MM_PER_PX) for d in f.defects]
    found = detect_defects(f.image, MM_PER_PX)
    pairs, false = match(truths, found, MM_PER_PX)
    report = [(e.kind, round(e.x_px), round(e.y_px), round(e.length_mm, 3)) for e in found]
    assert not false and all(d is not None and d.kind == t.kind for t, d in pairs), report
    for t, d in pairs:
        if t.kind == "scratch" or sized:
            assert _within(d.length_mm, t.length_mm), (t.kind, t.length_mm, report)


@pytest.mark.parametrize("seed, envelope", [(4300001, "station"), (4300003, "station"), (4300019, "station"),
                                            (4300044, "station"), (4300056, "station"), (4410002, "wide"),
                                            (4410069, "wide")])
def test_a_scratch_through_a_pore_read_as_one_mark_is_read_apart_from_it(seed, envelope):
    """Bench frames with each pore drawn on a scratch's line (``pores_on_scratches=1``)
    where the seed of the two, read whole, was one mark: a 0.39 mm pore on a 0.97 mm
    scratch read as a 0.71 x 0.47 mm pore (4300003), and a 0.46 mm pore on a 0.85 mm
    scratch 0.055 mm wide as a 0.56 mm one (4300019), the scratch lost each time; a 1.68 mm
    scratch through two pores lost (4300001); a 0.58 mm scratch whose arms beyond a 0.33 mm
    pore are 12 px each, too short for an axis of their own (4300044); a thin 1.91 mm
    scratch through two 0.41 mm pores, its seed no more than the stretch between them
    (4300056: read 1.41 mm, one pore lost); on the wide envelope's walls, a 0.44 mm scratch
    whose one 22 px arm beside a 0.23 mm pore, in a band of deep grooves' residue, read as
    no line (4410002), and a 0.55 mm one whose arm below a 0.34 mm pore is as wide as it
    is long, its own axis across the scratch (4410069). The scratch is read on the line of
    its arms with the pores' blobs hidden (``wall.line_through_blob``), the pores from what
    it leaves: every defect over the limit is found as its kind, and the pores' and
    scratches' lengths are within the tolerance."""
    f = random_defect_frame(seed, None, envelope=envelope, pores_on_scratches=1.0)
    found = detect_defects(f.image, MM_PER_PX)
    pairs, false = match(f.defects, found, MM_PER_PX)
    report = [(e.kind, round(e.x_px), round(e.y_px), round(e.length_mm, 3)) for e in found]
    assert not false, report
    over = [(t, d) for t, d in pairs if above_limit(t.kind, t.length_mm, t.width_mm)]
    assert {"pore", "scratch"} <= {t.kind for t, _d in over}
    for t, d in over:
        assert d is not None and d.kind == t.kind, (t.kind, t.length_mm, report)
        if t.kind in ("pore", "scratch"):
            assert _within(d.length_mm, t.length_mm), (t.kind, t.length_mm, report)


@pytest.mark.parametrize("seed, at", [(3220041, (1125, 602)), (3220090, (209, 576))],
                         ids=["an X of groove pieces", "a groove across a scratch"])
def test_what_a_groove_piece_or_a_crossing_leaves_of_its_seed_is_no_pore(seed, at):
    """The rest of a seed (``frame._seed_rest``) on the wide walls broken 20 %: an X of two
    groove pieces, measured as scratches and dropped as the grooves' pieces, left a 0.22 mm
    "pore" at its middle (``_drop_rests_of_dropped`` takes it with them); a 16 px region
    where a groove crosses a true scratch read as a 0.17 mm pore (a rest's mark must hold
    a rest's area). Neither is reported, and every true defect of the frames is found."""
    f = random_defect_frame(seed, None, mm_per_px=MM_PER_PX, envelope="wide", groove_breaks=0.2)
    found = detect_defects(f.image, MM_PER_PX)
    pairs, false = match(f.defects, found, MM_PER_PX)
    assert not [d for d in found if d.kind == "pore" and np.hypot(d.x_px - at[0], d.y_px - at[1]) < 15], \
        [(d.kind, round(d.x_px), round(d.y_px)) for d in found]
    assert not false and all(d is not None and d.kind == t.kind for t, d in pairs
                             if above_limit(t.kind, t.length_mm, t.width_mm))


@pytest.mark.parametrize("shape_seed, hatch", [(187, 150.0), (205, 30.0), (231, 150.0), (142, 30.0)])
def test_a_scratch_bent_along_the_hatch_in_its_middle_is_one_scratch_of_its_length(shape_seed, hatch):
    """A 9 mm scratch bent in an S (its second mode ~2 sigma of the twin's) whose chord is
    clear of the hatch but whose middle runs along a groove direction: the wall model's
    grooves take that stretch in, and it was read as one or two pieces of 3.4-4.7 mm
    (12 of 12 over these shapes and both hatch families, 11 with a second piece
    reported apart). Its furrow is now followed on past where the grooves' removal lost
    it (``_track_on``) and its pieces joined (``_scratch_gap``): one scratch, its length
    within tolerance, its centre line reported end to end."""
    c2 = float(np.random.default_rng(shape_seed).normal(0, 0.012, 2)[1])
    angle = hatch + float(np.degrees(np.arctan(2 * np.pi * c2)))  # the S's middle along the hatch
    spec = DefectSpec("scratch", 640, 512, 900.0, 4.0, angle, 0.6, None, shape_seed)
    f = render_frame(FrameParams(), [], seed=900 + shape_seed, defects=[spec])
    truths = [d.with_scale(MM_PER_PX) for d in f.defects]
    found = detect_defects(f.image, MM_PER_PX)
    pairs, false = match(truths, found, MM_PER_PX)
    (t, d), = pairs
    assert d is not None and not false, [(e.kind, round(e.length_px), round(e.angle_deg)) for e in found]
    assert _within(d.length_mm, t.length_mm), (d.length_mm, t.length_mm)
    line = np.array(d.line_px)
    assert abs(float(np.hypot(*np.diff(line, axis=0).T).sum()) - d.length_px) <= 0.02 * d.length_px
    assert "line_px" not in d.to_dict()


@pytest.mark.parametrize("angle, gap_at, gap_px, frame_seed", [(44.0, 80.0, 30.0, 80), (136.0, -120.0, 40.0, 78),
                                                              (75.0, 150.0, 25.0, 79)])
def test_a_thin_scratch_that_fades_for_a_stretch_is_one_scratch(angle, gap_at, gap_px, frame_seed):
    """A 1.5 px scratch fades to nothing for a stretch (its width varies by half along it;
    beside a groove that darkens its flanks it leaves no furrow of its own): the
    whole-surface bench read a 12.9 mm scratch in one frame as a 7.5 mm scratch and a
    5.1 mm "false" one, 0.3 mm apart, in line within 1.4 deg and 1.4 px. Two pieces in
    line to their core across a gap a fifth of their length or less are one scratch
    (``tracking._in_line``). The faded stretch here: the frame rendered again without the
    scratch, its pixels taken there."""
    spec = DefectSpec("scratch", 640, 512, 930.0, 1.5, angle, 0.6, None, 5)
    f = render_frame(FrameParams(), [], seed=frame_seed, defects=[spec])
    clean = render_frame(FrameParams(), [], seed=frame_seed).image
    yy, xx = np.mgrid[0:f.image.shape[0], 0:f.image.shape[1]]
    along = (xx - 640) * np.cos(np.radians(angle)) + (yy - 512) * np.sin(np.radians(angle))
    image = np.where((along >= gap_at) & (along < gap_at + gap_px), clean, f.image)
    truth = f.defects[0].with_scale(MM_PER_PX)
    found = detect_defects(image, MM_PER_PX)
    report = [(e.kind, round(e.x_px), round(e.y_px), round(e.length_px)) for e in found]
    scratches = [d for d in found if d.kind == "scratch"]
    assert len(found) == 1 and len(scratches) == 1, report
    assert _within(scratches[0].length_mm, truth.length_mm), (truth.length_mm, report)


def test_two_scratches_in_line_across_a_long_gap_stay_two():
    """The in-line join is for a gap short against both pieces: a 4 mm scratch with its
    middle 1 mm missing (pieces of 2 and 1 mm) is two scratches."""
    spec = DefectSpec("scratch", 640, 512, 400.0, 1.5, 44.0, 0.6, None, 5)
    f = render_frame(FrameParams(), [], seed=77, defects=[spec])
    clean = render_frame(FrameParams(), [], seed=77).image
    yy, xx = np.mgrid[0:f.image.shape[0], 0:f.image.shape[1]]
    along = (xx - 640) * np.cos(np.radians(44.0)) + (yy - 512) * np.sin(np.radians(44.0))
    image = np.where((along >= 0.0) & (along < 100.0), clean, f.image)
    found = detect_defects(image, MM_PER_PX)
    lengths = sorted(round(d.length_mm, 2) for d in found if d.kind == "scratch")
    assert len(found) == 2 and len(lengths) == 2, lengths
    assert abs(lengths[0] - 1.0) <= 0.1 and lengths[1] < 3.0, lengths

def test_a_pore_or_one_bent_scratch_is_one_mark_and_an_x_is_two_furrows():
    """``split_furrows`` splits only what crossing furrows leave: a disc of any size (a band
    through a blob always holds pixels; the first version split 0.4-0.47 mm pores in two,
    29 false pores per 100 frames of the bench) and one bent scratch stay one mark."""
    from station.vision.defects.wall import split_furrows

    for diameter in (40, 50, 60, 80, 100):
        m = np.zeros((160, 160), np.uint8)
        cv2.circle(m, (80, 80), diameter // 2, 1, -1)
        assert split_furrows(m.astype(bool)) == [], diameter
    t = np.linspace(0.0, 1.0, 400)
    bent = np.zeros((200, 1100), np.uint8)
    pts = np.column_stack([50 + 1000 * t, 100 + 25 * np.sin(np.pi * t)]).astype(np.int32)
    cv2.polylines(bent, [pts], False, 1, 6)
    assert split_furrows(bent.astype(bool)) == []
    x = np.zeros((300, 400), np.uint8)
    cv2.line(x, (50, 150), (350, 150), 1, 6)
    cv2.line(x, (120, 40), (260, 260), 1, 6)
    found = [float(np.rad2deg(a)) for _x, _y, a, _b in split_furrows(x.astype(bool))]

    def off(a: float, b: float) -> float:
        return abs((a - b + 90.0) % 180.0 - 90.0)

    assert len(found) == 2 and sorted(min(off(a, 0.0), off(a, 57.5)) for a in found)[1] <= 2.0, found
    assert {off(a, 0.0) < off(a, 57.5) for a in found} == {True, False}, found


def test_a_scratch_ending_under_a_pore_carries_the_pores_chord_in_its_length_uncertainty():
    """Where a scratch read past a pore ends under it, no frame shows where: its extent
    stops at the pore's near edge or runs on to its far edge with the pore's skirt (bench
    frame 4300083: 0.574 mm for 0.513, the true end 0.03 mm inside the far edge, the fit's
    u 0.020 mm). That end adds the pore's chord (its RMS from an edge, chord / sqrt 3) to
    the length's uncertainty, and the error is within 2u; a scratch whose ends lie clear
    of the pore on it keeps the fit's own (4300019: under 0.05 mm)."""
    for seed, wide in ((4300083, True), (4300019, False)):
        f = random_defect_frame(seed, None, pores_on_scratches=1.0)
        found = detect_defects(f.image, MM_PER_PX)
        pairs, _false = match(f.defects, found, MM_PER_PX)
        ((t, d),) = [(t, d) for t, d in pairs if t.kind == "scratch"]
        assert d is not None and d.kind == "scratch", found
        assert abs(d.length_mm - t.length_mm) <= 2.0 * d.size_u_mm, (seed, d.length_mm, t.length_mm, d.size_u_mm)
        assert (d.size_u_mm > 0.05) == wide, (seed, d.size_u_mm)


def test_a_line_through_a_blob_is_found_only_where_thin_arms_cross_it():
    """``line_through_blob``: a disc with a thin line through it, off its middle and with
    arms of unequal length, gives the line (its direction within 2 deg, through the
    disc's centre within 2 px) and the disc (no arm); a disc alone, a line alone, a line
    that passes beside the disc, and arms as wide as the disc give nothing."""
    from station.vision.defects.wall import line_through_blob

    def off(a: float, b: float) -> float:
        return abs((a - b + 90.0) % 180.0 - 90.0)

    for angle, shift in ((20.0, 0.0), (137.0, 12.0), (95.0, -20.0)):
        m = np.zeros((200, 240), np.uint8)
        ux, uy = np.cos(np.deg2rad(angle)), np.sin(np.deg2rad(angle))
        cx, cy = 120 + shift * ux, 100 + shift * uy
        cv2.line(m, (int(120 - 80 * ux), int(100 - 80 * uy)), (int(120 + 80 * ux), int(100 + 80 * uy)), 1, 5)
        cv2.circle(m, (int(round(cx)), int(round(cy))), 22, 1, -1)
        got = line_through_blob(m.astype(bool), min_arm_px=10.0)
        assert got is not None, angle
        (x, y, a, _bend), blob = got
        assert off(float(np.rad2deg(a)), angle) <= 2.0, (angle, np.rad2deg(a))
        assert abs((cx - x) * -np.sin(a) + (cy - y) * np.cos(a)) <= 2.0
        ys, xs = np.nonzero(blob)
        assert np.hypot(xs - cx, ys - cy).max() <= 24.0  # the disc, no arm
    disc = np.zeros((200, 240), np.uint8)
    cv2.circle(disc, (120, 100), 22, 1, -1)
    assert line_through_blob(disc.astype(bool)) is None
    line = np.zeros((200, 240), np.uint8)
    cv2.line(line, (40, 100), (200, 100), 1, 5)
    assert line_through_blob(line.astype(bool)) is None
    beside = disc.copy()
    cv2.line(beside, (40, 130), (200, 130), 1, 5)
    cv2.line(beside, (120, 110), (120, 130), 1, 5)  # joined to the disc by a stub
    assert line_through_blob(beside.astype(bool), min_arm_px=10.0) is None
    broad = disc.copy()
    cv2.line(broad, (20, 100), (220, 100), 1, 30)
    assert line_through_blob(broad.astype(bool), min_arm_px=10.0) is None


def test_the_bench_draws_scratches_along_the_hatch_when_asked():
    from sim.camera.defects import random_scratch_angle

    def off_hatch(a):
        return min(abs((a - g + 90.0) % 180.0 - 90.0) for g in (25.0, 155.0))

    rng = np.random.default_rng(5)
    along = [off_hatch(random_scratch_angle(rng, 25.0, within_deg=7.5)) for _ in range(400)]
    assert max(along) <= 7.5 and min(along) < 0.5
    assert min(off_hatch(random_scratch_angle(rng, 25.0)) for _ in range(400)) >= 10.0
    with pytest.raises(ValueError, match="within_deg"):
        random_scratch_angle(rng, 25.0, within_deg=0.0)


# ---------------------------------------------------------------- clean walls and rims
def test_clean_walls_give_no_defects():
    """The honing cross-hatch (grooves up to 24 % deep), grain, blotches and vignetting of
    the station envelope, and holes with clean rims: nothing is a defect."""
    for seed in range(92001, 92007):
        f = random_defect_frame(seed, {}, **SMALL)
        found = detect_defects(f.image, MM_PER_PX)
        assert found == [], (seed, [(d.kind, d.x_px, d.y_px, d.length_mm) for d in found])


def test_a_clean_rim_gives_no_burr_or_chip_even_on_deep_grooves_and_low_contrast():
    p = FrameParams(wall_level_dn=140.0, hole_level_dn=84.0, groove_depth=0.08, grain=0.03, blotch=0.05,
                    blur_sigma_px=1.8, gain_e_per_dn=25.0, read_noise_dn=2.0, vignetting=0.35, **SMALL)
    holes = [HoleSpec(180.2, 200.7, 70.0), HoleSpec(450.6, 300.1, 95.0)]
    for seed in (1, 2, 3):
        f = render_frame(p, holes, seed=seed)
        found = detect_defects(f.image, MM_PER_PX)
        assert [d for d in found if d.kind in ("burr", "chip")] == []


def test_the_honing_directions_are_read_from_the_frame():
    f = random_frame(3)
    small = cv2.resize(f.image.astype(np.float32), (640, 512), interpolation=cv2.INTER_AREA)
    darkness = 1.0 - small / cv2.GaussianBlur(small, (0, 0), 8.0)
    a1, a2 = honing_directions(darkness, np.ones(darkness.shape, bool))
    assert a1 == pytest.approx(30.0, abs=0.3) and a2 == pytest.approx(150.0, abs=0.3)


def test_a_hatch_of_another_angle_whose_families_differ_in_strength_is_read():
    """A part honed at 22 deg (plateau honing specifies 20-35 deg) whose two families'
    power differs 5x (the grooves fade along their lengths): both are read, not the
    +/-30 deg fallback, and the clean wall gives no defect (it gave seven "scratches")."""
    f = random_defect_frame(1063018, {}, mm_per_px=MM_PER_PX, hatch_deg=22.0)
    small = cv2.resize(f.image.astype(np.float32), (640, 512), interpolation=cv2.INTER_AREA)
    darkness = 1.0 - small / cv2.GaussianBlur(small, (0, 0), 8.0)
    a1, a2 = honing_directions(darkness, np.ones(darkness.shape, bool))
    assert a1 == pytest.approx(22.0, abs=0.3) and a2 == pytest.approx(158.0, abs=0.3)
    assert detect_defects(f.image, MM_PER_PX) == []


@pytest.mark.parametrize("hatch, seed", [(15.0, 181015), (45.0, 180022), (65.0, 182001)])
def test_a_hatch_outside_plateau_honings_angles_is_read_and_its_grooves_are_no_scratches(hatch, seed):
    """Honing makes other angles than plateau honing's 20-35 deg (helical slide honing:
    60-75): a search of 18-42 deg read 15, 45 and 65 deg hatches as +/-30, and the clean
    walls' grooves became "scratches" of 0.36-2.5 mm (9 on the first seed, 8 on the
    second; 39 and 10 over 25 clean frames of each angle)."""
    f = random_defect_frame(seed, {}, mm_per_px=MM_PER_PX, hatch_deg=hatch)
    small = cv2.resize(f.image.astype(np.float32), (640, 512), interpolation=cv2.INTER_AREA)
    darkness = 1.0 - small / cv2.GaussianBlur(small, (0, 0), 8.0)
    a1, a2 = honing_directions(darkness, np.ones(darkness.shape, bool))
    assert a1 == pytest.approx(hatch, abs=0.3) and a2 == pytest.approx(180.0 - hatch, abs=0.3)
    assert detect_defects(f.image, MM_PER_PX) == []


def test_a_hatch_whose_weaker_family_is_faint_is_read_and_its_grooves_are_no_scratches():
    """A 45 deg hatch at 0.008 mm/px under the wide envelope (bench seed 440009) whose
    families stand 25x and 4.5x above the median direction's power (the weaker 18 % of
    the stronger): it fell back to +/-30 deg, and five of the 45 deg family's grooves
    were reported as scratches of 1.3-6.4 mm beside the frame's seven true defects."""
    from station.vision.grooves import frame_hatch

    mm = 0.008
    f = random_defect_frame(440009, None, mm_per_px=mm, envelope="wide", hatch_deg=45.0, texture_scale=0.010 / mm)
    a1, a2 = frame_hatch(f.image, [(h.x_px, h.y_px, h.diameter_px / 2.0) for h in f.holes])
    assert a1 == pytest.approx(45.0, abs=0.3) and a2 == pytest.approx(-45.0, abs=0.3)
    found = detect_defects(f.image, mm)
    pairs, false = match(f.defects, found, mm)
    assert [found[i] for i in false] == []
    assert len(f.defects) == 7 and all(d is not None and d.kind == t.kind for t, d in pairs)


def test_a_lone_scratchs_flank_and_an_artefact_are_no_hatch():
    """The weaker family's lower bar (4x the median direction) holds only for peaks that
    stand clear of their flanks: on a bare wall with a hole, a lone 160 px scratch's
    broad peak paired its flank (73x) with an artefact near the frame's axis (4.2x), the
    hatch was read at 8.6 / -15 deg, and the scratch was taken for a groove and lost."""
    from station.vision.grooves import frame_hatch

    p = FrameParams(wall_level_dn=120.0, hole_level_dn=40.0, groove_depth=0.0, grain=0.005, blotch=0.0,
                    blur_sigma_px=1.3, gain_e_per_dn=60.0, read_noise_dn=0.5, vignetting=0.0, **SMALL)
    spec = DefectSpec("scratch", 320.3, 256.2, 160.0, 3.0, 159.0, 0.6, shape_seed=912)
    f = render_frame(p, [HoleSpec(80.0, 80.0, 70.0)], seed=62, defects=[spec])
    assert frame_hatch(f.image, [(80.0, 80.0, 35.0)]) == (30.0, -30.0)
    assert [d.kind for d in detect_defects(f.image, MM_PER_PX)] == ["scratch"]


def test_a_faint_scratch_beside_a_strong_one_on_a_frame_without_a_hole_is_read_under_their_shared_blur():
    """No hole and no blur given: each scratch read its own blur, and a faint 0.43 x 0.023
    mm one (bench seed 260088, 1.66 px of blur) read under 1.2 px of it came out too faint
    to be a scratch, beside a 0.74 mm one that reads the frame's blur to 0.07 px. The
    frame is examined again under the scratches' reads combined."""
    f = random_defect_frame(260088, None, mm_per_px=MM_PER_PX)
    assert f.holes == []
    found = detect_defects(f.image, MM_PER_PX)
    pairs, false = match(f.defects, found, MM_PER_PX)
    assert false == []
    faint = [(t, d) for t, d in pairs if t.kind == "scratch" and t.length_mm < 0.5]
    assert len(faint) == 1
    t, d = faint[0]
    assert d is not None and d.kind == "scratch"
    assert abs(d.length_mm - t.length_mm) <= 0.02 and abs(d.width_mm - t.width_mm) <= 0.02
    assert abs(d.width_mm - t.width_mm) <= 2.0 * d.width_u_mm
    assert all(d is not None and d.kind == t.kind for t, d in pairs)


def test_a_scratch_found_under_its_own_blur_stays_when_the_frames_shared_blur_drops_it():
    """The frame's shared blur is known only so well: a 0.64 x 0.016 mm scratch (bench
    seed 490058, 0.0085 mm/px, 1.74 px of blur, no hole) read contrast 0.111 under its own
    1.56 px and 0.104 under the frame's 1.49, under the 0.11 bar: found under either, it is
    a scratch."""
    mm = 0.0085
    f = random_defect_frame(490058, None, mm_per_px=mm, hatch_deg=35.0, texture_scale=0.010 / mm)
    assert f.holes == []
    found = detect_defects(f.image, mm)
    pairs, false = match(f.defects, found, mm)
    assert [found[i] for i in false] == []
    assert len(pairs) == 3 and all(d is not None and d.kind == t.kind for t, d in pairs)


def test_a_blur_known_to_within_a_variance_widens_a_thin_scratchs_width_uncertainty():
    """A blur given exactly leaves a thin scratch's width as certain as its profile; one
    shared by the frame's scratches (``KnownBlur``) carries its variance into the width
    (a thin scratch's width and contrast trade off against the blur)."""
    from station.vision.defects.examine import KnownBlur

    f = random_defect_frame(260088, None, mm_per_px=MM_PER_PX)
    b = f.params.blur_sigma_px

    def thin(blur):
        return [d for d in detect_defects(f.image, MM_PER_PX, blur_px=blur)
                if d.kind == "scratch" and d.length_mm < 0.5]

    exact, vague = thin(b), thin(KnownBlur(b, 0.15**2))
    assert len(exact) == len(vague) == 1
    assert vague[0].width_mm == pytest.approx(exact[0].width_mm, abs=1e-9)
    assert vague[0].width_u_mm > 1.3 * exact[0].width_u_mm


def test_the_scratches_shared_blur_counts_the_prior_once():
    """Each scratch's own read holds the prior (``BLUR_PRIOR_PX``); combined, the prior
    is counted once: the result is the prior and every read's own evidence together."""
    from station.vision.defects.examine import ExaminedCandidate, shared_blur
    from station.vision.defects.scratches import BLUR_PRIOR_PX

    pb, pv = BLUR_PRIOR_PX[0], BLUR_PRIOR_PX[1] ** 2
    data = [(1.9, 0.04), (1.7, 0.09), (2.1, 0.25)]  # each scratch's own evidence (blur, variance)

    def read(b, v):  # what a scratch reports: its evidence and the prior combined
        w = 1.0 / v + 1.0 / pv
        return (b / v + pb / pv) / w, 1.0 / w

    empty = np.zeros((1, 1), bool)
    exs = [ExaminedCandidate(None, empty, blur_read=read(b, v)) for b, v in data]
    w = 1.0 / pv + sum(1.0 / v for _, v in data)
    expected = ((pb / pv + sum(b / v for b, v in data)) / w, 1.0 / w)
    got = shared_blur(exs + [ExaminedCandidate(None, empty), ExaminedCandidate(None, empty, blur_read=(pb, pv))])
    assert got == pytest.approx(expected, rel=1e-9)
    assert shared_blur([ExaminedCandidate(None, empty)]) is None


def test_one_long_scratch_on_a_bare_wall_is_no_hatch():
    """One strong direction is a scratch, not a hatch: without its mirror family the
    directions fall back to the default."""
    p = FrameParams(width_px=640, height_px=512, groove_depth=0.0)
    spec = DefectSpec("scratch", 320.0, 256.0, 400.0, 3.0, 40.0, None, None, 7)
    f = render_frame(p, [], seed=11, defects=[spec])
    small = cv2.resize(f.image.astype(np.float32), (320, 256), interpolation=cv2.INTER_AREA)
    darkness = 1.0 - small / cv2.GaussianBlur(small, (0, 0), 8.0)
    assert honing_directions(darkness, np.ones(darkness.shape, bool), 30.0) == (30.0, 150.0)



@pytest.mark.parametrize("angle", [29.7, 151.0])
def test_a_scratch_along_the_nominal_hatch_on_a_wall_without_grooves_is_found(angle):
    """A wall whose grooves do not show falls back to the nominal +/-30 deg hatch, and a
    2.6 mm scratch within a few degrees of it was averaged away as that family's line
    mean and lost (no defect reported on either frame). Its peak near the nominal lies in
    a few of the frame's tiles, no family's lines cross the wall there: the frame has no
    hatch, and the scratch is found and measured."""
    spec = DefectSpec("scratch", 700.2, 600.3, 260.0, 5.0, angle, 0.6, shape_seed=3)
    f = render_frame(FrameParams(groove_depth=0.0), [], seed=0, defects=[spec])
    small = cv2.resize(f.image.astype(np.float32), (640, 512), interpolation=cv2.INTER_AREA)
    darkness = 1.0 - small / cv2.GaussianBlur(small, (0, 0), 8.0)
    assert honing_directions(darkness, np.ones(darkness.shape, bool)) == ()
    (t,) = [d.with_scale(MM_PER_PX) for d in f.defects]
    found = detect_defects(f.image, MM_PER_PX)
    pairs, false = match([t], found, MM_PER_PX)
    d = pairs[0][1]
    assert false == [] and d is not None and d.kind == "scratch", [(q.kind, q.x_px, q.y_px) for q in found]
    assert abs(d.length_mm - t.length_mm) <= max(0.1 * t.length_mm, 0.02)


def test_two_near_parallel_directions_on_one_side_of_the_axis_are_no_hatch():
    """A hatch's two families are mirrored about the bore's axis, each 6-84 deg off it. On
    a wall without grooves (seed 987014) a 0.69 mm scratch at 5.3 deg put a peak at 6.9
    deg, which was paired with one at 0.5 deg, on the same side of the axis, as a "hatch";
    the scratch was then taken for a groove and lost. A pair's second family must lie in
    the half-angles searched too: no hatch here, the nominal one stands, and both of the
    frame's scratches are found."""
    # two line families 1 and -8 deg off the axis: -8's mirror, 8, is within 8 deg of 1,
    # but 1 deg off the axis is no honing family
    yy, xx = np.mgrid[0:256, 0:320].astype(np.float64)
    darkness = 0.02 * np.random.default_rng(3).standard_normal(xx.shape)
    for line_deg in (1.0, 172.0):
        t = np.deg2rad(line_deg)
        darkness += 0.05 * np.cos(2 * np.pi * (np.cos(t) * yy - np.sin(t) * xx) / 9.0)
    assert honing_directions(darkness.astype(np.float32), np.ones(xx.shape, bool), 30.0) == (30.0, 150.0)
    f = random_defect_frame(987014, None, mm_per_px=MM_PER_PX, groove_depth=0.0)
    pairs, false = match(f.defects, detect_defects(f.image, MM_PER_PX), MM_PER_PX)
    assert false == []
    scratches = [(t, d) for t, d in pairs if t.kind == "scratch"]
    assert len(scratches) == 2
    for t, d in scratches:
        assert d is not None and d.kind == "scratch", t
        assert _within(d.length_mm, t.length_mm), (d.length_mm, t.length_mm)

# ---------------------------------------------------------------- the twin's part
def test_the_twin_renders_the_parts_defects_where_they_are_on_the_wall():
    from sim.camera.twin import CameraTwin, small_optics
    from sim.twins import TwinStation, load_scenario
    from sim.world import World, world_from_dict

    data = {
        "holes": [{"name": "hole_2", "axial_mm": 85.19, "angle_deg": 0.0, "diameter_mm": 0.7}],
        "defects": [
            {"name": "pore_a", "kind": "pore", "length_mm": 0.3, "width_mm": 0.25, "axial_mm": 85.79,
             "angle_deg": 2.0, "seed": 1},
            {"name": "burr_a", "kind": "burr", "length_mm": 0.15, "width_mm": 0.05, "hole": "hole_2", "at_deg": 90.0,
             "seed": 3},
        ],
    }
    world = world_from_dict(data)
    assert isinstance(world, World) and len(world.part.defects) == 2

    class Clock:
        t = 0.0

        def __call__(self):
            return self.t

    clock = Clock()
    twins = TwinStation(load_scenario(), clock=clock)
    world.attach(twins)
    z, c = twins.physics["Z"], twins.physics["C"]
    for ax in (z, c):
        ax.enable(True)
        assert ax.home()
    clock.t += 60.0
    cam = CameraTwin(world, z, c, small_optics(640, 512), seed=3)
    asyncio.run(cam.connect())
    assert z.start_move(85.19)
    clock.t += 60.0
    frame = asyncio.run(cam.grab())
    truth = {d.name: d for d in cam.last_truth.defects}
    assert set(truth) == {"pore_a", "burr_a"}
    # the pore's truth in the part's frame is the world's, and in px where the view puts it
    assert truth["pore_a"].axial_mm == pytest.approx(85.79, abs=1e-9)
    assert truth["pore_a"].part_angle_deg == pytest.approx(2.0, abs=1e-9)
    # the burr sits up the bore from its hole (at_deg 90: towards increasing axial = up)
    (_, hx, hy, *_rest) = cam.last_truth.holes[0]
    assert truth["burr_a"].y_px < hy - 30 and abs(truth["burr_a"].x_px - hx) < 1.0
    found = detect_defects(frame.image, MM_PER_PX)
    pairs, false = match(list(truth.values()), found, MM_PER_PX)
    assert not false and all(d is not None and d.kind == t.kind for t, d in pairs)


def test_a_scenario_defect_that_names_no_such_hole_is_refused():
    from sim.world import world_from_dict

    with pytest.raises(ValueError, match="no hole named"):
        world_from_dict({"defects": [{"name": "b", "kind": "burr", "length_mm": 0.1, "width_mm": 0.03,
                                      "hole": "hole_9"}]})
    with pytest.raises(ValueError, match="kind"):
        world_from_dict({"defects": [{"name": "x", "kind": "crack", "length_mm": 0.1, "width_mm": 0.03}]})


# ---------------------------------------------------------------- the CLI
runner = CliRunner()


def test_cli_json_is_one_object_with_the_defects(one_of_each, tmp_path):
    f, _ = one_of_each
    path = tmp_path / "wall.png"
    cv2.imwrite(str(path), f.image)
    result = runner.invoke(app, ["vision", "defects", str(path), "--mm-per-px", "0.01", "--json"])
    assert result.exit_code == 0, result.output
    out = json.loads(result.stdout)
    kinds = sorted(d["kind"] for d in out["defects"])
    assert kinds == ["burr", "chip", "pore", "scratch"]
    for d in out["defects"]:
        assert {"kind", "x_px", "y_px", "length_px", "width_px", "confidence", "size_mm", "size_u_mm"} <= set(d)
    table = runner.invoke(app, ["vision", "defects", str(path), "--mm-per-px", "0.01"])
    assert table.exit_code == 0 and "4 defect(s)" in table.stdout


def test_cli_takes_where_the_part_s_holes_show(one_of_each, tmp_path):
    """``--hole-at X,Y``: the hole there keeps its burr and chip; ``--no-holes``: the dark
    disc is a drilling the drawing does not have, a pore of its size (its rim not judged).
    Bad places are refused, naming the option."""
    f, _ = one_of_each
    path = tmp_path / "wall.png"
    cv2.imwrite(str(path), f.image)
    (hole,) = f.holes
    at = f"{hole.image_x_px:.1f},{hole.image_y_px:.1f}"
    placed = runner.invoke(app, ["vision", "defects", str(path), "--mm-per-px", "0.01", "--hole-at", at, "--json"])
    assert placed.exit_code == 0, placed.output
    assert sorted(d["kind"] for d in json.loads(placed.stdout)["defects"]) == ["burr", "chip", "pore", "scratch"]
    none = runner.invoke(app, ["vision", "defects", str(path), "--mm-per-px", "0.01", "--no-holes", "--json"])
    assert none.exit_code == 0, none.output
    found = json.loads(none.stdout)["defects"]
    assert not [d for d in found if d["kind"] in ("burr", "chip")], found
    drilling = [d for d in found if np.hypot(d["x_px"] - hole.image_x_px, d["y_px"] - hole.image_y_px) < 5.0]
    assert len(drilling) == 1 and drilling[0]["kind"] == "pore" \
        and abs(drilling[0]["length_px"] - hole.diameter_px) < 0.1 * hole.diameter_px, drilling
    for args, says in ((["--hole-at", "220;300"], "expected X,Y"),
                       (["--hole-at", at, "--no-holes"], "contradict")):
        bad = runner.invoke(app, ["vision", "defects", str(path), "--mm-per-px", "0.01", *args, "--json"])
        assert bad.exit_code == 2 and says in bad.stderr and "wall.png" in bad.stderr and bad.stdout == ""


@pytest.mark.parametrize("content", [b"not an image\n", b""])
def test_cli_bad_input_names_the_file(tmp_path, content):
    bad = tmp_path / "broken.png"
    bad.write_bytes(content)
    result = runner.invoke(app, ["vision", "defects", str(bad), "--mm-per-px", "0.01", "--json"])
    assert result.exit_code == 2
    assert "broken.png" in result.stderr and "not an image" in result.stderr
    assert "Traceback" not in result.output and result.stdout == ""


def test_cli_refuses_a_scale_that_is_not_positive(tmp_path):
    path = tmp_path / "w.png"
    cv2.imwrite(str(path), np.full((128, 128), 120, np.uint8))
    result = runner.invoke(app, ["vision", "defects", str(path), "--mm-per-px", "0", "--json"])
    assert result.exit_code == 2 and "w.png" in result.stderr and result.stdout == ""
    missing = runner.invoke(app, ["vision", "defects", str(tmp_path / "nope.png"), "--mm-per-px", "0.01"])
    assert missing.exit_code == 2 and "nope.png" in missing.stderr and "no such file" in missing.stderr


def test_clean_rims_on_dim_frames_with_deep_grooves_give_no_burr_or_chip():
    """The wide envelope's corner (grooves up to 15 % deep, 5-20 e-/DN, contrast down to
    30 %): a first crossing of the hole's share is a threshold's, so on a dim frame one
    noisy pixel moved a ray's edge by pixels (false "burrs"), and a groove that fades
    along its length, read on the ring averaged over both sides of the hole, was put back
    at the rim too deep or too shallow (false "chips"). These are the bench's clean wide
    frames the change was made on, at full size: before it, five of their rims gave a burr
    or a chip; ``station bench defects --envelope wide`` reports fresh seeds."""
    rims = []
    for seed in range(1070000, 1070060):
        f = random_defect_frame(seed, {}, mm_per_px=MM_PER_PX, envelope="wide")
        if not f.holes:
            continue
        found = detect_defects(f.image, MM_PER_PX)
        rims += [(seed, d.kind, round(d.x_px), round(d.y_px)) for d in found if d.kind in ("burr", "chip")]
    assert rims == []


def test_chips_on_a_rim_that_is_half_defect_stand_out_of_its_own_noise():
    """A 0.75 mm hole with two burrs and two chips over 42 % of its rim (station bench seed
    93005, blur 1.9 px): the MAD of the rim's deviations read 0.62 px of noise, the
    5-noise bar 3.1 px, and both chips (2.5 and 3.5 px high, 0.25 and 0.29 mm long) were
    missed. The noise is read again without what stands out of it: every rim defect found
    as its kind, its length within tolerance, and nothing else."""
    f = random_defect_frame(93005, mm_per_px=MM_PER_PX)
    rim = [t for t in f.defects if t.kind in ("burr", "chip")]
    assert sorted(t.kind for t in rim) == ["burr", "burr", "chip", "chip"]
    pairs, false = match(f.defects, detect_defects(f.image, MM_PER_PX), MM_PER_PX)
    assert not false
    for t, d in pairs:
        assert d is not None and d.kind == t.kind, (t.kind, t.x_px, t.y_px)
        assert _within(d.length_mm, t.length_mm), (t.kind, d.length_mm, t.length_mm)


def test_a_rim_defect_must_stand_out_of_the_rim_either_side_of_it():
    """Two clean wide frames where the wall's model is off along an arc of a rim (a groove
    tangent to it, a dark blotch beyond it): the whole arc's edge sits 0.3-0.7 px in, and
    noise on it crossed the 1 px bar as a 0.05 mm and a 0.13 mm "burr" (wide bench seed
    82000's clean frames 26 and 49). Measured against the rim either side of them, they
    are 0.8-0.9 px and dropped."""
    for seed in (1082026, 1082049):
        f = random_defect_frame(seed, {}, mm_per_px=MM_PER_PX, envelope="wide")
        found = detect_defects(f.image, MM_PER_PX)
        assert [(d.kind, round(d.x_px), round(d.y_px)) for d in found] == [], seed


def test_the_rims_level_either_side_of_a_defect():
    """``_flank_level``: the lower of the two flanks' medians past the blur's spill, never
    below 0; a flank cut off by an unread arc gives 0 (nothing to compare with)."""
    from station.vision.defects.rims import _flank_level

    n, step = 400, 0.5
    v = np.zeros(n)
    v[180:220] = 2.0  # the defect: 20 px of arc
    v[130:175] = 0.4  # one flank displaced...
    v[225:270] = 0.6  # ... and the other more
    valid = np.ones(n, bool)
    assert _flank_level(v, valid, True, 90.0, 110.0, 1.0, step) == pytest.approx(0.4)
    v[225:270] = -0.3  # a flank the other way: the rim is not displaced both sides
    assert _flank_level(v, valid, True, 90.0, 110.0, 1.0, step) == 0.0
    v[225:270] = 0.6
    valid[222:400] = False  # the right flank unread
    assert _flank_level(v, valid, False, 90.0, 110.0, 1.0, step) == 0.0
    # across theta = 0 on a whole rim: the left flank wraps round
    w = np.roll(v, -190)
    assert _flank_level(w, np.ones(n, bool), True, -5.0, 15.0, 1.0, step) == pytest.approx(0.4)


def test_a_groove_tangent_to_a_rim_or_a_scratch_ending_at_it_is_no_chip():
    """Wide bench frames: a deep groove tangent to a rim, whose two sides' profiles
    differ, was corrected with one side's depth up to the tangent point and the other's
    beyond it, and the step read as a 0.15 mm and a 0.07 mm "chip" (clean frames 1085048
    and 1082099); a scratch ending at a rim darkens the wall beside its region as well,
    read as a 0.07 mm "chip" next to it (frame 82083, whose true chip, 0.24 mm, is found
    within tolerance)."""
    for seed in (1085048, 1082099):
        f = random_defect_frame(seed, {}, mm_per_px=MM_PER_PX, envelope="wide")
        found = detect_defects(f.image, MM_PER_PX)
        assert [(d.kind, round(d.x_px), round(d.y_px)) for d in found] == [], seed
    f = random_defect_frame(82083, None, mm_per_px=MM_PER_PX, envelope="wide")
    chips = [d for d in detect_defects(f.image, MM_PER_PX) if d.kind == "chip"]
    (truth,) = [t for t in f.defects if t.kind == "chip"]
    assert len(chips) == 1
    assert np.hypot(chips[0].x_px - truth.image_x_px, chips[0].y_px - truth.image_y_px) * MM_PER_PX < 0.05
    assert abs(chips[0].length_mm - truth.length_mm) <= max(0.1 * truth.length_mm, 0.02)


def test_a_pore_beyond_a_rim_leaves_the_chip_between_them_whole():
    """Hatch 22 deg, bench seed 89000: a 0.26 mm chip points at a 0.41 mm pore 30 px
    beyond the rim. The marks' blurred skirt is left out of a rim only for marks that
    reach its band: the pore's reached the ring that calibrates the wall, left the rays
    through it out, and cut the chip in two (0.07 and 0.11 mm)."""
    f = random_defect_frame(89000, None, mm_per_px=MM_PER_PX, hatch_deg=22.0)
    (truth,) = [t for t in f.defects if t.kind == "chip" and abs(t.image_x_px - 296.7) < 1.0]
    near = [d for d in detect_defects(f.image, MM_PER_PX)
            if np.hypot(d.x_px - truth.image_x_px, d.y_px - truth.image_y_px) < 30.0]
    assert [d.kind for d in near] == ["chip"]
    assert abs(near[0].length_mm - truth.length_mm) <= max(0.1 * truth.length_mm, 0.02)


def test_a_pore_whose_region_covers_the_ring_beyond_a_chip_leaves_the_chip_whole():
    """Station envelope, hatch 28 deg, 0.009 mm/px with the texture in mm, bench seed
    680052: a 0.41 mm pore 24 px beyond a rim, its region itself (no skirt) over the
    ring that calibrates the wall's level beyond a 0.16 x 0.028 mm chip's middle. The
    rays through that ring were left out, and the chip read as two (0.045 and 0.058 mm,
    one of them false); their wall's level now comes from the rays either side."""
    mm = 0.009
    f = random_defect_frame(680052, None, mm_per_px=mm, hatch_deg=28.0, texture_scale=0.010 / mm)
    (truth,) = [t for t in f.defects if t.kind == "chip"]
    found = detect_defects(f.image, mm)
    near = [d for d in found if np.hypot(d.x_px - truth.image_x_px, d.y_px - truth.image_y_px) < 20.0]
    assert [d.kind for d in near] == ["chip"]
    assert abs(near[0].length_mm - truth.length_mm) <= max(0.1 * truth.length_mm, 0.02)
    assert abs(near[0].width_mm - truth.width_mm) <= max(0.1 * truth.width_mm, 0.02)
    pairs, false = match(f.defects, found, mm)
    assert false == []
    assert all(d is not None and d.kind == t.kind for t, d in pairs)


def test_a_scratch_across_a_rims_outer_ring_leaves_the_chip_under_it_found():
    """Station envelope, bench seed 190003: a found 1 mm scratch 27 px below a 64 px hole
    crosses the ring beyond the rim's band over 36 deg of arc, and a 0.18 x 0.064 mm chip
    lies under it. The rays through that ring were not read, and the chip was lost
    (a known limit since session 61); their wall's level now comes from the rays either
    side, and nothing false comes with it."""
    f = random_defect_frame(190003, None, mm_per_px=MM_PER_PX)
    (truth,) = [t for t in f.defects if t.kind == "chip"]
    found = detect_defects(f.image, MM_PER_PX)
    near = [d for d in found if np.hypot(d.x_px - truth.image_x_px, d.y_px - truth.image_y_px) < 20.0]
    assert [d.kind for d in near] == ["chip"]
    assert np.hypot(near[0].x_px - truth.image_x_px, near[0].y_px - truth.image_y_px) * MM_PER_PX < 0.05
    assert abs(near[0].length_mm - truth.length_mm) <= max(0.1 * truth.length_mm, 0.02)
    pairs, false = match(f.defects, found, MM_PER_PX)
    assert false == []


def test_a_groove_that_fades_along_its_length_is_read_on_each_side_of_the_hole():
    """One groove family at 30 deg whose depth fades along its lines, 8 % at a hole's
    centre and 0.08 % more per px (1-16 % over the patch): the two sides' profiles,
    joined linearly between their own pixels' places along the lines, give the depth
    across the hole's disc within 0.5 % (a switch from one side's depth to the other's
    at the centre was up to 4.7 % off there); one profile over both gives their mean, 8 %, to
    every pixel."""
    yy, xx = np.mgrid[0:120, 0:160].astype(np.float32)
    t = np.deg2rad(30.0)
    u = -np.sin(t) * xx + np.cos(t) * yy
    v = np.cos(t) * (xx - 80.0) + np.sin(t) * (yy - 60.0)
    depth = 0.08 + 0.0008 * v
    d = (depth * np.exp(-0.5 * ((np.mod(u, 14.0) - 7.0) / 1.2) ** 2)).astype(np.float32)
    use = np.hypot(xx - 80.0, yy - 60.0) > 25.0  # the ring; the hole's disc left out
    on_groove = np.abs(np.mod(u, 14.0) - 7.0) < 0.25
    near = (np.hypot(xx - 80.0, yy - 60.0) < 25.0) & on_groove
    sides = groove_profiles(d, xx, yy, use, (30.0,), sides_about=(80.0, 60.0))
    both = groove_profiles(d, xx, yy, use, (30.0,))
    assert np.max(np.abs(sides[near] - depth[near])) < 0.005
    assert np.median(both[near]) == pytest.approx(0.08, rel=0.1)
    assert np.max(np.abs(both[near] - depth[near])) > 0.015


def _dark_lines(shape, segments, width_px=2.0, depth=0.3, blur_px=1.2, noise=0.01, seed=0):
    """A residual (darkness) of dark straight segments ((x0, y0, x1, y1), ...) under a
    blur, with white noise."""
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float32)
    d = np.zeros(shape, np.float32)
    for x0, y0, x1, y1 in segments:
        ux, uy = x1 - x0, y1 - y0
        n = np.hypot(ux, uy)
        t = np.clip(((xx - x0) * ux + (yy - y0) * uy) / (n * n), 0.0, 1.0)
        dist = np.hypot(xx - (x0 + t * ux), yy - (y0 + t * uy))
        d = np.maximum(d, np.where(dist <= width_px / 2, depth, 0.0).astype(np.float32))
    d = cv2.GaussianBlur(d, (0, 0), blur_px)
    return d + np.random.default_rng(seed).normal(0.0, noise, shape).astype(np.float32)


def test_a_straight_furrow_runs_along_itself_and_crossing_grooves_residue_does_not():
    """``_along_share``: one straight furrow 70 deg off the x axis puts ~all its oriented
    energy along itself; the V and the X that deep crossing grooves leave (arms along the
    30 / 150 deg hatch) put almost none along their long axis, the hatch's bisector."""
    from station.vision.defects.examine import _along_share

    hatch = (30.0, 150.0)
    c, s = np.cos(np.deg2rad(70.0)), np.sin(np.deg2rad(70.0))
    furrow = _dark_lines((120, 120), [(60 - 45 * c, 60 - 45 * s, 60 + 45 * c, 60 + 45 * s)])
    region = cv2.GaussianBlur(furrow, (0, 0), 1.0) > 0.1
    assert _along_share(cv2.GaussianBlur(furrow, (0, 0), 1.0), region, 70.0, hatch) > 0.8
    c30, s30 = np.cos(np.deg2rad(30.0)), np.sin(np.deg2rad(30.0))
    v = _dark_lines((120, 160), [(80, 90, 80 - 60 * c30, 90 - 60 * s30), (80, 90, 80 + 60 * c30, 90 - 60 * s30)])
    x = _dark_lines((120, 160), [(80 - 60 * c30, 60 - 60 * s30, 80 + 60 * c30, 60 + 60 * s30),
                                 (80 - 60 * c30, 60 + 60 * s30, 80 + 60 * c30, 60 - 60 * s30)])
    for residue, bisector in ((v, 0.0), (x, 0.0), (x, 90.0)):
        rs = cv2.GaussianBlur(residue, (0, 0), 1.0)
        assert _along_share(rs, rs > 0.1, bisector, hatch) < 0.2


def test_deep_grooves_crossing_on_a_clean_wall_are_not_a_scratch():
    """Clean frames of the wide envelope's bench (seed 82000's clean set) where two deep
    grooves crossing left a V or an X of residue 6-25 deg off the hatch, taken for
    scratches of 0.17-1.27 mm before the along-share test: none now."""
    for seed in (1082022, 1082069, 1082078, 1082095):
        f = random_defect_frame(seed, {}, mm_per_px=MM_PER_PX, envelope="wide")
        found = detect_defects(f.image, MM_PER_PX)
        assert [d for d in found if d.kind == "scratch"] == [], seed


def test_a_deep_groove_running_into_a_rim_is_not_a_chip():
    """Wide-envelope frames where a deep groove (or two crossing) ran into a hole's rim and
    read as a chip of 0.11-0.20 mm; beyond a true chip the wall comes back, along these
    the darkness runs on (0.6-0.9 of the hole's). The true chip of the frame with defects
    is still found."""
    assert _chips_without_false_ones(((1082040, True), (82018, False), (85061, False))) == 1  # seed 85061's


def _chips_without_false_ones(cases) -> int:
    """Wide-envelope bench frames (seed, clean): no false chip in any, each true chip found
    as a chip; how many true chips there were."""
    true_chips = 0
    for seed, clean in cases:
        f = random_defect_frame(seed, {} if clean else None, mm_per_px=MM_PER_PX, envelope="wide")
        found = detect_defects(f.image, MM_PER_PX)
        pairs, false = match(f.defects, found, MM_PER_PX)
        assert [found[k].kind for k in false if found[k].kind == "chip"] == [], seed
        chips = [d for t, d in pairs if t.kind == "chip"]
        assert all(d is not None and d.kind == "chip" for d in chips), seed
        true_chips += len(chips)
    return true_chips


def test_grooves_are_put_back_on_the_honed_wall_beyond_a_rim_but_not_on_a_dark_floor():
    """``groove_cover``: beyond the rim's blurred step, a pixel as dark as the hole (a
    chip's floor) takes no grooves back, a grooved wall pixel takes them all, and within
    the step, or where the grooves modelled are too deep to tell wall from hole, the
    circle's blurred outside decides alone."""
    wall, hole = 120.0, 70.0
    beyond = np.array([[0.3, 0.99, 0.99, 0.99, 0.99]], np.float32)
    grooves = np.array([[5.0, 6.0, 6.0, 0.0, 24.0]], np.float32)
    # in the step; a lit floor; a grooved wall pixel; a bare wall pixel; a floor under a
    # groove modelled at half the step (its unmixing not trusted)
    img = np.array([[85.0, hole + 6.0, wall - 6.0, wall, hole + 6.0]], np.float32)
    img = np.repeat(img, 3, axis=0)  # rows alike, so the smoothing across them is neutral
    cover = groove_cover(img, np.full_like(img, wall), np.repeat(grooves, 3, axis=0), hole,
                         np.repeat(beyond, 3, axis=0), blur_px=0.1)[1]
    assert cover[0] == pytest.approx(0.3)  # the step: unchanged
    assert cover[1] < 0.05  # the floor: nothing put back
    assert cover[2] == pytest.approx(0.99) and cover[3] == pytest.approx(0.99)  # the wall: all of it
    assert cover[4] == pytest.approx(0.99)  # too deep a groove to tell: unchanged


def test_a_chip_whose_floor_grooves_cross_is_found_and_a_deep_groove_at_a_rim_is_no_chip():
    """Station seed 981006: a 0.10 x 0.05 mm chip, its floor lit at 15 % of the step, two
    grooves crossing it. The grooves modelled on the ring beyond were put back over the
    floor at the wall's full depth, lifting it over the rim's crossing, and the chip was
    lost; grooves now go back only where the pixel is honed wall. Where a deep groove (or
    two) runs along or into a rim (wide clean frames 1960012, 1985037; the groove model
    off by its own size), nothing is read as a chip."""
    f = random_defect_frame(981006, None, mm_per_px=MM_PER_PX)
    found = detect_defects(f.image, MM_PER_PX)
    pairs, false = match(f.defects, found, MM_PER_PX)
    assert false == []
    (chip,) = [(t, d) for t, d in pairs if t.kind == "chip" and t.length_mm > 0.1]
    truth, d = chip
    assert d is not None and d.kind == "chip"
    assert _within(d.length_mm, truth.length_mm) and _within(d.width_mm, truth.width_mm), (d, truth)
    for seed in (1960012, 1985037):
        f = random_defect_frame(seed, {}, mm_per_px=MM_PER_PX, envelope="wide")
        assert [(d.kind, round(d.x_px), round(d.y_px)) for d in detect_defects(f.image, MM_PER_PX)] == [], seed


def test_the_edge_blurs_bar_follows_the_cameras_blur_where_it_is_known():
    """A pore's edge is the camera's blur and a little more: the fixed 2.8 px bar held a
    camera of the station's 0.8-2 px, but a lens focused less sharply (2.84 px) lost two
    pores of 0.33 and 0.39 mm in a frame without a hole, even with the blur given (the
    station gives it: what the scan read at the holes' edges). The bar is now the
    camera's blur + 0.8 px where it is known, and 2.8 px below 2 px of blur."""
    cfg = DefectConfig()
    assert cfg.edge_blur_limit(None) == cfg.edge_blur_limit(1.5) == cfg.edge_blur_limit(2.0) == 2.8
    assert cfg.edge_blur_limit(2.84) == pytest.approx(3.64)
    f = random_defect_frame(981010, None, mm_per_px=MM_PER_PX, blur_sigma_px=2.84)
    assert not f.holes and sorted(t.kind for t in f.defects) == ["pore", "pore"]
    pairs, false = match(f.defects, detect_defects(f.image, MM_PER_PX, blur_px=2.84), MM_PER_PX)
    assert false == []
    for t, d in pairs:
        assert d is not None and d.kind == "pore", t
        assert _within(d.length_mm, t.length_mm) and _within(d.width_mm, t.width_mm), (d, t)


def test_a_strong_scratch_whose_region_a_groove_pulls_onto_the_hatch_is_measured_as_a_line():
    """A 640 x 480 frame (seed 982022): a 0.34 x 0.042 mm scratch, contrast 0.6, 10 deg
    off the hatch beside a groove. The groove's residue joined to its region pulled the
    region's axis to 5.9 deg off the hatch, its ends were read along the groove (no cut),
    and it was dropped as groove residue; a strong mark is now measured as a line first,
    and that line crosses the hatch."""
    f = random_defect_frame(982022, None, mm_per_px=MM_PER_PX, width_px=640, height_px=480)
    assert sorted(t.kind for t in f.defects) == ["scratch", "scratch"]
    pairs, false = match(f.defects, detect_defects(f.image, MM_PER_PX), MM_PER_PX)
    assert false == []
    for t, d in pairs:
        assert d is not None and d.kind == "scratch", t
        assert _within(d.length_mm, t.length_mm) and _within(d.width_mm, t.width_mm), (d, t)


def test_a_rims_baseline_follows_its_clean_arcs_when_defects_hold_much_of_one_side():
    """Two long burrs and a chip on 140 deg of a rim pulled the hole's fit 1.9 px off
    (fresh station frame 4560076). The rim's baseline, fitted with Tukey weights from the
    median radius, settled between the burrs and the clean arc beside them, ran through
    the burrs, and both (0.26 and 0.28 mm long, over the limit) were lost. Circles through
    three sectors' median edges are tried too, and the one most of the rim agrees with
    stands: here the baseline is within 0.1 px of the truth (4.6 px off before)."""
    from station.vision.defects.rims import _robust_harmonics

    rng = np.random.default_rng(3)
    theta = np.linspace(-np.pi, np.pi, 720, endpoint=False)
    true = 38.0 + 1.9 * np.cos(theta) + 0.4 * np.sin(theta)  # the measured centre 1.9 px off
    edge = true + 0.15 * rng.standard_normal(theta.size)
    deg = np.rad2deg(theta)
    edge[(deg > -72) & (deg < -32)] -= 3.0  # a burr
    edge[(deg > 27) & (deg < 65)] -= 4.5  # a burr
    edge[(deg > 95) & (deg < 125)] += 6.0  # a chip
    base = _robust_harmonics(theta, edge, np.ones(theta.size, bool), 1)
    assert np.abs(base - true).max() < 0.1
    # a clean rim, and one with a single chip, keep the baseline they had
    for dent in (0.0, 6.0):
        e = true + 0.15 * rng.standard_normal(theta.size)
        e[(deg > 95) & (deg < 125)] += dent
        assert np.abs(_robust_harmonics(theta, e, np.ones(theta.size, bool), 1) - true).max() < 0.1

    f = random_defect_frame(4560076, mm_per_px=MM_PER_PX)
    pairs, false = match(f.defects, detect_defects(f.image, MM_PER_PX), MM_PER_PX)
    burrs = [(t, d) for t, d in pairs if t.kind == "burr"]
    assert len(burrs) == 2 and all(d is not None and d.kind == "burr" for _, d in burrs), burrs
    assert all(_within(d.length_mm, t.length_mm) for t, d in burrs), [(t.length_mm, d.length_mm) for t, d in burrs]
    assert not false


def test_a_rim_defects_arc_is_read_on_the_rims_own_circle():
    """A hole's fit pulled off by its rim defects put their arcs out: read about that
    centre, a burr's arc (the centre moved away from it) came out short and a chip's long
    by the centre's offset over the radius (wide frame 4600078: 1.6 px on 34, burrs 5-10 %
    short). The arcs are read on the baseline's circle. Here the rays come from a centre
    1.8 px off: each arc between two of the true rim's points reads as it is."""
    from station.vision.defects.rims import _RimCircle, _robust_harmonic_coefs

    class Hole:
        x_px, y_px, diameter_px = 101.5, 199.0, 2 * 33.0  # the pulled fit: centre (1.5, -1.0) off, 1 px small

    true_x, true_y, radius, blur, crossing = 100.0, 200.0, 34.0, 1.5, 0.75
    n = 720
    theta = 2 * np.pi * np.arange(n) / n
    # the share's crossing along each ray: a circle 0.674 blur inside the rim, about the true centre
    dx, dy = true_x - Hole.x_px, true_y - Hole.y_px
    p, q = dx * np.cos(theta) + dy * np.sin(theta), -dx * np.sin(theta) + dy * np.cos(theta)
    r_cross = radius - 0.6745 * blur
    base = p + np.sqrt(r_cross**2 - q**2)
    circle = _RimCircle.of(Hole, _robust_harmonic_coefs(theta, base, np.ones(n, bool), 1), n, blur, crossing)
    assert np.hypot(circle.x - true_x, circle.y - true_y) < 0.1 and abs(circle.radius - radius) < 0.1

    def ray_of(phi):  # the fractional ray index from the hole's fit towards the true rim's point at phi
        x, y = true_x + radius * np.cos(phi) - Hole.x_px, true_y + radius * np.sin(phi) - Hole.y_px
        return (np.arctan2(y, x) % (2 * np.pi)) / (2 * np.pi) * n

    old_errors = []
    for start, span in ((250.0, 0.8), (20.0, 0.3), (120.0, 0.5), (340.0, 0.6)):  # the last across 0: the index runs on
        i1, i2 = ray_of(np.deg2rad(start)), ray_of(np.deg2rad(start) + span)
        i2 += n if i2 < i1 else 0
        new = circle.arc(i2) - circle.arc(i1)
        assert abs(new - radius * span) < 0.05 + 0.002 * radius * span, (start, new, radius * span)
        old_errors.append((i2 - i1) * 2 * np.pi * Hole.diameter_px / 2 / n / (radius * span) - 1)  # about the fit
    assert max(np.abs(old_errors)) > 0.05, old_errors  # where the fit's arc was 5 % off
    # where the baseline is the fit's own circle, the arc is the fit's
    same = _RimCircle.of(Hole, np.array([33.0 - 0.6745 * blur, 0.0, 0.0]), n, blur, crossing)
    assert abs(same.arc(300.0) - same.arc(100.0) - 200 * 2 * np.pi * 33.0 / n) < 1e-3

    # the frame: two burrs and a chip pulled the hole's fit 1.6 px off; its 0.160 mm burr,
    # 11 px high, read 0.023 mm short
    f = random_defect_frame(4600078, mm_per_px=MM_PER_PX, envelope="wide")
    pairs, false = match(f.defects, detect_defects(f.image, MM_PER_PX), MM_PER_PX)
    (t, d), = [(t, d) for t, d in pairs if t.kind == "burr" and abs(t.length_mm - 0.160) < 0.001]
    assert d is not None and d.kind == "burr" and _within(d.length_mm, t.length_mm), d
    assert not false


def test_a_burr_whose_run_ends_on_a_low_shelf_is_not_turned_inside_out():
    """A rim defect's ends are first guessed where its rays' edges cross half the run's
    median height, interpolated between the run's last ray and the next. Where the run
    (found on the share smoothed along the rim) ends on a low shelf, its last ray is
    already under half the height, and the interpolation ran back into the run by as much
    as the shelf is flat: a 0.30 mm burr (3 px high, a 1-1.7 px shelf over its last 10
    deg) had its stop guessed 6 px before its start, its length came out negative, and
    it was lost (wide frame 4620099, a 65 deg hatch). The run's end stands there now."""
    f = random_defect_frame(4620099, mm_per_px=MM_PER_PX, envelope="wide", hatch_deg=65.0)
    pairs, false = match(f.defects, detect_defects(f.image, MM_PER_PX), MM_PER_PX)
    burrs = [(t, d) for t, d in pairs if t.kind == "burr"]
    assert len(burrs) == 2 and all(d is not None and d.kind == "burr" for _, d in burrs), burrs
    assert all(_within(d.length_mm, t.length_mm) for t, d in burrs), [(t.length_mm, d.length_mm) for t, d in burrs]
    assert not false


def test_a_deep_groove_meeting_a_rim_obliquely_is_no_chip():
    """A deep groove that meets a rim obliquely darkens the wedge between it and the rim,
    which reads as a notch (a 0.11 mm, 7.6 px deep "chip" on a clean wide frame, 5700027).
    Its darkness runs on along the groove: 0.377 of the hole's (the upper quartile of the
    lines through the notch's mouth), where 290 true chips on six sets read 0.30 at most.
    The bar is 0.35 (0.4 before). A true chip that a groove runs on from stays a chip:
    station frame 4710065's 0.127 mm chip reads 0.275."""
    f = random_defect_frame(5700027, {}, mm_per_px=MM_PER_PX, envelope="wide")
    assert f.holes and not f.defects
    assert detect_defects(f.image, MM_PER_PX) == []
    f = random_defect_frame(4710065, mm_per_px=MM_PER_PX, envelope="station")
    pairs, false = match(f.defects, detect_defects(f.image, MM_PER_PX), MM_PER_PX)
    chips = [(t, d) for t, d in pairs if t.kind == "chip"]
    assert len(chips) == 2 and all(d is not None and d.kind == "chip" for _, d in chips), chips
    assert not false


def test_a_notch_lit_as_a_grooves_bottom_is_no_chip():
    """A chip's broken face slopes into the hole in shadow. Where a deep groove grazes a
    rim or meets it with another, the edge moves out as at a notch, and the floor read in
    it stands at a groove's darkness: clean wide frames 5910054 (a groove tangent to the
    rim, darker on one side of the tangent than on the other: 0.41 mm "chip", its floor
    0.44 of the wall-to-hole step) and 5910051 (two grooves meeting at the rim: 0.11 mm,
    0.36). Their darkness runs on beyond them under the groove tests' bars. A notch whose
    floor reads under half the step (``chip_min_floor``) is no chip; a true chip whose
    floor reads low (wide frame 129081 at a 26 deg hatch: a 0.082 x 0.042 mm chip, 0.54)
    is found."""
    for seed in (5910051, 5910054):
        f = random_defect_frame(seed, {}, mm_per_px=MM_PER_PX, envelope="wide")
        assert f.holes and not f.defects
        found = detect_defects(f.image, MM_PER_PX)
        assert found == [], (seed, [(d.kind, round(d.length_mm, 3)) for d in found])
        # the groove tests alone pass it
        found = detect_defects(f.image, MM_PER_PX, cfg=replace(DefectConfig(), chip_min_floor=0.0))
        assert [d.kind for d in found] == ["chip"], (seed, found)
    f = random_defect_frame(129081, None, mm_per_px=MM_PER_PX, envelope="wide", hatch_deg=26.0)
    pairs, _ = match(f.defects, detect_defects(f.image, MM_PER_PX), MM_PER_PX)
    ((t, d),) = [(t, d) for t, d in pairs if t.kind == "chip" and abs(t.length_mm - 0.082) < 0.005]
    assert d is not None and d.kind == "chip", d


def test_a_short_wide_scratch_well_off_the_hatch_keeps_to_no_groove_line():
    """A mark keeps to a groove family's line when its chord crosses few of the family's
    lines beyond its own width (``on_groove_line``), and is then a piece of a groove if
    that line runs on as one. A short wide scratch crosses few lines at any angle: a
    0.216 x 0.043 mm scratch 30.6 deg off the hatch, plain to see, kept to a line by the
    width allowance, a groove ran on along the line through its middle, and it was lost
    (station frame 4710086). Groove pieces read 19.3 deg off at most (207 on six sets);
    a mark more than ``groove_line_max_off_deg`` (20.5) off keeps to no line."""
    cfg = DefectConfig()
    assert on_groove_line(119.4, 21.9, 4.3, (30.0, 150.0), cfg) is None  # 30.6 deg off, crossing 11.1 px
    assert on_groove_line(162.0, 30.0, 4.0, (30.0, 150.0), cfg) == 150.0  # 12 deg off: a piece's reading
    f = random_defect_frame(4710086, mm_per_px=MM_PER_PX, envelope="station")
    pairs, false = match(f.defects, detect_defects(f.image, MM_PER_PX), MM_PER_PX)
    scratches = [(t, d) for t, d in pairs if t.kind == "scratch"]
    assert len(scratches) == 2 and all(d is not None and d.kind == "scratch" for _, d in scratches), scratches
    assert all(_within(d.length_mm, t.length_mm) and _within(d.width_mm, t.width_mm) for t, d in scratches), \
        [(t.length_mm, d.length_mm, t.width_mm, d.width_mm) for t, d in scratches]
    assert not false


def test_a_square_ended_burr_is_as_long_as_it_is(monkeypatch):
    """A burr's ends are read on its area-true profile at half the height read 1.2 blur
    inside them, where the end's blurred step (the camera's blur and the profile's 1 px
    smoothing) has reached only 80-90 %: each end read ~0.3 px out, and square-ended burrs
    of one height came out 0.64 px long at the median (-0.12 to +1.44 px over eight). The height
    is read as the step's plateau (``fit_end``'s ``step_blur``), as a scratch's is. On
    the bench's ragged burrs: median +0.4-0.5 -> -0.1 to -0.2 px (wide 4540000, 620000,
    station 60000)."""
    import sim.camera.defects as twin_defects

    monkeypatch.setattr(twin_defects, "RIM_ROUGHNESS", {"burr": 0.0, "chip": 0.0})  # one height, square ends
    errors = []
    for k, (blur, length, height) in enumerate([(1.0, 10, 2), (1.3, 16, 5), (1.6, 22, 3), (1.9, 14, 7),
                                                (1.2, 8, 1.5), (2.0, 12, 2.5)]):
        p = FrameParams(wall_level_dn=150.0, hole_level_dn=60.0, groove_depth=0.04, grain=0.02, blotch=0.02,
                        blur_sigma_px=blur, gain_e_per_dn=30.0, read_noise_dn=1.5, vignetting=0.1, **SMALL)
        burr = DefectSpec("burr", length_px=length, width_px=height, angle_deg=25.0 + 45 * k, reflectance=1.0,
                          hole=0, shape_seed=k)
        truth, d = _found_as_itself(p, [HoleSpec(300.4, 256.2, 90.0)], burr, seed=300 + k)
        errors.append(d.length_px - truth.length_px)
    assert abs(np.median(errors)) <= 0.3 and max(np.abs(errors)) <= 0.8, np.round(errors, 2)


def test_an_ends_uncertainty_holds_the_smoothed_profiles_own_noise():
    """An end's crossing moves by the profile's noise over its slope. A rim defect's
    area-true profile is smoothed over 1 px of arc (2 of its 0.5 px samples), and its
    sample-to-sample differences hold about a quarter of its spread: ``fit_end``'s u
    from them was a fifth of the ends' scatter (Monte Carlo below), and a 1.2 px high burr
    whose ends read 1.2-1.5 px in on a textured wall had a length u of 1.04 px (the model
    term's), |error| / u 2.6-2.9 (station 4800001, 4800045). Given the profile's own
    spread where no defect is and the blur of a step in it, the u is the scatter's."""
    from scipy.ndimage import gaussian_filter1d
    from scipy.special import ndtr

    from station.vision.defects.common import fit_end

    rng = np.random.default_rng(7)
    s = np.arange(-20.0, 20.0, 0.5)
    blur, height, white = 1.5, 1.2, 0.3
    step_blur = float(np.hypot(blur, 1.0))
    ends, u_diff, u_given = [], [], []
    for _ in range(300):
        noisy = height * ndtr(s / blur) + white * rng.standard_normal(s.size)
        data = gaussian_filter1d(noisy, 2.0)  # 1 px of smoothing over 0.5 px samples
        clean = gaussian_filter1d(white * rng.standard_normal(400), 2.0)  # the profile where no defect is
        end, u0 = fit_end(s, data, 0.0, blur, rising=True)
        _, u1 = fit_end(s, data, 0.0, blur, rising=True, noise=(float(np.std(clean)), step_blur))
        ends.append(end)
        u_diff.append(u0)
        u_given.append(u1)
    scatter = float(np.std(ends))
    # (seeds 7-9: the differences' u 0.17-0.21 of the scatter, the profile's 0.73-0.87: the
    # local height the half is taken of is read with the same noise)
    assert np.median(u_diff) < 0.3 * scatter, (np.median(u_diff), scatter)
    assert 0.65 * scatter < np.median(u_given) < 1.35 * scatter, (np.median(u_given), scatter)

    # on the frames: two shallow burrs that read 0.027-0.031 mm short, within 2 u (the old
    # u, 0.0104 mm, held neither)
    for seed, length_mm in ((4800001, 0.2703), (4800045, 0.2849)):
        f = random_defect_frame(seed, mm_per_px=MM_PER_PX)
        pairs, _ = match(f.defects, detect_defects(f.image, MM_PER_PX), MM_PER_PX)
        (t, d), = [(t, d) for t, d in pairs if t.kind == "burr" and abs(t.length_mm - length_mm) < 0.0005]
        assert d is not None and d.kind == "burr", (seed, d)
        assert abs(d.length_mm - t.length_mm) <= 2.0 * d.size_u_mm, (seed, t.length_mm, d.length_mm, d.size_u_mm)


def test_a_rim_defects_end_is_read_on_its_own_side():
    """``fit_end`` reads the crossing of the local half height that steps the way the
    end does: up at a defect's start, down at its end. A ragged chip's area-true profile
    (wide bench seed 78008, hatch 22 deg: a 0.086 x 0.072 mm chip with a shoulder on one
    side) was read at its far end on the rising side, 2.8 px before its start, and the
    chip was dropped for a negative length. The profile below is that chip's.

    Since session 56 (a rim's edge read where the share falls for good, ``RIM_HOLD_PX``)
    one ray in that chip's middle, whose floor dipped below the crossing for a sample,
    reads the notch's depth rather than the rim: the profile's main step is higher and
    its shoulder (2-3 px deep over its last 3 px of arc) lies under the half height the
    end is read at, so the chip reads 0.059 mm (0.082 before; a ragged chip's shallow
    end, docs/surface.md's known limits). It is found, and its length is its notch's."""
    from station.vision.defects.common import fit_end

    s = 210.68 + 0.4985 * np.arange(34)
    data = np.array([-0.02, -0.02, -0.028, -0.034, -0.021, 0.021, 0.094, 0.197, 0.328, 0.503, 0.754, 1.127,
                     1.666, 2.397, 3.301, 4.291, 5.215, 5.909, 6.253, 6.194, 5.754, 5.051, 4.272, 3.601, 3.127,
                     2.828, 2.614, 2.386, 2.074, 1.663, 1.187, 0.721, 0.34, 0.084])
    start, _ = fit_end(s, data, 217.36, 1.057, rising=True)
    end, _ = fit_end(s, data, 220.30, 1.057, rising=False)
    assert 216.5 < start < 218.0
    assert 224.0 < end < 226.5  # past the shoulder, where the profile falls to its local half
    # the same profile mirrored: the same ends, mirrored
    m_start, _ = fit_end(-s[::-1], data[::-1], -220.30, 1.057, rising=True)
    m_end, _ = fit_end(-s[::-1], data[::-1], -217.36, 1.057, rising=False)
    assert m_start == pytest.approx(-end, abs=1e-6) and m_end == pytest.approx(-start, abs=1e-6)
    # and the chip is found, its length within tolerance
    f = random_defect_frame(78008, None, mm_per_px=MM_PER_PX, envelope="wide", hatch_deg=22.0)
    found = detect_defects(f.image, MM_PER_PX)
    pairs, _ = match(f.defects, found, MM_PER_PX)
    (d,) = [d for t, d in pairs if t.kind == "chip" and abs(t.length_mm - 0.086) < 0.001]
    assert d is not None and d.kind == "chip" and 0.05 <= d.length_mm <= 0.086 + 0.02


def test_a_deep_groove_meeting_a_rim_obliquely_or_two_meeting_in_a_v_are_not_a_chip():
    """The run-on lines follow each groove direction from the notch's mouth on the rim,
    each read from where it leaves the notch. Read from the notch's outer end along the
    radius, they missed a deep groove that meets the rim obliquely (wide seed 74021: a
    0.15 mm "chip", run-on share 0.11, now 1.0) and two that meet at it in a V, whose
    notch reaches out along their bisector (wide clean seed 1074004: 0.08 mm, 0.19, now
    0.45). The true chip with the highest share on wide seeds 82000-82059 (82013: 0.29
    before, 0.22 now) is still found."""
    assert _chips_without_false_ones(((1074004, True), (74021, False), (82013, False))) == 2  # seed 82013's


def test_a_finer_cameras_large_hole_is_a_hole_and_its_rim_is_judged():
    """At 0.007 mm/px a 0.95 mm hole is 136 px across, past the coarse detector's 120 px
    for the station's 0.010 mm/px: it was reported as a 0.95 mm pore and its burr and chip
    were not looked for. With the scale known the hole is measured (its diameter within
    0.3 px, the burr and chip on its rim included) and its rim judged; without it the px
    range stays the station's."""
    from station.vision.measure import measure_holes

    mm = 0.007
    p = FrameParams(wall_level_dn=150.0, hole_level_dn=50.0, groove_depth=0.06, grain=0.02, blotch=0.03,
                    blur_sigma_px=1.4, gain_e_per_dn=30.0, read_noise_dn=1.5, vignetting=0.2, **SMALL)
    defects = [DefectSpec("burr", length_px=18.0, width_px=6.0, angle_deg=300.0, reflectance=1.0, hole=0,
                          shape_seed=13),
               DefectSpec("chip", length_px=16.0, width_px=5.0, angle_deg=120.0, hole=0, shape_seed=14)]
    f = render_frame(p, [HoleSpec(300.4, 250.2, 0.95 / mm)], seed=21, defects=defects)
    f.defects = [d.with_scale(mm) for d in f.defects]
    (hole,) = measure_holes(f.image, mm)
    assert hole.diameter_px == pytest.approx(0.95 / mm, abs=0.3)
    assert measure_holes(f.image) == []
    found = detect_defects(f.image, mm)
    pairs, false = match(f.defects, found, mm)
    assert [found[k].kind for k in false] == []
    assert sorted((t.kind, d.kind if d else None) for t, d in pairs) == [("burr", "burr"), ("chip", "chip")]


def test_a_finer_cameras_large_pores_keep_their_size():
    """Pores of 0.42-0.49 mm at 0.005 mm/px are 84-97 px: the coarse stage's median (104
    px) and its grooves' means along 84 px lines took them for the wall's own level and a
    groove, they were never marked dark, their centres set the local wall's level, and
    they read 11-21 % narrow (the defects bench at 0.005 mm/px, seed 88000: these three
    frames). The coarse windows now reach past the largest pore at the frame's scale; at
    0.010 mm/px they are what they were."""
    mm = 0.005
    checked = 0
    for seed in (88008, 88036, 88053):
        f = random_defect_frame(seed, mm_per_px=mm)
        found = detect_defects(f.image, mm)
        for t, d in match(f.defects, found, mm)[0]:
            if t.kind == "pore" and t.length_mm > 0.4:
                assert d is not None and d.kind == "pore", seed
                assert _within(d.length_mm, t.length_mm), (seed, d.length_mm, t.length_mm)
                assert _within(d.width_mm, t.width_mm), (seed, d.width_mm, t.width_mm)
                checked += 1
    assert checked == 3  # one such pore in each frame


def test_the_wall_beside_a_measured_pore_is_modelled_without_it():
    """Each candidate's local wall model leaves out what the defects measured before it
    cover: a 0.43 mm and a 0.48 mm pore within a few px of a fainter candidate's patch
    pulled its grooves' fit, and the wall beside each stood as a false 0.31 / 0.24 mm
    pore (station bench frames 70078 and 70097; the old code reported both). Only the
    measured defects, not every candidate: most candidates are the grooves' residue, and
    a deep groove left out of its own profile's fit read its crossing with another as a
    0.31 mm pore on a clean wide frame (1078051), which must stay clean."""
    for seed, envelope, n_true in ((70078, "station", 7), (70097, "station", 1), (1078051, "wide", 0)):
        f = random_defect_frame(seed, {} if n_true == 0 else None, mm_per_px=MM_PER_PX, envelope=envelope)
        assert len(f.defects) == n_true
        found = detect_defects(f.image, MM_PER_PX)
        pairs, false = match(f.defects, found, MM_PER_PX)
        assert not false, (seed, [(found[k].kind, found[k].x_px, found[k].y_px, found[k].length_mm) for k in false])
        for t, d in pairs:
            assert d is not None and d.kind == t.kind, (seed, t)
            assert _within(d.length_mm, t.length_mm), (seed, t.kind, d.length_mm, t.length_mm)


def test_a_large_pore_with_a_ragged_outline_is_not_taken_for_a_soft_shading():
    """At 0.005 mm/px, with the wall's texture drawn at that scale, a 0.31 x 0.22 mm pore
    (62 x 43 px) of ragged outline fitted a blurred ellipse whose edge blur was 2.9 px (1.4
    rendered): the outline's departure from an ellipse read as blur, and the mark was
    dropped as a soft shading of the wall (max 2.8 px). The outline's own roughness beyond
    the ellipse's harmonics (2.5 px RMS here) comes off the blur first."""
    mm = 0.005
    f = random_defect_frame(88030, mm_per_px=mm, texture_scale=0.010 / mm)
    found = detect_defects(f.image, mm)
    pairs, false = match(f.defects, found, mm)
    big = [(t, d) for t, d in pairs if t.kind == "pore" and np.hypot(t.image_x_px - 1176, t.image_y_px - 387) < 5]
    assert len(big) == 1 and big[0][0].length_mm > 0.3
    t, d = big[0]
    assert d is not None and d.kind == "pore"
    assert _within(d.length_mm, t.length_mm) and _within(d.width_mm, t.width_mm), (d.length_mm, d.width_mm)
    assert [found[k].kind for k in false] == []


def test_an_outlines_roughness_is_its_departure_from_an_ellipse():
    from station.vision.defects.pores import _outline_roughness

    th = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    for aspect in (1.0, 1.3, 2.5):  # an ellipse has none, however elongated
        ellipse = 20.0 / np.sqrt((np.cos(th - 0.4) / aspect) ** 2 + (np.sin(th - 0.4)) ** 2)
        assert _outline_roughness(th, ellipse) < 1e-6, aspect
    ragged = 20.0 + 2.0 * np.cos(5 * th) + 1.0 * np.sin(7 * th)  # 1.58 px RMS beyond the circle
    assert _outline_roughness(th, ragged) == pytest.approx(np.sqrt((4.0 + 1.0) / 2.0), rel=0.05)


def test_a_burr_across_the_rims_zero_angle_is_one_burr_when_an_arc_elsewhere_is_left_out():
    """A rim whose rays are not all read (a pore claimed beside it leaves an arc out at
    the top) still runs on across 0 deg: a 0.17 mm burr there was reported twice, as the
    two runs either side of the wrap (22 deg hatch, bench seed 89058).

    Each is one burr, its whole length: a half reads 0.07-0.085 mm short. Both burrs are
    ragged, their area-true profiles ramps rather than steps (one rises over 10 px to a
    peak at its far end), and they read 0.020 and 0.023 mm short (0.010 and 0.012 before
    session 83 read a burr's ends against the blurred step's plateau, which took 0.4-0.5
    px off the benches' median burr and left it 0.1-0.2 px short)."""
    f = random_defect_frame(89058, mm_per_px=MM_PER_PX, hatch_deg=22.0)
    found = detect_defects(f.image, MM_PER_PX)
    pairs, false = match(f.defects, found, MM_PER_PX)
    assert [(found[k].kind, round(found[k].x_px)) for k in false] == []
    burrs = [(t, d) for t, d in pairs if t.kind == "burr"]
    assert len(burrs) == 2 and all(d is not None and d.kind == "burr" for _, d in burrs)
    assert all(abs(d.length_mm - t.length_mm) <= 0.03 for t, d in burrs), [(t.length_mm, d.length_mm) for t, d in burrs]


def test_a_chip_beside_a_pore_is_not_taken_for_a_groove_running_on():
    """A 0.2 mm chip with a 0.16 mm pore just outside its hole's rim (0.005 mm/px, texture
    at that scale, seed 90032): the chip's run-on test read the pore's darkness, where the
    pore's claimed region stops at the hole's zone, as a groove's (1.2 of the hole's
    darkness) and dropped the chip. The frame's pores and scratches found are left out
    of that reading whole."""
    mm = 0.005
    f = random_defect_frame(90032, mm_per_px=mm, texture_scale=0.010 / mm)
    found = detect_defects(f.image, mm)
    pairs, false = match(f.defects, found, mm)
    (t, d), = [(t, d) for t, d in pairs if t.kind == "chip" and t.length_mm > 0.2]
    assert d is not None and d.kind == "chip"
    assert _within(d.length_mm, t.length_mm), (d.length_mm, t.length_mm)
    assert [p for p in pairs if p[0].kind == "pore" and (p[1] is None or p[1].kind != "pore")] == []
    assert [found[k].kind for k in false] == []


def test_a_wall_brighter_than_its_level_beside_a_rim_is_no_burr():
    """Three clean wide frames where the wall beside a rim reads brighter than the level
    calibrated on the ring beyond it (a deep groove on that ring fading beside the rim,
    whose model was put back there; a dark spot on the ring): the edge's crossing moved
    in by ~1 px over 13-32 px of arc, read as 0.13-0.32 mm "burrs" at significance 47-157
    (wide bench seeds 86000 and 84000: clean frames 25, 84 and 18). With the wall's
    level raised where it reads brighter beyond the blurred step, none is left."""
    for seed in (1086025, 1086084, 1084018):
        f = random_defect_frame(seed, {}, mm_per_px=MM_PER_PX, envelope="wide")
        found = detect_defects(f.image, MM_PER_PX)
        assert [(d.kind, round(d.x_px), round(d.y_px)) for d in found if d.kind in ("burr", "chip")] == [], seed


def test_the_walls_level_is_raised_only_where_it_reads_brighter_beyond_the_rim():
    """``_lift_wall`` on a synthetic rim: a blurred step 1 - (1 - e) Phi whose wall reads
    e = -1 over an arc (brighter than its level) is brought back to 1 - Phi there, with its
    0.75 crossing where the rest of the rim has it; a chip's darker wall (e > 0) and the
    hole's side are left as they were."""
    from scipy.special import ndtr

    from station.vision.defects.rims import _lift_wall

    rb = np.arange(20.0, 50.0, 0.5)
    n = 400
    rad, blur = 35.0, 1.5
    phi = ndtr((rb - rad) / blur)[:, None] * np.ones(n)[None, :]
    e = np.zeros(n)
    e[100:160] = -1.0  # the wall brighter than its level over 30 px of arc
    e[250:300] = 0.5  # a chip: darker than the level beyond the rim
    share = 1.0 - (1.0 - e)[None, :] * phi
    share[:, 250:300] = np.where(rb[:, None] < rad + 6.0, 1.0 - phi[:, 250:300], 0.5)
    valid = np.ones(n, bool)

    def smooth(v, px):
        return v  # the rays here are noise-free: no averaging along the rim needed

    lifted = _lift_wall(share, rb, valid, rad + 2.5 * blur + 1.0, smooth)
    assert np.allclose(lifted[:, 100:160], 1.0 - phi[:, 100:160], atol=1e-9)
    assert np.array_equal(lifted[:, 250:300], share[:, 250:300])
    assert np.array_equal(lifted[:, :90], share[:, :90])
    inner = rb < rad - 4.0 * blur
    assert np.allclose(lifted[inner], 1.0, atol=1e-3)

    def crossing(col):
        k = int(np.argmax(col < 0.75))
        return rb[k - 1] + (col[k - 1] - 0.75) / (col[k - 1] - col[k]) * (rb[k] - rb[k - 1])

    before, after, clean = crossing(share[:, 130]), crossing(lifted[:, 130]), crossing(share[:, 20])
    assert clean - before > 0.5  # the brighter wall moved the crossing in
    assert after == pytest.approx(clean, abs=0.02)


def _with_groove_stretch(wall: np.ndarray, x0: float, y0: float, angle_deg: float, length_px: float,
                         depth: float, width_px: float = 4.0, fade: float = 0.3) -> np.ndarray:
    """The wall's radiance with a deep groove's stretch cut in it: from (x0, y0) along
    ``angle_deg`` for ``length_px``, ``depth`` dark at its start and fading out over the
    last ``fade`` of its length (a groove whose depth the frame's wall model, a mean
    along the groove's whole line, does not hold)."""
    h, w = wall.shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    ux, uy = np.cos(np.deg2rad(angle_deg)), np.sin(np.deg2rad(angle_deg))
    t = (xx - x0) * ux + (yy - y0) * uy
    n = -(xx - x0) * uy + (yy - y0) * ux
    along = np.where((t >= 0) & (t <= length_px), np.clip((1.0 - t / length_px) / fade, 0.0, 1.0), 0.0)
    return wall * (1.0 - depth * along * np.exp(-0.5 * (n / (width_px / 2)) ** 2)).astype(np.float32)


@pytest.mark.parametrize("case", range(5))
def test_a_pore_in_line_with_a_deep_grooves_stretch_is_found_alone_and_measured(case):
    """A deep groove's stretch that ends 8-25 px short of a pore and points at it is a
    candidate in line with the pore's, and the two are grouped (as a faint scratch's pieces
    are). The pore was measured with the stretch: on the surface bench's seed 24203 a
    0.31 mm pore of contrast ~0.6 was lost (its frame's only defect); here one of these five
    was lost (the 30 deg stretch 15 px off) and two read 35 and 42 px for 30, their places
    7-8 px off. A pore is one cavity: the region's part round its peak is measured, and a
    region taken for a piece of groove is looked at again for a dark compact core. Each is
    found once, in place and within the tolerance; the stretch alone is nothing. (A
    stretch 8 px off the pore, whose skirt joins the pore's region, still narrows it 1.8
    px, 13 % of 24: a known limit, not tested here.)"""
    angle, gap = [(150.0, 10.0), (30.0, 15.0), (150.0, 20.0), (330.0, 12.0), (210.0, 25.0)][case]
    p = FrameParams(wall_level_dn=140.0, hole_level_dn=45.0, groove_depth=0.07, grain=0.03, blotch=0.03,
                    blur_sigma_px=1.4, gain_e_per_dn=30.0, read_noise_dn=1.5, vignetting=0.2, **SMALL)
    cx, cy = 320.3, 260.6
    ux, uy = np.cos(np.deg2rad(angle)), np.sin(np.deg2rad(angle))
    wall = _with_groove_stretch(wall_patch(p, 70 + case), cx + (15 + gap) * ux, cy + (15 + gap) * uy, angle,
                                150.0, 0.35)
    pore = DefectSpec("pore", cx, cy, 30.0, 22.0, 20.0 * case, 0.35, shape_seed=50 + case)
    f = render_frame(p, [], seed=90 + case, wall=wall, defects=[pore])
    (truth,) = [d.with_scale(MM_PER_PX) for d in f.defects]
    found = detect_defects(f.image, MM_PER_PX)
    assert [d.kind for d in found] == ["pore"], found
    (d,) = found
    assert np.hypot(d.x_px - truth.x_px, d.y_px - truth.y_px) < 2.0, (d.x_px, d.y_px)
    assert _within(d.length_mm, truth.length_mm), (d.length_px, truth.length_px)
    assert _within(d.width_mm, truth.width_mm), (d.width_px, truth.width_px)
    assert detect_defects(render_frame(p, [], seed=90 + case, wall=wall).image, MM_PER_PX) == []


@pytest.mark.parametrize("case", range(6))
def test_a_pore_on_a_scratchs_line_beyond_its_end_is_measured_as_a_pore_of_its_own(case):
    """A pore that lies on a scratch's line 30-60 px beyond its end is a candidate in line
    with the scratch's, and the two are grouped as a faint scratch's pieces are; the
    scratch's region grew into the pore and the pore was never measured (wide bench,
    35 deg hatch, seed 85007: a 0.45 mm pore, plain to see, lost). A compact mark much
    wider than the furrow is no piece of it and is not grouped (the four larger pores),
    and a member of a group that the group's defects do not cover (a scratch its line and
    width) is examined on its own (the two small ones, still grouped): both are found,
    each in place and within the tolerance."""
    angle, gap, size = [(160.0, 30.0, 40.0), (20.0, 45.0, 30.0), (100.0, 60.0, 36.0), (75.0, 38.0, 44.0),
                        (160.0, 25.0, 16.0), (65.0, 30.0, 18.0)][case]
    p = FrameParams(**SMALL)
    ux, uy = np.cos(np.deg2rad(angle)), np.sin(np.deg2rad(angle))
    length = 130.0
    sx, sy = 319.5 - (length / 2 + gap / 2 + size / 4) * ux, 255.5 - (length / 2 + gap / 2 + size / 4) * uy
    scratch = DefectSpec("scratch", sx, sy, length, 3.5, angle, 0.6, shape_seed=60 + case)
    px_, py_ = sx + (length / 2 + gap + size / 2) * ux, sy + (length / 2 + gap + size / 2) * uy
    pore = DefectSpec("pore", px_, py_, size, 0.85 * size, 30.0 * case, 0.3, shape_seed=70 + case)
    f = render_frame(p, [], seed=80 + case, defects=[scratch, pore])
    truths = [d.with_scale(MM_PER_PX) for d in f.defects]
    found = detect_defects(f.image, MM_PER_PX)
    pairs, false = match(truths, found, MM_PER_PX)
    for t, d in pairs:
        assert d is not None and d.kind == t.kind, (case, t.kind, found)
        assert np.hypot(d.x_px - t.image_x_px, d.y_px - t.image_y_px) * MM_PER_PX <= 0.05, (case, t.kind)
        assert _within(d.length_mm, t.length_mm), (case, t.kind, d.length_mm, t.length_mm)
    assert not false, [found[k] for k in false]


def test_a_broad_faint_mark_at_a_crossing_of_deep_grooves_is_no_pore():
    """The cross-hatch's residue where two deep grooves cross, at the frame's border (the
    grooves' means along their lines end there) or inside it, fitted as a steep blurred
    ellipse: 0.16-0.34 mm "pores" only 0.06-0.16 dark over their region (wide bench
    seeds 84000 and 85000: clean frames 18, 78 and 54, and frame 87 with defects). A
    cavity that large holds its floor's darkness (0.22 and more on the dev frames), so
    none is a pore; frame 87's two true pores beside the border are still found."""
    for seed in (1084018, 1084078, 1085054):
        f = random_defect_frame(seed, {}, mm_per_px=MM_PER_PX, envelope="wide")
        found = detect_defects(f.image, MM_PER_PX)
        assert [(d.kind, round(d.x_px), round(d.y_px)) for d in found if d.kind == "pore"] == [], seed
    f = random_defect_frame(85087, None, mm_per_px=MM_PER_PX, envelope="wide")
    found = [d for d in detect_defects(f.image, MM_PER_PX) if d.kind == "pore"]
    truth = [t for t in f.defects if t.kind == "pore"]
    assert len(found) == len(truth) == 2
    for t in truth:
        d = min(found, key=lambda d: np.hypot(d.x_px - t.x_px, d.y_px - t.y_px))
        assert np.hypot(d.x_px - t.x_px, d.y_px - t.y_px) < 3.0
        assert abs(d.length_mm - t.length_mm) <= max(0.1 * t.length_mm, 0.02)


def test_a_mark_darker_on_the_whole_than_its_fitted_floor_is_no_pore():
    """A cavity has one dark floor, and its region's mean darkness exceeds the fitted
    blurred ellipse's contrast only by noise. The residue peaked where two deep grooves
    cross, its arms out along them, fitted a broad faint ellipse under a core darker than
    it (1.12-2.13 times): a 0.40 mm "pore" on wide clean frame 1100002 (35 deg hatch), and
    0.28-0.61 mm ones beside true defects on wide frames 95088, 96076 and 96090. None is a
    pore now, and each of those frames' true defects is found as it was; 96090's 0.19 mm
    scratch, missed before, is found since session 61 (its group, a strong piece and a
    faint one in line, was no defect, and the strong piece alone is the scratch)."""
    f = random_defect_frame(1100002, {}, mm_per_px=MM_PER_PX, envelope="wide", hatch_deg=35.0)
    assert [(d.kind, round(d.length_mm, 3)) for d in detect_defects(f.image, MM_PER_PX)] == []
    for seed, found_kinds in ((95088, 4), (96076, 4), (96090, 4)):
        f = random_defect_frame(seed, None, mm_per_px=MM_PER_PX, envelope="wide")
        found = detect_defects(f.image, MM_PER_PX)
        pairs, false = match(f.defects, found, MM_PER_PX)
        assert [(found[k].kind, round(found[k].length_mm, 3)) for k in false] == [], seed
        assert sum(d is not None and d.kind == t.kind for t, d in pairs) == found_kinds, seed
        for t, d in pairs:
            if d is not None and t.kind == "pore":
                assert abs(d.length_mm - t.length_mm) <= max(0.1 * t.length_mm, 0.02), (seed, t, d)


def test_the_floor_test_spares_a_dark_disc_at_none_of_the_parts_holes(monkeypatch):
    """A mark of a hole's size centred in a dark disc at none of the part's holes (which
    ``detect_defects`` finds when given ``hole_places``) is a cavity whatever its outline,
    and the floor test does not refuse it (whole-surface bench seed 96000: a 1.43 mm pore
    at a frame's border read a floor of 0.40 under a mean darkness of 0.49, and was lost).
    Elsewhere the test stands for marks of any size: the grooves' residue it stops
    reaches 0.61 mm (wide frame 96090, ``test_a_mark_darker_on_the_whole_than_its_fitted_
    floor_is_no_pore``). A frame alone spares nothing."""
    from station.vision.defects.examine import _accept

    m = dict(x=80.0, y=80.0, length=148.0, width=140.0, angle=0.0, u_length=2.8, u_width=2.7, significance=435.0,
             contrast=0.40, blur=1.6, mean_darkness=0.49)
    box = (100, 200, 300, 400)
    spared = replace(DefectConfig(), floor_test_exempt=((182.0, 279.0, 140.0),))

    def accepted(mark, cfg):
        return _accept(mark, "pore", box, False, (30.0, 150.0), cfg, 10.0, 1.3) is not None

    assert accepted(m, spared) and not accepted(m, DefectConfig())
    assert not accepted(dict(m, length=60.0, width=55.0), spared)  # no disc's size: a mark in it
    assert not accepted(dict(m, x=0.0), spared)  # beside the disc
    seen = []

    def spy(*args, **kw):
        seen.append(args[5].floor_test_exempt)
        return _accept(*args, **kw)

    import station.vision.defects.examine as examine

    monkeypatch.setattr(examine, "_accept", spy)
    detect_defects(random_defect_frame(7200, None, mm_per_px=MM_PER_PX).image, MM_PER_PX)
    assert seen and all(v == () for v in seen)


def test_a_deep_groove_crossing_a_chips_arc_does_not_make_it_a_groove():
    """Two true chips on 30 %-contrast holes of the wide envelope at a 22 deg hatch, each
    with a deep groove running out of part of its arc (seed 78000, frames 7 and 54): the
    darkest line beyond the notch was as dark as the hole (0.65 and 0.88 of it), and the
    run-on test took both for grooves running into the rim. Read by the upper quartile of
    the lines through the notch (0.23 and 0.19), both are chips; a groove that makes a
    notch covers the notch's lines (0.48-0.77)."""
    for seed in (78007, 78054):
        f = random_defect_frame(seed, None, mm_per_px=MM_PER_PX, envelope="wide", hatch_deg=22.0)
        found = detect_defects(f.image, MM_PER_PX)
        chips = [t for t in f.defects if t.kind == "chip"]
        assert chips, seed
        for t in chips:
            near = [d for d in found if d.kind == "chip" and np.hypot(d.x_px - t.x_px, d.y_px - t.y_px) < 0.5 * t.length_px]
            assert near, (seed, t.x_px, t.y_px)


@pytest.mark.parametrize("angle, side, gap", [(150.0, 1, 0.0), (150.0, -1, 1.0), (150.0, 1, 2.0), (30.0, -1, 1.0)])
def test_a_deep_groove_grazing_a_rim_is_no_chip_and_a_chip_on_that_rim_is_found(angle, side, gap):
    """A groove of the hatch darker than the hole, running along the rim's tangent 2.5-4.5
    px outside it (its middle), moves the rim's edge out along an arc as a notch does: a
    0.35-0.49 mm "chip" (wide clean frame 1094030: 0.44 mm, the wide bench's one false
    defect per 100 clean frames). No groove direction leaves the rim outwards through
    that arc, so the run-on test (``_groove_run_on``) read nothing; the groove's darkness
    runs on along its line beyond both the notch's ends (1.14-1.33 of the hole's), where a
    chip's wall comes back (true chips on the benches: at most 0.6). The frame is clean;
    a true chip on the same rim, a third of the way round, is found as one and in place."""
    p = FrameParams(wall_level_dn=140.0, hole_level_dn=84.0, groove_depth=0.07, grain=0.03, blotch=0.03,
                    blur_sigma_px=1.5, gain_e_per_dn=30.0, read_noise_dn=1.5, vignetting=0.2, **SMALL)
    cx, cy, diameter = 320.3, 256.6, 90.0
    ux, uy = np.cos(np.deg2rad(angle)), np.sin(np.deg2rad(angle))
    nx, ny = -uy * side, ux * side  # from the hole's centre towards the groove
    g = diameter / 2 + 2.5 + gap
    wall = _with_groove_stretch(wall_patch(p, 300 + int(gap * 2)), cx + g * nx - 250 * ux, cy + g * ny - 250 * uy,
                                angle, 500.0, 0.6, width_px=5.0, fade=0.05)
    seed = 400 + int(gap * 2)
    clean = render_frame(p, [HoleSpec(cx, cy, diameter)], seed=seed, wall=wall)
    assert [(d.kind, round(d.length_mm, 3)) for d in detect_defects(clean.image, MM_PER_PX)] == []
    at = (np.rad2deg(np.arctan2(ny, nx)) + 120.0) % 360.0
    chip = DefectSpec("chip", length_px=14.0, width_px=4.0, angle_deg=at, hole=0, shape_seed=7)
    f = render_frame(p, [HoleSpec(cx, cy, diameter)], seed=seed, wall=wall, defects=[chip])
    (truth,) = [d.with_scale(MM_PER_PX) for d in f.defects]
    found = detect_defects(f.image, MM_PER_PX)
    assert [d.kind for d in found] == ["chip"], found
    assert np.hypot(found[0].x_px - truth.image_x_px, found[0].y_px - truth.image_y_px) * MM_PER_PX < 0.05


def test_a_bench_frames_grazing_groove_is_no_chip_and_a_chip_a_groove_runs_through_is():
    """Wide bench frames: clean frame 1094030, where a groove darker than the hole grazes
    its rim (a 0.44 mm "chip", along-the-groove share 1.78), and frame 94053, whose true
    chip (0.24 mm) a groove of the hatch runs through on a 36 %-dark hole: the highest
    share of 276 true chips on the benches (0.60). The first is clean, the second's chip
    is found."""
    assert _chips_without_false_ones(((1094030, True), (94053, False))) == 1


def _along_and_across(deg: float, h: int = 200, w: int = 480) -> tuple[np.ndarray, np.ndarray]:
    """Each pixel's place across and along lines of direction ``deg`` through the middle
    of an ``h`` x ``w`` frame (px): the ends' tests' rendered marks and grooves."""
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    a = np.deg2rad(deg)
    return (-np.sin(a) * (xx - w / 2) + np.cos(a) * (yy - h / 2), np.cos(a) * (xx - w / 2) + np.sin(a) * (yy - h / 2))


def _mark_ending_mid_frame(deg: float, h: int = 200, w: int = 480) -> tuple[np.ndarray, tuple]:
    """A flat wall level of 150 DN, and a 120 px centre line of direction ``deg`` that
    ends in the middle of the frame (its last point)."""
    along = np.linspace(-120.0, 0.0, 25)
    a = np.deg2rad(deg)
    return np.full((h, w), 150.0, np.float32), (w / 2 + along * np.cos(a), h / 2 + along * np.sin(a))


def test_a_groove_crossed_where_it_fades_has_no_cut_end_and_a_furrow_cut_there_has():
    """``end_steps`` with the crossing family (``other_deg``). A deep groove of the hatch
    that fades where a groove of the other family crosses it read, as core less flanks
    across the mark alone, as a step 1.1-1.8 px wide whatever the fade's length: the
    crossing groove meets the core and the flanks at places 5-10 px apart along the
    line. With the crossing family read along its own lines and taken out, the groove's
    end fades as it does, and a furrow cut at the crossing steps by all of its darkness
    over the blur alone (1.4 px). Wide clean frames 1097042 and 1097051 (22 deg hatch) are
    below: such stretches were 1.14 and 0.84 mm "scratches"."""
    from station.vision.defects import DefectConfig
    from station.vision.defects.examine import end_steps

    cfg = DefectConfig()
    blur = 1.4
    (u_a, v_a), (u_b, _) = _along_and_across(22.0), _along_and_across(158.0)
    level, line = _mark_ending_mid_frame(22.0)  # the mark ends at the crossing

    def image(dark):
        return level * (1.0 - cv2.GaussianBlur(dark.astype(np.float32), (0, 0), blur))

    for crossing in (0.15, 0.3):
        b = crossing * np.exp(-0.5 * (u_b / 3.0) ** 2)
        for fade in (4.0, 6.0, 10.0):
            groove = (0.05 + 0.3 * (1.0 - np.tanh(v_a / fade)) / 2.0) * np.exp(-0.5 * (u_a / 3.0) ** 2)
            m = dict(line=line, blur=blur, width=6.0)
            (width, _), = end_steps(image(groove + b), level, 0, 0, m, ends=(-1,), other_deg=158.0)
            assert width > 0.75 * fade, (crossing, fade, width)
            if fade >= 6.0:
                assert width > cfg.square_end_max_width_px, (crossing, fade, width)
        for furrow_w in (3.0, 6.0):
            furrow = 0.25 * ((np.abs(u_a) <= furrow_w / 2.0) & (v_a <= 0.0))
            m = dict(line=line, blur=blur, width=furrow_w)
            (width, height), = end_steps(image(furrow + b), level, 0, 0, m, ends=(-1,), other_deg=158.0)
            assert abs(width - blur) < 0.2 and abs(height - 1.0) < 0.05, (crossing, furrow_w, width, height)
    for seed in (1097042, 1097051):
        f = random_defect_frame(seed, {}, mm_per_px=MM_PER_PX, envelope="wide", hatch_deg=22.0)
        assert [(d.kind, round(d.length_mm, 3)) for d in detect_defects(f.image, MM_PER_PX)] == [], seed


def test_a_tapering_furrows_cut_end_reads_square():
    """``end_steps`` fits the step over the end's last 15 px inside: a furrow whose
    darkness grows 1.8x over the 30 px inside its cut end (a scratch that tapers, or
    bends off its chord) read over all 30 px, in grain, was a step as wide as the taper
    about half the time (10 of 20 renders square; 0.7 or 12 px on bench frame 542006 as
    the data moved by a few thousandths), and an untapered furrow's end reads as before."""
    from station.vision.defects import DefectConfig
    from station.vision.defects.examine import end_steps

    cfg = DefectConfig()
    h, w, blur = 200, 480, 1.4
    (u, v), (level, line) = _along_and_across(22.0), _mark_ending_mid_frame(22.0)
    m = dict(line=line, blur=blur, width=3.0)
    for taper, least in ((0.8, 17), (0.0, 19)):
        square = 0
        for k in range(20):
            grain = cv2.GaussianBlur(np.random.default_rng(k).standard_normal((h, w)).astype(np.float32), (0, 0), 0.7)
            dark = 0.1 * (1.0 + taper * np.clip(-v, 0.0, 30.0) / 30.0) * (np.abs(u) <= 1.5) * (v <= 0.0)
            img = level * (1.0 - cv2.GaussianBlur(dark.astype(np.float32), (0, 0), blur) - 0.01 * grain / grain.std())
            (width, height), = end_steps(img, level, 0, 0, m, ends=(-1,))
            square += width <= cfg.square_end_max_width_px and height >= cfg.square_end_min_height
        assert square >= least, (taper, square)


def test_a_deep_grooves_stretch_meeting_a_hole_is_not_cut_there():
    """A mark along the hatch is a scratch only if it ends in cuts; one cut end and the
    other running on is read again on the residual with its line left out of the
    grooves. The residual is 0 in the holes' zone, which read as the wall beyond an end
    that meets a hole: a cut. Wide clean frames 1096029 (a deep groove's stretch between
    a crossing and a rim: a 0.63 mm "scratch") and 1096052 (a 1.45 mm stretch whose far
    end's read reached a hole's zone 18 px on). The zone is not read there, as the frame's
    border is not: both frames are clean."""
    for seed in (1096029, 1096052):
        f = random_defect_frame(seed, {}, mm_per_px=MM_PER_PX, envelope="wide")
        assert [(d.kind, round(d.length_mm, 3)) for d in detect_defects(f.image, MM_PER_PX)] == [], seed


def test_a_rims_edge_is_where_the_share_falls_for_good_not_where_the_noise_dips():
    """``_rim_profile`` reads a ray's edge where the share of hole falls below the
    crossing going out and stays below it over ``RIM_HOLD_PX``. On the wide bench's dim,
    noisy holes the share inside reads 1 +/- 0.1 a sample, and one sample below 0.75 some
    15 px inside the rim was that ray's edge: 0.03-0.07 mm "burrs" 3-12 px high (wide
    clean frames 1097086, 1099092 and 1100029, below). A bright pixel inside a hole now
    leaves the edge at the rim, and a burr's metal, which runs on to the wall, is still
    read at its tip."""
    from types import SimpleNamespace

    from station.vision.defects.rims import _rim_profile

    h = w = 160
    cx = cy = 80.0
    rad, blur = 35.0, 1.4
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    rho, phi = np.hypot(xx - cx, yy - cy), np.arctan2(yy - cy, xx - cx)
    hole = rho < rad
    # a burr: the wall's metal 5 px into the hole over 10 px of arc round 180 deg
    burr = (rho >= rad - 5.0) & (rho < rad + 1.0) & (np.abs(np.abs(phi) - np.pi) < 5.0 / rad)
    dark = np.where(hole & ~burr, 1.0, 0.0).astype(np.float32)
    img = 150.0 * (1.0 - 0.33 * cv2.GaussianBlur(dark, (0, 0), blur))
    img[int(cy), int(cx + rad - 15.0)] = 150.0  # a bright pixel inside, on the 0 deg ray
    spec = SimpleNamespace(x_px=cx, y_px=cy, diameter_px=2.0 * rad)
    prof = _rim_profile(img, spec, np.zeros((h, w), bool), 18.0, np.full((h, w), 150.0, np.float32),
                        (30.0, 150.0), blur, 0.75, 1.0, True)
    deg = np.rad2deg(prof.theta)
    at0 = (deg < 0.5) | (deg > 359.5)
    at180 = np.abs(deg - 180.0) < 2.0
    for edge in (prof.edge, prof.edge_find):
        rim = float(np.median(edge))  # the 0.75 crossing of the blurred step: ~0.7 blur inside
        assert np.all(np.abs(edge[at0] - rim) < 1.0), edge[at0] - rim
        assert np.all(np.abs(edge[at180] - (rim - 5.0)) < 1.0), edge[at180] - rim
    for seed, hatch in ((1097086, 22.0), (1099092, 25.0), (1100029, 35.0)):
        f = random_defect_frame(seed, {}, mm_per_px=MM_PER_PX, envelope="wide", hatch_deg=hatch)
        assert [(d.kind, round(d.length_mm, 3)) for d in detect_defects(f.image, MM_PER_PX)] == [], seed


def test_a_stretch_the_grooves_scaling_adds_along_a_groove_at_a_level_of_its_own_is_no_scratch():
    """``_shelf_beyond``: the stretch that the grooves' scaling adds past the raw read's
    end is a groove's shelf, not the scratch, when a modelled groove runs along the
    scratch's filter there and the stretch holds the scaled darkening at most at
    ``SHELF_MAX_SHARE`` of the scratch's, the two not overlapping. The scaling lifted a
    groove that a scratch ends on at 12 deg to half the scratch's level (station frame
    110048, in the next test: a 0.85 mm scratch read 1.82 mm). Where the scaling restores
    the scratch through a groove it crosses, or the scratch narrows a little, or no groove
    runs along it (a faint end its straight line leaves: 91044), the stretch is the
    scratch's; and a stretch under ``SHELF_MIN_PX`` says nothing."""
    from station.vision.defects.scratches import SHELF_MAX_SHARE, SHELF_MIN_GROOVE_SHARE, SHELF_MIN_PX, _shelf_beyond

    rng = np.random.default_rng(110048)
    step = 0.5

    def profile(parts):  # (length px, level) pieces, sampled every 0.5 px, with noise
        m = np.concatenate([np.full(int(n / step), v) for n, v in parts])
        return m + rng.normal(0.0, 0.04, m.size)

    core = (int(60 / step), int(140 / step))  # the raw read's extent: 60-140 px
    a = int(20 / step)  # the scaled read starts 40 px before it
    along = profile([(20, 0.0), (40, 0.45), (80, 0.0), (20, 0.0)])  # a groove along the filter before it
    assert _shelf_beyond(profile([(20, 0.0), (40, 0.5), (80, 1.0), (20, 0.0)]), along, a, core[0], core, step)
    assert _shelf_beyond(profile([(20, 0.0), (40, SHELF_MAX_SHARE - 0.05), (80, 1.0), (20, 0.0)]), along, a,
                         core[0], core, step)
    # ... and after it
    after = profile([(60, 0.0), (80, 0.0), (20, 0.4)])
    assert _shelf_beyond(profile([(60, 0.0), (80, 1.0), (20, 0.45)]), after, core[1], int(160 / step), core, step)
    # no groove along it (crossings only): the scratch's own end, however low
    crossing = profile([(20, 0.0), (40, SHELF_MIN_GROOVE_SHARE - 0.1), (80, 0.0), (20, 0.0)])
    assert not _shelf_beyond(profile([(20, 0.0), (40, 0.5), (80, 1.0), (20, 0.0)]), crossing, a, core[0], core, step)
    # restored through a groove it crosses, or a quarter narrower: the scratch's
    for level in (0.95, 0.75):
        assert not _shelf_beyond(profile([(20, 0.0), (40, level), (80, 1.0), (20, 0.0)]), along, a, core[0], core,
                                 step)
    # too short to say
    a_short = core[0] - int((SHELF_MIN_PX - 2.0) / step)
    assert not _shelf_beyond(profile([(52, 0.0), (8, 0.5), (80, 1.0), (20, 0.0)]), along, a_short, core[0], core,
                             step)


def test_a_run_on_that_turns_onto_a_groove_is_the_groove():
    """``_turns_onto_hatch``: a scratch's run on whose body, past its first 60 px, is a
    straight line along a groove family while the scratch's end runs off the hatch is a
    groove the scratch ends on. Station frame 110048: a 0.85 mm scratch 12 deg off the
    30 deg hatch ends on a deep groove; its first box took the groove's residue in (1.82
    mm, a false scratch and a miss), and, its box cut at its own end, the run on followed
    the groove to the frame's border (8.3 mm). Now it is found and sized."""
    from station.vision.defects import DefectConfig
    from station.vision.defects.tracking import _turns_onto_hatch

    cfg = DefectConfig()
    hatch = (30.0, 150.0)

    def path(start, deg, length, step=2.0):
        t = np.array([np.cos(np.deg2rad(deg)), np.sin(np.deg2rad(deg))])
        return np.asarray(start, float) + np.arange(0.0, length + step / 2, step)[:, None] * t

    line = path((100.0, 100.0), 18.0, 90.0)  # a scratch 12 deg off the hatch, ends at line[-1]
    end = line[-1]
    turn = path(end, 24.0, 40.0)
    onto = np.vstack([turn, path(turn[-1], 30.0, 300.0)[1:]])
    assert _turns_onto_hatch(line, -1, onto, hatch, cfg)
    # straight on: the scratch's own furrow
    assert not _turns_onto_hatch(line, -1, path(end, 18.0, 340.0), hatch, cfg)
    # a bend that passes the hatch's direction and goes on bending: a scratch's
    s = np.arange(0.0, 340.0, 2.0)
    ang = np.deg2rad(18.0 + 0.09 * s)  # 4.5 deg per 50 px
    bent = end + np.column_stack([np.concatenate([[0.0], np.cumsum(2.0 * np.cos(ang[:-1]))]),
                                  np.concatenate([[0.0], np.cumsum(2.0 * np.sin(ang[:-1]))])])
    assert not _turns_onto_hatch(line, -1, bent, hatch, cfg)
    # too short a body to say
    assert not _turns_onto_hatch(line, -1, np.vstack([turn, path(turn[-1], 30.0, 100.0)[1:]]), hatch, cfg)
    # a scratch along the hatch running on along it
    along = path((100.0, 100.0), 30.0, 90.0)
    assert not _turns_onto_hatch(along, -1, path(along[-1], 30.0, 340.0), hatch, cfg)
    # the frame
    f = random_defect_frame(110048, None, mm_per_px=MM_PER_PX)
    truth = [t for t in f.defects if t.kind == "scratch"]
    found = detect_defects(f.image, MM_PER_PX)
    pairs, false = match(f.defects, found, MM_PER_PX)
    assert not false, [(found[k].kind, round(found[k].length_mm, 3)) for k in false]
    (t, d), = [(t, d) for t, d in pairs if t.kind == "scratch"]
    assert len(truth) == 1 and d is not None and d.kind == "scratch"
    assert abs(d.length_mm - t.length_mm) <= 0.1 * t.length_mm, (d.length_mm, t.length_mm)


def test_an_end_read_where_a_grooves_stretch_begins_is_not_followed_on():
    """A scratch's end that the measurement read where a groove's stretch begins
    (``_groove_beyond_end``, ``_shelf_beyond``) is not followed on the raw darkness
    (``track_scratches``): beyond it that darkness is the groove's. The twin's frame
    2088002: a 1.58 mm scratch ends on a deep groove at a shallow angle; the scaling's
    shelf carried its end 12 px on (its place 0.067 mm off, over the 0.05 mm a defect's
    place is allowed), and with its end read right the run on went 21 px straight on
    through the groove's band to a step that passes as a cut (0.11 mm off)."""
    from station.bench.defects import PLACE_TOL_MM, twin_scratch_frame

    f = twin_scratch_frame(2088002)
    (t,) = f.defects
    found = [d for d in detect_defects(f.image, MM_PER_PX) if d.kind == "scratch"]
    assert len(found) == 1, [(d.kind, round(d.length_mm, 3)) for d in found]
    d = found[0]
    assert abs(d.length_mm - t.length_mm) <= 0.1 * t.length_mm, (d.length_mm, t.length_mm)
    place = float(np.hypot(d.x_px - t.x_px, d.y_px - t.y_px)) * MM_PER_PX
    assert place <= PLACE_TOL_MM, place


def test_a_faint_ragged_mark_is_no_scratch_and_a_faint_straight_one_is():
    """``min_scratch_line_contrast``: a scratch's contrast carried along its own direction
    (the fitted contrast times the square root of the along share) must reach 0.076. The
    grooves' residue that passes the contrast and along-share gates one at a time can be
    faint and ragged at once: fresh wide clean frames 1116042 and 1116076 each read a
    deep broad groove as a 0.27-1.0 mm "scratch" (under a hole, one arm of a crossing) at
    a contrast of 0.11 and a share of 0.35-0.39 (0.067-0.070). Faint true scratches pass:
    station frames 118085 (a 0.56 mm scratch read at 0.138 and 0.62) and 113013 (a 0.26
    mm one at 0.131 and 0.78), and wide 129012 at a 26 deg hatch (a 0.40 mm scratch among
    deep grooves at 0.125 and 0.43: 0.082)."""
    for seed in (1116042, 1116076):
        f = random_defect_frame(seed, {}, mm_per_px=MM_PER_PX, envelope="wide")
        found = detect_defects(f.image, MM_PER_PX)
        assert not found, (seed, [(d.kind, round(d.length_mm, 3), round(d.width_mm, 3)) for d in found])
    for seed, kw in ((118085, {}), (113013, {}), (129012, dict(envelope="wide", hatch_deg=26.0))):
        f = random_defect_frame(seed, None, mm_per_px=MM_PER_PX, **kw)
        found = detect_defects(f.image, MM_PER_PX)
        pairs, false = match(f.defects, found, MM_PER_PX)
        assert not any(found[k].kind == "scratch" for k in false), (seed, [found[k].length_mm for k in false])
        scratches = [(t, d) for t, d in pairs if t.kind == "scratch"]
        assert scratches, seed
        for t, d in scratches:
            assert d is not None and d.kind == "scratch", (seed, t.length_mm)
            assert abs(d.length_mm - t.length_mm) <= max(0.1 * t.length_mm, 0.02), (seed, d.length_mm, t.length_mm)


def test_a_run_on_off_the_hatch_that_the_residual_does_not_carry_is_the_grooves():
    """``_run_on_grooves_only``: off the hatch no groove's line mean takes a furrow in, so
    a run on there must hold half the scratch's own darkness with the grooves removed;
    along the hatch the residual says nothing. Synthetic residuals, then the twin's frames:
    2130019 and 2115051 (1.26 and 1.41 mm scratches meeting a deep groove at a shallow
    angle) ran on 15 and 14 px through the groove's band (0.08 mm off); 2091057's true
    run on (16 px, at 0.76 of the body's residual) is kept."""
    from station.bench.defects import PLACE_TOL_MM, twin_scratch_frame
    from station.vision.defects import DefectConfig
    from station.vision.defects.tracking import _run_on_grooves_only

    cfg = DefectConfig()
    hatch = (30.0, 150.0)
    residual = np.random.default_rng(2130019).normal(0.0, 0.005, (200, 300)).astype(np.float32)  # the wall's
    line = np.column_stack([np.linspace(40.0, 200.0, 17), np.full(17, 200.0)])  # a scratch at 0 deg (frame px)
    residual[99:102, 20:101] += 0.08  # ... and the scratch's residual (half resolution)
    run = np.column_stack([np.linspace(200.0, 230.0, 16), np.full(16, 200.0)])
    assert _run_on_grooves_only(residual, line, run, hatch, cfg)  # nothing carries it on
    carried = residual.copy()
    carried[99:102, 100:116] += 0.06
    assert not _run_on_grooves_only(carried, line, run, hatch, cfg)
    # along a family the grooves' means take a furrow in: no judgement
    run_along = np.vstack([line[-1], line[-1] + 30.0 * np.array([np.cos(np.deg2rad(30.0)), np.sin(np.deg2rad(30.0))])])
    assert not _run_on_grooves_only(residual, line, run_along, hatch, cfg)
    for seed in (2130019, 2115051, 2091057):
        f = twin_scratch_frame(seed)
        (t,) = f.defects
        found = [d for d in detect_defects(f.image, MM_PER_PX) if d.kind == "scratch"]
        assert len(found) == 1, (seed, [round(d.length_mm, 3) for d in found])
        d = found[0]
        assert abs(d.length_mm - t.length_mm) <= 0.1 * t.length_mm, (seed, d.length_mm, t.length_mm)
        place = float(np.hypot(d.x_px - t.x_px, d.y_px - t.y_px)) * MM_PER_PX
        assert place <= PLACE_TOL_MM, (seed, place)


def test_the_grooves_scaling_does_not_split_what_the_raw_read_holds_together():
    """A scratch's profile along it, read again with the grooves' scaling: a gap that
    the scaling alone makes (a groove beside the scratch drives the residual below zero,
    a junction of grooves on it lifts the median) does not split it where the raw read
    holds; a gap the raw read has too still does (the larger piece is kept). And the
    twin's 2170043, a faint 1.6 mm scratch whose lesser half was lost that way (read
    0.66 mm, 0.48 mm off), is found whole."""
    from station.vision.defects.scratches import _scratch_extent

    step = 0.5
    raw = np.zeros(400)
    raw[40:360] = 1.0  # 160 px of scratch, 2 samples per px
    raw[200:230] = 0.5  # ... fainter where a groove runs beside it, but there
    scaled = raw.copy()
    scaled[200:230] = -0.3  # the scaling's gap
    scaled[240:300] = 2.0  # a junction lifted
    ext_raw = _scratch_extent(raw, step, 8.0)
    assert ext_raw == (40, 360)
    assert _scratch_extent(scaled, step, 8.0) == (230, 360)  # without the raw read: split
    assert _scratch_extent(scaled, step, 8.0, held=(raw, ext_raw)) == (40, 360)
    raw_gap = raw.copy()
    raw_gap[200:230] = 0.0  # the raw read has the gap too: two marks
    assert _scratch_extent(raw_gap, step, 8.0)[1] <= 205  # the raw read splits it too
    assert _scratch_extent(scaled, step, 8.0, held=(raw_gap, (40, 360))) == (230, 360)
    t, d = _the_twin_scratch_found(2170043)
    assert abs(d.length_mm - t.length_mm) <= 0.02


def test_a_scratchs_peaks_that_turn_onto_the_hatch_at_its_end_are_the_groove():
    """``_hatch_tail``: a scratch that ends on a deep groove at a shallow angle joins the
    groove's residue in one region, and its centre-line peaks run on along the groove.
    Synthetic peaks: a body 17 deg off a groove family with a 100 px tail along it, half
    as dark, is cut at the kink, at either end; no tail when the tail is off the hatch,
    when the body is along it, when the tail is nearly as dark as the body, or when the
    line is straight or bends smoothly (a cubic fits it 4x better than two lines). Then the twin's frame
    2131037 (a 1.33 mm scratch read 2.36 mm, its place 0.5 mm off)."""
    from station.vision.defects.scratches import _hatch_tail

    rng = np.random.default_rng(2131037)
    hatch = (30.0, 150.0)
    ang = np.deg2rad(47.0)  # the axis: the body's direction

    def peaks(turn_deg, body=(0.0, 135.0), tail_len=100.0, at_high=True, tail_share=0.5):
        sb = np.arange(body[0], body[1], 0.5)
        m = np.tan(np.deg2rad(turn_deg))
        st = np.arange(body[1], body[1] + tail_len, 0.5) if at_high else np.arange(body[0] - tail_len, body[0], 0.5)
        ct = m * (st - (body[1] if at_high else body[0]))
        s = np.concatenate([sb, st])
        c = np.concatenate([np.zeros(sb.size), ct]) + rng.normal(0.0, 0.3, sb.size + st.size)
        return s, c, np.concatenate([np.ones(sb.size), np.full(st.size, tail_share)])  # the peaks' heights

    cut = _hatch_tail(*peaks(-17.0), ang, hatch, 7.5)  # the tail at 30 deg
    assert cut is not None
    mask, where, side = cut
    s = peaks(-17.0)[0]
    assert side == 1 and abs(where - 135.0) <= 4.0, (side, where)
    assert mask[s > 140.0].all() and not mask[s < 130.0].any()
    low = _hatch_tail(*peaks(-17.0, at_high=False), ang, hatch, 7.5)  # 47 - 17 = 30 deg either way
    assert low is not None and low[2] == 0 and abs(low[1] - 0.0) <= 4.0, low and low[1:]
    assert _hatch_tail(*peaks(-9.0), ang, hatch, 7.5) is None  # the tail at 38 deg: no groove's
    assert _hatch_tail(*peaks(0.0), ang, hatch, 7.5) is None  # straight on
    assert _hatch_tail(*peaks(-17.0), np.deg2rad(36.0), hatch, 7.5) is None  # the body along the hatch
    # a tail as dark as the body is a scratch's own stretch along the hatch (a scratch along
    # it whose region took in a piece off it: along the hatch 542000, six cut to a third)
    assert _hatch_tail(*peaks(-17.0, tail_share=0.8), ang, hatch, 7.5) is None
    s = np.arange(0.0, 235.0, 0.5)  # a smooth bend of the renderer's size (1.2 % of the length)
    c = 0.012 * 235.0 * np.sin(np.pi * s / 235.0) + rng.normal(0.0, 0.3, s.size)
    assert _hatch_tail(s, c, np.where(s > 140.0, 0.5, 1.0), ang, hatch, 7.5) is None
    _the_twin_scratch_found(2131037)
    # a scratch 10 deg off the hatch whose own smooth bend takes its last 48 px within 3
    # deg of it, fainter there (station frame 88091, 1.81 mm): a cubic fits it 8.5x better
    # than two lines, and it is not cut
    f = random_defect_frame(88091, None, mm_per_px=MM_PER_PX)
    pairs, _ = match(f.defects, detect_defects(f.image, MM_PER_PX), MM_PER_PX)
    (t, d), = [(t, d) for t, d in pairs if t.kind == "scratch" and t.length_mm > 1.0]
    assert d is not None and d.kind == "scratch" and abs(d.length_mm - t.length_mm) <= 0.1 * t.length_mm, d


def test_a_dim_hole_whose_rim_defects_take_half_its_rays_is_still_a_hole_for_its_rims():
    """``rim_hole_min_inlier_fraction``: the rim analysis measures a hole that the
    photometric fit drops by its rays alone, and there its rim defects are the rays'
    outliers. Wide frame 129068 (26 deg hatch): a dim 0.70 mm hole (33 % contrast, blur
    1.8 px) with two burrs and two chips had 103 of 218 rays agree, under the hole
    measurement's 0.5; it was no hole and its four defects were lost."""
    f = random_defect_frame(129068, None, mm_per_px=MM_PER_PX, envelope="wide", hatch_deg=26.0)
    found = detect_defects(f.image, MM_PER_PX)
    pairs, false = match(f.defects, found, MM_PER_PX)
    rim = [(t, d) for t, d in pairs if t.kind in ("burr", "chip")]
    assert len(rim) == 4
    assert all(d is not None and d.kind == t.kind for t, d in rim), [(t.kind, d and d.kind) for t, d in rim]
    assert not false, [(found[k].kind, round(found[k].length_mm, 3)) for k in false]


@pytest.mark.parametrize("seed, rim", [(270025, ("burr", "chip", "chip")), (270027, ("burr", "burr"))])
def test_a_dim_holes_noisy_or_cut_rim_is_still_measured_for_its_rims(seed, rim):
    """The rim analysis's own measurement of the holes the photometric fit drops, by their
    rays alone. Wide frame 270025: a dim 0.74 mm hole (31 % contrast, blur 1.9 px) with a
    burr and two chips; its rays agreed (0.53) but scattered 0.47 px, its confidence read
    0.116 against the hole measurement's 0.15 (``rim_hole_min_confidence``). Wide frame
    270027: a dim 0.70 mm hole with two burrs of 0.22 and 0.28 mm, which the coarse detector
    read as a 44 px blob, under the 0.8 of the least hole's diameter its rays were cast
    from (``rim_hole_coarse_share``). Each was no hole, and its rim defects were lost."""
    f = random_defect_frame(seed, None, mm_per_px=MM_PER_PX, envelope="wide")
    (hole,) = [h for h in f.holes if h.x_px < 300 or h.x_px > 1100]
    found = detect_defects(f.image, MM_PER_PX)
    pairs, false = match(f.defects, found, MM_PER_PX)
    here = [(t, d) for t, d in pairs if np.hypot(t.image_x_px - hole.image_x_px, t.image_y_px - hole.image_y_px)
            < hole.diameter_px]
    assert sorted(t.kind for t, _ in here) == sorted(rim)
    # the rim defects above the spec's limits found as what they are
    big = [(t, d) for t, d in here if above_limit(t.kind, t.length_mm, t.width_mm)]
    assert big and all(d is not None and d.kind == t.kind for t, d in big), \
        [(t.kind, round(t.length_mm, 3), d and d.kind) for t, d in here]
    assert not false, [(found[k].kind, round(found[k].length_mm, 3)) for k in false]


def test_a_large_pore_its_rays_read_as_a_holes_circle_is_no_hole_and_stays_a_pore():
    """The rim analysis measures by their rays alone the dark discs the hole measurement
    drops, and a large elongated pore gave one: wide frame 4920063's 0.47 x 0.31 mm pore
    read as a 0.56 mm circle (over the 0.55 mm that parts a pore from a hole) that it
    fills half of. Its outline was read as two chips and the pore was lost. What such a
    circle holds must be dark (``rim_hole_min_dark_share``); the holes measured so keep
    their rims' defects (wide frame 4920007: a 0.91 mm hole with two burrs and a chip)."""
    from station.vision.defects.frame import _dark_disc_share, _measure_holes_for_rims

    f = random_defect_frame(4920063, None, mm_per_px=MM_PER_PX, envelope="wide")
    assert not f.holes
    (pore,) = [t for t in f.defects if t.kind == "pore" and t.length_mm > 0.4]
    found = detect_defects(f.image, MM_PER_PX)
    pairs, false = match(f.defects, found, MM_PER_PX)
    assert not false, [(found[k].kind, round(found[k].length_mm, 3)) for k in false]
    (d,) = [d for t, d in pairs if t is pore]
    assert d is not None and d.kind == "pore" and _within(d.length_mm, pore.length_mm), d
    # the rays' circle is read, and what it holds is judged
    cfg = DefectConfig()
    assert _measure_holes_for_rims(f.image, MM_PER_PX, replace(cfg, rim_hole_min_dark_share=0.0))
    assert _measure_holes_for_rims(f.image, MM_PER_PX, cfg) == []
    g = random_defect_frame(4920007, None, mm_per_px=MM_PER_PX, envelope="wide")
    holes = _measure_holes_for_rims(g.image, MM_PER_PX, cfg)
    assert len(holes) == len(g.holes) and all(_dark_disc_share(g.image, h) > 0.9 for h in holes)
    pairs, false = match(g.defects, detect_defects(g.image, MM_PER_PX), MM_PER_PX)
    rim = [(t, d) for t, d in pairs if t.kind in ("burr", "chip")]
    assert len(rim) == 3 and all(d is not None and d.kind == t.kind for t, d in rim), rim
    assert not false


def test_a_dark_disc_at_none_of_the_parts_holes_is_a_pore_whatever_its_size():
    """``hole_places``: where the part's holes show (the whole-surface scan knows them from
    the bore scan). A dark disc of a hole's size at none of them is a mark of the wall: a
    0.9 and a 1.25 mm pore are measured as pores within the issue's tolerance, the wall's
    level modelled past them (under the pores' 0.55 mm it followed a 1.25 mm pore's
    middle, and half the pores of 0.65-1.3 mm were lost), and the hole where the part has
    one keeps its burr. Without the places a disc that size is taken for a hole (a frame
    alone does not say which are the part's): the 1.25 mm pore is lost, its outline read
    as a rim's defect. With none (``()``, a frame the part's holes are not in), the hole is
    a drilling the drawing does not have, reported as a pore of its size, its rim not
    judged. Station-size frames: the wall's model reaches twice the largest mark."""
    from sim.camera.render import HoleSpec

    rng = np.random.default_rng(5)
    params = random_params(rng, "station", width_px=1280, height_px=1024)
    defects = [DefectSpec("pore", 440.0, 130.0, 90.0, 70.0, 20.0, shape_seed=6),
               DefectSpec("pore", 900.0, 700.0, 125.0, 105.0, 110.0, shape_seed=7),
               DefectSpec("burr", hole=0, angle_deg=300.0, length_px=15.0, width_px=6.0, shape_seed=8)]
    f = render_frame(params, [HoleSpec(150.0, 256.0, 70.0)], seed=5, defects=defects)
    f.defects = [d.with_scale(MM_PER_PX) for d in f.defects]
    (hole,) = f.holes
    small, large, burr = f.defects

    def run(places):
        found = detect_defects(f.image, MM_PER_PX, hole_places=places)
        pairs, false = match(f.defects, found, MM_PER_PX)
        return dict((id(t), d) for t, d in pairs), [found[k] for k in false]

    got, false = run(None)
    assert got[id(large)] is None or got[id(large)].kind != "pore" \
        or not _within(got[id(large)].length_mm, large.length_mm)
    got, false = run([(hole.image_x_px, hole.image_y_px, 45.0)])
    for t in (small, large):
        d = got[id(t)]
        assert d is not None and d.kind == "pore" and _within(d.length_mm, t.length_mm) \
            and _within(d.width_mm, t.width_mm), (t.length_mm, d)
    assert got[id(burr)] is not None and got[id(burr)].kind == "burr" and got[id(burr)].hole == 0
    assert not false, false
    got, false = run(())
    assert all(got[id(t)] is not None and got[id(t)].kind == "pore" for t in (small, large))
    (drilling,) = false
    assert drilling.kind == "pore" and abs(drilling.length_mm - hole.diameter_px * MM_PER_PX) < 0.05 \
        and np.hypot(drilling.x_px - hole.image_x_px, drilling.y_px - hole.image_y_px) < 5.0, drilling


def test_a_dark_disc_at_none_of_the_parts_holes_is_not_measured_again_under_a_level_round_it(monkeypatch):
    """A pore the frame's level dipped under is measured again under the level taken round
    it (``wall.level_dip``); the dark discs of a hole's size at none of the part's holes
    are not: the frame's model reaches past them already, and one of the whole-surface
    bench (seed 96000, ``--large-pores 3``) read 10 % long so. With every pore's dip read
    as large, the 0.9 and 1.25 mm discs are still never judged by it, and the 0.3 mm pore
    beside them is."""
    import station.vision.defects.examine as examine

    rng = np.random.default_rng(5)
    params = random_params(rng, "station", width_px=1280, height_px=1024)
    defects = [DefectSpec("pore", 440.0, 130.0, 90.0, 70.0, 20.0, shape_seed=6),
               DefectSpec("pore", 900.0, 700.0, 125.0, 105.0, 110.0, shape_seed=7),
               DefectSpec("pore", 700.0, 300.0, 30.0, 24.0, 60.0, shape_seed=9)]
    f = render_frame(params, [], seed=5, defects=defects)
    judged = []

    def every_dip(img, patch, region, sigma):
        ys, xs = np.nonzero(region)
        judged.append((patch.x0 + xs.mean(), patch.y0 + ys.mean()))
        return 1.0

    monkeypatch.setattr(examine, "level_dip", every_dip)
    found = detect_defects(f.image, MM_PER_PX, hole_places=())
    pairs, false = match([d.with_scale(MM_PER_PX) for d in f.defects], found, MM_PER_PX)
    assert not false and all(d is not None and d.kind == "pore" for _, d in pairs), found

    def near(x, y):
        return any(np.hypot(x - jx, y - jy) < 15.0 for jx, jy in judged)

    assert near(700.0, 300.0) and not near(440.0, 130.0) and not near(900.0, 700.0), judged


def test_a_scratch_end_read_at_half_its_local_height_does_not_walk_out_over_a_shelf():
    """A square end is read where the profile falls through half its local height, and
    read again from there; where the scratch ends on a deep groove crossing it, the wall
    model's misfit of the groove beyond holds a third of the scratch's level, and the
    walk fell onto that shelf and on along it. An end that went 10 px or more past the
    raw read's over a shelf (``_shelf_beyond``) is read at half the scratch's own level:
    the twin's 2133057, a 1.22 mm scratch read 1.37 mm and 0.07 mm off, now within 10 %
    and 0.05 mm. ``fit_end`` with a known height crosses at its half."""
    from scipy.ndimage import gaussian_filter1d

    from station.vision.defects.common import fit_end

    s = np.arange(-30.0, 30.0, 0.5)
    # a scratch ending at 0, a shelf fading to 16 (blurred), the end's first guess 3 px out
    step = gaussian_filter1d(np.where(s < 0.0, 1.0, np.where(s < 16.0, 0.45 - 0.025 * s, 0.0)), 2.0)
    walked, _ = fit_end(s, step, 3.0, 1.0, rising=False)
    held, _ = fit_end(s, step, 3.0, 1.0, rising=False, height=1.0)
    assert walked > 10.0 and abs(held) <= 1.0, (walked, held)
    _the_twin_scratch_found(2133057)


@pytest.mark.parametrize("seed", [530015, 530045])
def test_a_bent_scratch_along_the_hatch_whose_grown_patch_cuts_it_again_is_followed_on(seed):
    """A bent scratch 0-5 deg off a groove family (station bench seeds drawn with
    ``scratch_within_deg=5``: 530015's 1.72 x 0.057 mm, 530045's 1.36 x 0.035 mm): the wall
    model's grooves along its line take it in by pieces, each with one square end and the
    other running on. The patch grown along a piece cut it again; with neither patch's
    verdict a defect, the grown one's piece is followed on, and the scratch is measured
    whole."""
    f = random_defect_frame(seed, None, mm_per_px=MM_PER_PX, scratch_within_deg=5.0)
    found = detect_defects(f.image, MM_PER_PX)
    pairs, false = match(f.defects, found, MM_PER_PX)
    assert [found[i] for i in false] == []
    for t, d in pairs:
        assert d is not None and d.kind == t.kind, (t.kind, t.x_px, t.y_px)
        if t.kind == "scratch":
            assert _within(d.length_mm, t.length_mm), (d.length_mm, t.length_mm)


def test_a_scratch_along_the_hatch_cut_at_both_ends_where_a_groove_crosses_one_is_found():
    """A 0.80 x 0.055 mm scratch 4 deg off a groove family (station bench seed 580021,
    drawn with ``scratch_within_deg=7.5``) ends where a groove of the other family crosses:
    its ends step 1.6 px / 1.01 and 1.5 px / 0.72 of its darkness, under the 0.8 a lone
    square end needs. Cut sharply at both, it is a scratch; the frame's other defects are
    found and nothing is false."""
    f = random_defect_frame(580021, None, mm_per_px=MM_PER_PX, scratch_within_deg=7.5)
    found = detect_defects(f.image, MM_PER_PX)
    pairs, false = match(f.defects, found, MM_PER_PX)
    assert [found[i] for i in false] == []
    assert len([t for t, _ in pairs if t.kind == "scratch"]) == 2
    for t, d in pairs:
        assert d is not None and d.kind == t.kind, (t.kind, t.x_px, t.y_px)
        if t.kind == "scratch":
            assert _within(d.length_mm, t.length_mm), (d.length_mm, t.length_mm)


def test_a_scratchs_line_significance_is_the_boxs_for_a_box_and_unit_on_white_noise():
    """``_line_significance`` weighs the strip by the scratch's own blurred box: on white
    noise of the per-pixel sd it assumes (5 x the 5 x 5 box mean's) it spreads with sd 1
    about 0; on a thin line it reads well above the box integral's significance (~1.4x
    for a 1.6 px line under 1.3 px of blur in a 14.5 px band and 5 px flanks); without
    flanks, a model as wide as the band reads what the box does."""
    from station.vision.defects.scratches import _blurred_box, _line_significance

    step = 0.5
    nu = np.arange(-12.0, 12.0 + step / 2, step)
    core = np.abs(nu) <= 7.0
    sv = np.arange(0.0, 150.0, step)
    sigma = 0.04
    noise_box5 = sigma / 5.0
    rng = np.random.default_rng(5)
    # white noise of sd sigma per px, sampled every half px: the same px twice each way
    nulls = []
    for _ in range(300):
        px = rng.normal(0.0, sigma, (nu.size // 2 + 1, sv.size // 2 + 1))
        st = np.repeat(np.repeat(px, 2, axis=0), 2, axis=1)[: nu.size, : sv.size]
        nulls.append(_line_significance(st, nu, core, sv, 10.0, 140.0, step, 0.0, 1.6, 1.3, noise_box5))
    nulls = np.array(nulls)
    assert abs(nulls.mean()) < 0.2 and 0.8 < nulls.std() < 1.25
    # a thin line: its box significance over the core against its line's
    line = 0.3 * _blurred_box(nu, 0.0, 1.6, 1.3)[:, None] * np.ones(sv.size)
    sel = (sv >= 10.0) & (sv <= 140.0)
    box = float(line[core][:, sel].sum()) * step * step / (5.0 * noise_box5 * np.sqrt(core.sum() * step * 130.0))
    thin = _line_significance(line, nu, core, sv, 10.0, 140.0, step, 0.0, 1.6, 1.3, noise_box5)
    assert 1.3 < thin / box < 2.0
    # the model as wide as the band, no flanks: the box's figure
    nc = nu[core]
    wide = np.full((nc.size, sv.size), 0.1)
    box_w = float(wide[:, sel].sum()) * step * step / (5.0 * noise_box5 * np.sqrt(nc.size * step * 130.0))
    line_w = _line_significance(wide, nc, np.ones(nc.size, bool), sv, 10.0, 140.0, step, 0.0, 15.0, 0.01,
                                noise_box5)
    assert line_w == pytest.approx(box_w, rel=0.03)


def test_a_long_thin_faint_scratch_is_found_by_its_lines_significance():
    """Station seed 994005: a 1.52 x 0.016 mm scratch crossing the hatch at 41 deg, plain
    to see, whose box integral over its core band reads 7.0 against the bar of 8 (the
    known limit of session 70): through its own cross profile it is found (its length
    reads short, 1.27 mm: its faint ends, docs/surface.md's known limits)."""
    f = random_defect_frame(994005)
    truth = max((t for t in f.defects if t.kind == "scratch"), key=lambda t: t.length_mm)
    assert truth.length_mm > 1.4 and truth.width_mm < 0.02
    found = detect_defects(f.image, 0.010)
    pairs, _ = match([truth], found, 0.010)
    d = pairs[0][1]
    assert d is not None and d.kind == "scratch"
    assert abs(d.length_mm - truth.length_mm) <= 0.2 * truth.length_mm
    assert d.significance >= DefectConfig().min_significance
