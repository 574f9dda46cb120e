"""Round 13 of the hole fit: the grooves' profiles read over a hole's wide neighbourhood
(``station.vision.grooves``) and the blur the frame's holes share (``measure._frame_blur``)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2 as chi2_dist

from sim.camera.render import FrameParams, HoleSpec, render_frame
from station.vision.grooves import frame_grooves
from station.vision.measure import MeasureConfig, _frame_blur, measure_holes
from station.vision.photometric import PhotometricFit


def _cross_hatch(w: int, h: int, seed: int, depth: float = 0.08, sigma: float = 1.5):
    """A flat wall of 160 DN with two families of Gaussian grooves at +/-30 deg (known
    places and depths), and the true relative field."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    rel = np.zeros((h, w))
    for a in np.deg2rad([30.0, -30.0]):
        u = -np.sin(a) * xx + np.cos(a) * yy
        for c in rng.uniform(u.min(), u.max(), int((u.max() - u.min()) / 12)):
            rel -= rng.uniform(0.3, 1.0) * depth * np.exp(-0.5 * ((u - c) / sigma) ** 2)
    return 160.0 * (1.0 + rel), rel


def test_the_profiles_recover_a_known_cross_hatch_around_a_masked_hole():
    clean, rel = _cross_hatch(640, 480, seed=3)
    img = clean + np.random.default_rng(4).normal(0.0, 3.0, clean.shape)
    yy, xx = np.mgrid[0:480, 0:640]
    hole = np.hypot(xx - 300.0, yy - 250.0) < 40
    img[hole] = 40.0  # a dark hole: masked, it must not bend the profiles
    img = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    fg = frame_grooves(img, [(300.0, 250.0, 40.0)], stride=2)
    assert fg is not None
    wall = ~hole & (np.hypot(xx - 300.0, yy - 250.0) < 90)  # the ring a hole's fit would read
    vals, _ = fg.values(xx[wall].astype(float), yy[wall].astype(float))
    model = sum(vals)
    truth = rel[wall] - rel[wall].mean()
    err = (model - model.mean()) - truth
    assert np.sqrt(np.mean(err**2)) < 0.15 * np.sqrt(np.mean(truth**2))
    # the level is the wall's, not the hole's
    assert fg.level_at(np.array([300]), np.array([250]))[0] == pytest.approx(160.0 * (1 + rel.mean()), rel=0.05)


def test_a_window_reads_the_same_lines_in_frame_coordinates():
    clean, _ = _cross_hatch(640, 480, seed=5)
    img = np.clip(np.rint(clean + np.random.default_rng(6).normal(0.0, 2.0, clean.shape)), 0, 255).astype(np.uint8)
    whole = frame_grooves(img, [], stride=2)
    part = frame_grooves(img, [], stride=2, window=(200, 150, 420, 360))
    assert part.origin == (200, 150) and part.shape == (210, 220) and part.level.shape == (480, 640)
    yy, xx = np.mgrid[200:310, 260:360]
    a = sum(whole.values(xx.ravel().astype(float), yy.ravel().astype(float))[0])
    b = sum(part.values(xx.ravel().astype(float), yy.ravel().astype(float))[0])
    assert np.corrcoef(a, b)[0, 1] > 0.95
    # too small a window, or a frame that is all hole: no profiles
    assert frame_grooves(img, [], window=(0, 0, 10, 10)) is None
    assert frame_grooves(img, [(320.0, 240.0, 900.0)]) is None


def _fit(blur: float, sd: float, u: float = float("nan")) -> PhotometricFit:
    return PhotometricFit(0.0, 0.0, 20.0, blur, 80.0, 2.0, 1000, 3, blur_sd=sd, blur_u=u)


def test_the_frame_blur_is_the_precision_weighted_mean_and_says_when_holes_disagree():
    fb = _frame_blur([_fit(1.20, 0.01), _fit(1.23, 0.03), None])
    assert fb.mean == pytest.approx((1.20 / 0.01**2 + 1.23 / 0.03**2) / (1 / 0.01**2 + 1 / 0.03**2))
    q = (1.20 - fb.mean) ** 2 / 0.01**2 + (1.23 - fb.mean) ** 2 / 0.03**2
    assert (fb.dof, fb.chi2) == (1, pytest.approx(q))
    assert fb.p_value == pytest.approx(chi2_dist.sf(q, 1))
    assert fb.p_value >= MeasureConfig().share_blur_alpha
    # two holes 3 sigma apart (a chance of 0.27 %; round 16's gate, 4 per degree of
    # freedom, kept each its own, worst-read, blur): they share. Six holes, one 4 sigma
    # from the others: shared too (p 2 % on 5 degrees of freedom)
    assert _frame_blur([_fit(1.20, 0.01), _fit(1.20 + 3 * np.sqrt(2) * 0.01, 0.01)]).p_value > 0.001
    assert _frame_blur([_fit(1.20, 0.01)] * 5 + [_fit(1.24, 0.01)]).p_value > 0.001
    # a lens whose blur changes across the field: the holes keep their own
    assert _frame_blur([_fit(1.0, 0.01), _fit(1.5, 0.01)]).p_value < MeasureConfig().share_blur_alpha
    assert _frame_blur([_fit(1.2, 0.01)]) is None
    assert _frame_blur([_fit(1.2, 0.01), _fit(1.2, float("nan"))]) is None
    # each hole weighed by its blur's correlated uncertainty when it has one (a grainy
    # hole's white figure understates its scatter), by the white figure when not
    fb = _frame_blur([_fit(1.20, 0.01, u=0.03), _fit(1.23, 0.01), _fit(1.26, 0.02, u=0.01)])
    w = np.array([1 / 0.03**2, 1 / 0.01**2, 1 / 0.01**2])
    assert fb.mean == pytest.approx(np.dot(w, [1.20, 1.23, 1.26]) / w.sum())
    assert fb.dof == 2


def test_holes_under_a_blur_that_changes_across_the_field_keep_their_own():
    """The left half of the frame at 1.0 px of blur, the right at 2.2 px (a lens whose
    focus changes across the field): the gate finds the holes' blurs disagree, and each
    hole keeps its own, as with sharing off. Forced to share (``share_blur_alpha`` 0),
    both diameters are tens of u off: what the gate is for."""
    p = dict(width_px=480, height_px=360, groove_depth=0.05, grain=0.03, blotch=0.0, gain_e_per_dn=30.0,
             read_noise_dn=1.0, vignetting=0.0, wall_level_dn=150, hole_level_dn=50)
    holes = [HoleSpec(130.4, 180.2, 60.0), HoleSpec(350.7, 170.3, 60.0)]
    image = render_frame(FrameParams(blur_sigma_px=1.0, **p), holes, seed=2).image
    image[:, 240:] = render_frame(FrameParams(blur_sigma_px=2.2, **p), holes, seed=2).image[:, 240:]

    def measured(**cfg):
        return sorted(measure_holes(image, cfg=MeasureConfig(**cfg)), key=lambda m: m.x_px)

    gated, own, forced = measured(), measured(share_blur=False), measured(share_blur_alpha=0.0)
    assert len(gated) == len(own) == len(forced) == 2
    assert [m.diameter_px for m in gated] == [m.diameter_px for m in own]
    for m in gated:
        assert abs(m.diameter_px - 60.0) < 3 * m.diameter_u_px
    for m in forced:
        assert abs(m.diameter_px - 60.0) > 10 * m.diameter_u_px


def test_sharing_the_blur_changes_nothing_for_a_frame_of_one_hole_and_moves_a_small_hole_of_two():
    p = FrameParams(width_px=480, height_px=360, groove_depth=0.05, grain=0.03, blotch=0.0, blur_sigma_px=1.6,
                    gain_e_per_dn=30.0, read_noise_dn=1.0, vignetting=0.0, wall_level_dn=150, hole_level_dn=50)
    one = render_frame(p, [HoleSpec(240.4, 180.2, 70.0)], seed=2).image
    a = measure_holes(one, cfg=MeasureConfig(share_blur=True))
    b = measure_holes(one, cfg=MeasureConfig(share_blur=False))
    assert [m.diameter_px for m in a] == [m.diameter_px for m in b]
    two = render_frame(p, [HoleSpec(150.4, 180.2, 90.0), HoleSpec(370.7, 170.3, 24.0)], seed=2).image
    shared = sorted(measure_holes(two, cfg=MeasureConfig(share_blur=True)), key=lambda m: m.diameter_px)
    own = sorted(measure_holes(two, cfg=MeasureConfig(share_blur=False)), key=lambda m: m.diameter_px)
    assert len(shared) == len(own) == 2
    assert shared[0].diameter_px != own[0].diameter_px  # the small hole took the frame's blur
    for m, d in zip(shared, (24.0, 90.0)):
        assert abs(m.diameter_px - d) < 4 * m.diameter_u_px


def _one_sided_groove_frame(depth: float = 0.15):
    """A honed wall (the renderer's cross-hatch and grain, no blotches) and one deep
    groove at +30 deg that fades under a hole: full where it leaves the rim on one side,
    a fifth of that on the other (a worn stone's stroke), blurred by the camera; and the
    grooves' true field as the camera shows it (DN about the wall's level)."""
    from scipy.ndimage import gaussian_filter

    from sim.camera.lens import ideal_pixel_grid
    from sim.camera.render import wall_radiance

    p = FrameParams(width_px=640, height_px=480, blotch=0.0, grain=0.02, vignetting=0.0,
                    blur_sigma_px=1.2, gain_e_per_dn=40.0, read_noise_dn=1.0, groove_depth=0.05)
    parts: dict = {}
    xu, yu = ideal_pixel_grid(None, p.width_px, p.height_px)
    wall = wall_radiance(np.random.default_rng(1), xu, yu, p, parts).astype(np.float64)  # as ``wall_patch``
    yy, xx = np.mgrid[0:480, 0:640].astype(np.float64)
    cx, cy, r = 320.3, 240.6, 30.0
    a = np.deg2rad(30.0)
    u = -np.sin(a) * (xx - cx) + np.cos(a) * (yy - cy)
    v = np.cos(a) * (xx - cx) + np.sin(a) * (yy - cy)
    groove = -depth * (0.6 + 0.4 * np.tanh(v / 6.0)) * np.exp(-0.5 * ((u - 12.0) / 1.5) ** 2)
    frame = render_frame(p, [HoleSpec(cx, cy, 2 * r)], seed=2, wall=(wall * (1.0 + groove)).astype(np.float32))
    return frame, (cx, cy, r), p.wall_level_dn * gaussian_filter(parts["grooves"] + groove, 1.2)


def test_the_rings_own_groove_profile_is_read_on_each_side_of_the_hole():
    """Round 19: the ring's local profile (on what the frame's profiles and the ring's
    linear depth leave) is one per side of the hole along the grooves, so a groove that
    fades along its length is modelled where it crosses the rim; one profile for both
    sides gives each crossing the mean of the two."""
    from dataclasses import replace

    from station.vision.photometric import PhotometricConfig, refine_hole

    frame, (cx, cy, r), truth = _one_sided_groove_frame()
    holes = [(cx, cy, 1.3 * r + 4.0)]
    fg = frame_grooves(frame.image, holes, (30.0, -30.0), window=(0, 0, 640, 480))
    assert fg is not None
    # the fit's pixels, as ``refine_hole`` chooses them (blur 1.2: s = sqrt(1.2^2 + 1/12))
    s = float(np.sqrt(1.2**2 + 1.0 / 12.0))
    errs = {}
    for sides in (1, 2):
        cfg = replace(PhotometricConfig(), groove_frame_local_sides=sides)
        cache: dict = {}
        fit = refine_hole(frame.image, cx, cy, r, s, cfg, frame_grooves=fg, cache=cache)
        assert fit is not None and fit.converged
        half = cfg.k_sigma * s + cfg.pad_px
        r_roi = max(r + half, r + 2.5 * s + 1.0 + cfg.groove_margin_px)
        x0, y0 = int(np.floor(cx - r_roi)), int(np.floor(cy - r_roi))
        x1, y1 = int(np.ceil(cx + r_roi)) + 1, int(np.ceil(cy + r_roi)) + 1
        yy, xx = np.mgrid[y0:y1, x0:x1]
        d = np.hypot(xx - cx, yy - cy).ravel()
        sel = d <= r + half
        field = cache["groove"][0]
        assert field.size == int(sel.sum())
        # the rim's wall side, where the grooves meet the edge
        rim = (d[sel] >= r) & (d[sel] <= r + half)
        # about its mean: the wall's level there is the fit's, the grooves' mean with it
        errs[sides] = float(np.std(field[rim] - truth[yy.ravel()[sel][rim], xx.ravel()[sel][rim]]))
    # one profile for both sides gives each crossing of the fading groove the mean of the
    # two (1.86 DN RMS over the rim against 1.49 DN per side, of a cross-hatch of 6.8 DN)
    assert errs[2] < 0.9 * errs[1], errs
