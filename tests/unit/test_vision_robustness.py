"""Detection under heavy honing texture: holes merged with dark grooves are split off by
the threshold ladder, and crossings of dark grooves are not taken for holes."""

from __future__ import annotations

import numpy as np
import pytest

from sim.camera.render import FrameParams, HoleSpec, random_frame, render_frame
from station.vision import measure_holes
from station.vision.detect import DetectConfig, detect_candidates
from station.vision.measure import MeasureConfig
from station.vision.photometric import refine_hole
from station.vision.scoring import Score, score_frame


def _hole_with_a_dark_band_touching_it() -> tuple[np.ndarray, HoleSpec]:
    """A 40 px hole of 30 % contrast and a 16 px band 22 % dark (a cluster of deep honing
    grooves: a single 1-3 px groove is removed by the coarse stage's opening) running
    from its rim across the frame.  On the 4x coarse frame the band is ~0.2 dark and the
    hole ~0.34: both pass the first threshold (0.15), and merged they fail the shape test."""
    p = FrameParams(width_px=480, height_px=320, groove_depth=0.0, grain=0.01, blotch=0.0, vignetting=0.0,
                    blur_sigma_px=1.2, wall_level_dn=150.0, hole_level_dn=150.0 * 0.70)
    hole = HoleSpec(240.3, 160.6, 40.0)
    img = render_frame(p, [hole], seed=2).image.astype(np.float64)
    img[154:170, 255:] *= 0.78
    return np.clip(np.rint(img), 0, 255).astype(np.uint8), hole


def test_a_hole_merged_with_a_dark_band_is_split_off_by_the_threshold_ladder():
    img, hole = _hole_with_a_dark_band_touching_it()

    def near(cands):
        return [c for c in cands if np.hypot(c.x_px - hole.x_px, c.y_px - hole.y_px) < 8 and not c.touches_border]

    # one step of 0.2 (the earlier split) overshoots the hole's own darkness: lost by the
    # ladder, and found again only by the search with the mask opened wide (below)
    assert len(near(detect_candidates(img, DetectConfig(split_step=0.2)))) == 1
    assert len(near(detect_candidates(img))) == 1
    # found and measured; the band darkens 16 px of the rim, which no model here knows,
    # and reads it ~0.2 px small and ~0.25 px off-centre
    (m,) = measure_holes(img)
    assert m.diameter_px == pytest.approx(hole.diameter_px, abs=0.5)
    assert np.hypot(m.x_px - hole.x_px, m.y_px - hole.y_px) < 0.5


def test_a_hole_touched_by_a_groove_darker_than_it_is_found():
    """A hole beside grooves as dark as it or darker: no level of the ladder parts them
    (above the grooves' darkness the hole is gone too), and the hole was lost. Wide clean
    frame 1097092 (22 deg hatch): a 0.79 mm hole of 33 % contrast, its coarse darkness
    0.26 beside 13 % grooves, whose piece read as a 0.47 mm pore; and a 40 px hole of 30 %
    contrast with a 12 px band 35 % dark running from its rim (at the ladder's last level
    with the hole, 0.30, the band alone is left and passes as a hole the border cuts).
    Each window that failed is searched again with the mask opened by a disc as wide as
    the smallest hole, which cuts the grooves off: both holes are found and measured."""
    from sim.camera.defects import random_defect_frame

    f = random_defect_frame(1097092, {}, mm_per_px=0.010, envelope="wide", hatch_deg=22.0)
    (truth,) = f.holes
    (m,) = [m for m in measure_holes(f.image, 0.010) if np.hypot(m.x_px - truth.x_px, m.y_px - truth.y_px) < 8]
    assert abs(m.diameter_px - truth.diameter_px) < 0.2
    assert np.hypot(m.x_px - truth.x_px, m.y_px - truth.y_px) < 0.2

    p = FrameParams(width_px=480, height_px=320, groove_depth=0.0, grain=0.01, blotch=0.0, vignetting=0.0,
                    blur_sigma_px=1.2, wall_level_dn=150.0, hole_level_dn=150.0 * 0.70)
    hole = HoleSpec(240.3, 160.6, 40.0)
    img = render_frame(p, [hole], seed=3).image.astype(np.float64)
    img[155:167, 255:] *= 0.65
    img = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    near = [c for c in detect_candidates(img) if np.hypot(c.x_px - hole.x_px, c.y_px - hole.y_px) < 8]
    assert len(near) == 1
    (m,) = [m for m in measure_holes(img) if np.hypot(m.x_px - hole.x_px, m.y_px - hole.y_px) < 8]
    # the band darkens 12 px of the rim, which no model here knows: ~0.4 px small
    assert m.diameter_px == pytest.approx(hole.diameter_px, abs=0.6)
    assert np.hypot(m.x_px - hole.x_px, m.y_px - hole.y_px) < 0.5


def test_crossings_of_dark_grooves_that_no_disc_fits_are_not_holes():
    """Wide-envelope frames (13-15 % grooves, 30-40 % holes) where a crossing of dark
    grooves passes the shape, ray and confidence tests: the blurred-disc model runs away
    from it, and the default drops it; every true hole is still found.  (On seed 3345
    round 13's fit converges on the crossing, at a radius of 8.8 px with a u of 1.6 px,
    and the confidence drops it even with the check off: two phantoms are left for it.)"""
    seeds = (3099, 3117, 3345)  # found by scanning wide seeds 3000-3399 with the check off
    off, on = Score(), Score()
    for seed in seeds:
        f = random_frame(seed, envelope="wide")
        truth = [(h.x_px, h.y_px, h.diameter_px, h.partial) for h in f.holes]
        for cfg, score in ((MeasureConfig(reject_unfitted_whole=False), off), (MeasureConfig(), on)):
            found = measure_holes(f.image, cfg=cfg)
            score.add(score_frame(truth, [(m.x_px, m.y_px, m.diameter_px, m.partial) for m in found]))
    assert off.phantoms >= 2
    assert on.phantoms == 0
    assert on.misses == off.misses == 0


def test_the_disc_fit_reports_a_run_away_instead_of_a_fit():
    """A fit that moves more than 2 px from the circle it was started on says so and
    returns that start (the caller drops such a whole candidate); started close enough,
    the same hole is fitted."""
    p = FrameParams(width_px=200, height_px=200, groove_depth=0.06, grain=0.03, blotch=0.0, vignetting=0.0,
                    blur_sigma_px=1.5)
    img = render_frame(p, [HoleSpec(100.2, 99.7, 32.0)], seed=5).image
    fit = refine_hole(img, 100.0, 100.0, 13.0, 1.5)
    assert fit is not None and not fit.converged
    assert (fit.cx, fit.cy, fit.r) == (100.0, 100.0, 13.0)
    fit = refine_hole(img, 100.0, 100.0, 15.5, 1.5)
    assert fit.converged and fit.r == pytest.approx(16.0, abs=0.05)


def test_the_roughest_walls_without_holes_give_no_phantoms():
    """Walls rougher than the station envelope (15 % grooves, strong grain and blotches,
    50 % vignetting, 5 e-/DN) and no hole at all: nothing is found.  Two of these frames
    give a phantom when whole candidates are kept whatever the disc fit does."""
    from sim.camera.render import random_params

    found, found_unchecked = 0, 0
    for i in range(24, 40):
        rng = np.random.default_rng(700 + i)
        p = random_params(rng, groove_depth=0.15, grain=0.05, blotch=0.06, vignetting=0.5, gain_e_per_dn=5.0)
        image = render_frame(p, [], seed=i).image
        found += len(measure_holes(image))
        found_unchecked += len(measure_holes(image, cfg=MeasureConfig(reject_unfitted_whole=False)))
    assert found == 0
    assert found_unchecked >= 2


def test_a_hole_cut_in_half_by_the_border_is_found_from_its_inward_centroid():
    """Station frame 1010: a 41 px hole centred 1.8 px above the frame.  Its coarse
    component's centroid lies 10 px inside the frame, nearer the rim's lowest point than
    half a radius, so a wide ray search starting at 0.5 r saw too little rim."""
    f = random_frame(1010)
    (cut,) = [h for h in f.holes if h.partial]
    truth = [(cut.x_px, cut.y_px, cut.diameter_px, True)]

    def score(cfg):
        found = measure_holes(f.image, cfg=cfg)
        return score_frame(truth, [(m.x_px, m.y_px, m.diameter_px, m.partial) for m in found])

    assert score(MeasureConfig(wide_inner_border=0.5)).partial_found == 0
    s = score(MeasureConfig())
    assert s.partial_found == 1 and s.partial_flag_errors == 0


def test_the_uncertainties_cover_the_errors_they_claim():
    """+/- 2 u (k = 2) holds about 95 % of whole-hole diameter and centre errors on fresh
    frames (seeds never used to set the factor), u tracks which holes are hard, and
    without the factor for the texture the white-noise theory would claim too much."""
    from station.vision.measure import MeasureConfig as Cfg

    err, u, err_c, u_c = [], [], [], []
    for seed in range(41000, 41100):
        f = random_frame(seed)
        found = measure_holes(f.image)
        for h in f.holes:
            if h.partial:
                continue
            (m,) = [m for m in found if np.hypot(m.x_px - h.x_px, m.y_px - h.y_px) < max(3, 0.25 * h.diameter_px)]
            assert m.diameter_u_px is not None and m.diameter_u_px > 0
            assert m.x_u_px is not None and m.x_u_px > 0 and m.y_u_px is not None and m.y_u_px > 0
            err.append(abs(m.diameter_px - h.diameter_px))
            u.append(m.diameter_u_px)
            err_c += [abs(m.x_px - h.x_px), abs(m.y_px - h.y_px)]
            u_c += [m.x_u_px, m.y_u_px]
    for e, uu in ((err, u), (err_c, u_c)):
        e, uu = np.array(e), np.array(uu)
        assert len(e) > 120
        assert 0.90 <= np.mean(e <= 2 * uu) <= 0.99
        assert np.mean(e <= 2 * uu / Cfg().uncertainty_factor) < 0.90  # the bare theory
        rank = np.corrcoef(np.argsort(np.argsort(e)), np.argsort(np.argsort(uu)))[0, 1]
        assert rank > 0.2
    # cut holes have no photometric fit and so no u; a scale gives u in mm too
    f = render_frame(FrameParams(width_px=320, height_px=256, vignetting=0.0),
                     [HoleSpec(160.2, 127.7, 40.0), HoleSpec(5.0, 60.0, 40.0)], seed=1)
    whole, cut = sorted(measure_holes(f.image, mm_per_px=0.01), key=lambda m: m.partial)
    assert cut.partial and cut.diameter_u_px is None and "diameter_u_px" not in cut.to_dict()
    assert cut.x_u_px is None and cut.y_u_px is None
    assert whole.diameter_u_mm == pytest.approx(whole.diameter_u_px * 0.01)


def test_a_hole_on_heavy_grooves_is_judged_by_its_fit_not_by_its_rays_scatter():
    """Wide seed 3220: a 76 px hole of 31 % contrast on 13 % grooves. Its rays scatter by
    ~0.5 px RMS, so a confidence from the rays alone drops it (< 0.15), while the
    photometric fit gives it a diameter u of ~0.11 px: judged by its own u it is kept,
    with a confidence that says it is no clean hole.  Its error is ~0.35 px, 3.2 u with
    round 13's fit (0.12 px, 0.9 u with round 12's): one of the wide envelope's tails,
    where the fit is better on the whole (docs/vision-history.md, round 13); a u of the
    right size keeps one hole within 4 u."""
    f = random_frame(3220, envelope="wide")
    (big,) = [h for h in f.holes if not h.partial and h.diameter_px > 70]

    def near(found):
        return [m for m in found if np.hypot(m.x_px - big.x_px, m.y_px - big.y_px) < 2]

    assert near(measure_holes(f.image, cfg=MeasureConfig(confidence_u_ref_px=None))) == []
    (m,) = near(measure_holes(f.image))
    assert m.fit_rms_px > 0.4  # the rays' scatter, which alone would score ~0.12
    assert 0.15 <= m.confidence < 0.5
    assert abs(m.diameter_px - big.diameter_px) < 4 * m.diameter_u_px
