"""``station bench vision``: accuracy and speed of hole measurement against two baselines.

The same rendered frames (``sim.camera.render.random_frame``: honed texture, 0.8-2 px
blur, shot + read noise, 40-85 % hole contrast, vignetting, whole holes 20-100 px,
holes cut by the border, frames without holes) go through:

* ours: ``station.vision.measure_holes``;
* OpenCV ``HoughCircles`` with ``HOUGH_GRADIENT_ALT`` (sub-pixel-capable variant);
* threshold + ``findContours`` + ``fitEllipse``.

Errors are measured on whole holes only; phantoms are detections matching no hole,
misses are whole holes not found.  Time is the median per 1280x1024 frame on one core
(``cv2.setNumThreads(1)``), wall clock and process CPU time.  The benchmark needs the
renderer, so it imports ``sim`` (the CLI is allowed to; the measuring code never does).
"""

from __future__ import annotations

import statistics
import time

import cv2
import numpy as np
import typer

from station.bench.psf import PSF_DISC, PSF_SMEAR, PSF_SMEAR_DEG, psf_overrides, psf_title
from station.vision.scoring import Score, ratio_of_medians_ci, score_frame

#: the smallest and largest hole radius the baselines look for (holes are 20-100 px)
MIN_RADIUS_PX, MAX_RADIUS_PX = 8, 60


def hough_alt(image: np.ndarray) -> list[tuple]:
    """HOUGH_GRADIENT_ALT on a lightly smoothed frame.

    param1 (Canny high threshold) 200 and param2 (circle "perfectness") 0.8 were
    chosen on frames outside the benchmark's seeds: lower values add phantoms on the
    honing texture without improving accuracy; dp = 1 is its most precise resolution.
    """
    blurred = cv2.GaussianBlur(image, (0, 0), 1.5)
    c = cv2.HoughCircles(blurred, cv2.HOUGH_GRADIENT_ALT, dp=1.0, minDist=20, param1=200, param2=0.8,
                         minRadius=MIN_RADIUS_PX, maxRadius=MAX_RADIUS_PX)
    if c is None:
        return []
    h, w = image.shape
    return [(x, y, 2 * r, x - r < 0 or y - r < 0 or x + r > w - 1 or y + r > h - 1) for x, y, r in c.reshape(-1, 3)]


def contour_ellipse(image: np.ndarray) -> list[tuple]:
    """Local threshold + external contours + fitEllipse, with the usual filters.

    The adaptive threshold (block 151 px, larger than a hole; offset 15 DN, above the
    texture) copes with vignetting; contour points are the centres of the region's
    boundary pixels, half a pixel inside its edge, so 1 px is added to the diameter.
    """
    blurred = cv2.GaussianBlur(image, (0, 0), 1.5)
    mask = cv2.adaptiveThreshold(blurred, 255, cv2.ADAPTIVE_THRESH_MEAN_C, cv2.THRESH_BINARY_INV, 151, 15)
    mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5)))
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    h, w = image.shape
    out = []
    for c in contours:
        area = cv2.contourArea(c)
        if not (np.pi * MIN_RADIUS_PX**2 <= area <= np.pi * MAX_RADIUS_PX**2) or len(c) < 10:
            continue
        perimeter = cv2.arcLength(c, True)
        if 4 * np.pi * area / perimeter**2 < 0.7:  # circularity of a disc is 1
            continue
        (x, y), (d1, d2), _ = cv2.fitEllipse(c)
        bx, by, bw, bh = cv2.boundingRect(c)
        cut = bx == 0 or by == 0 or bx + bw >= w or by + bh >= h
        out.append((x, y, (d1 + d2) / 2 + 1.0, cut))
    return out


def ours(image: np.ndarray, photometric: bool = True) -> list[tuple]:
    from station.vision.measure import MeasureConfig, measure_holes

    # the default pipeline refines whole holes' diameters photometrically; without it,
    # the rays' diameter only (the pipeline of earlier rounds)
    cfg = MeasureConfig() if photometric else MeasureConfig(photometric=None)
    return [(m.x_px, m.y_px, m.diameter_px, m.partial, m.diameter_u_px, m.x_u_px, m.y_u_px)
            for m in measure_holes(image, cfg=cfg)]


METHODS = {"ours": ours, "hough_gradient_alt": hough_alt, "contours_fit_ellipse": contour_ellipse}
SHORT = {"ours": "ours", "hough_gradient_alt": "Hough ALT", "contours_fit_ellipse": "fitEllipse"}


def run(frames: int = 400, seed: int = 1000, envelope: str = "station", photometric: bool = True,
        progress=None, psf: dict | None = None) -> dict:
    """``progress(n)``: called after each rendered frame and each measured frame (of the
    3 methods), ``4 * frames`` calls in all. ``psf``: the renderer's fields for a lens
    spread beyond the Gaussian (``station.bench.defects.psf_overrides``; None: none)."""
    from sim.camera.render import random_frame  # the CLI side may import sim

    cv2.setNumThreads(1)
    tick = progress or (lambda: None)
    rendered = []
    for i in range(frames):
        rendered.append(random_frame(seed + i, envelope=envelope, **(psf or {})))
        tick()
    results, per_frame = {}, {}
    methods = {**METHODS, "ours": ours if photometric else (lambda im: ours(im, photometric=False))}
    for name, fn in methods.items():
        fn(rendered[0].image)  # warm-up (imports, allocations)
        total, times, cpu, frames_scored = Score(), [], [], []
        for f in rendered:
            c0, t0 = time.process_time(), time.perf_counter()
            det = fn(f.image)
            times.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
            tick()
            truths = [(h.x_px, h.y_px, h.diameter_px, h.partial) for h in f.holes]
            score = score_frame(truths, det, check_partial=True)
            frames_scored.append(score)
            total.add(score)
        per_frame[name] = frames_scored
        # wall-clock is what the station sees; CPU time (the process's, all threads) is
        # the like-for-like figure on a shared machine, where other work stretches the
        # wall clock but not the CPU time, and shows whether anything ran multi-threaded
        results[name] = {**total.summary(), "median_ms_per_frame": 1000 * statistics.median(times),
                         "median_cpu_ms_per_frame": 1000 * statistics.median(cpu)}
    o = results["ours"]
    # the better baseline per quantity, and how far this frame set's ratio can be trusted
    baselines = [k for k in METHODS if k != "ours"]
    better_c = min(baselines, key=lambda k: results[k]["median_centre_err_px"] or np.inf)
    better_d = min(baselines, key=lambda k: results[k]["median_diameter_err_px"] or np.inf)
    best_c = results[better_c]["median_centre_err_px"] or np.inf
    best_d = results[better_d]["median_diameter_err_px"] or np.inf
    ci_c = ratio_of_medians_ci([s.centre_err_px for s in per_frame[better_c]],
                               [s.centre_err_px for s in per_frame["ours"]])
    ci_d = ratio_of_medians_ci([s.diameter_err_px for s in per_frame[better_d]],
                               [s.diameter_err_px for s in per_frame["ours"]])
    # the same comparison by the tails: the headline ratio is of medians, and a method
    # whose errors spread wider on hard holes gains less at the 90th percentile or in RMS
    by_stat = {q: {"centre": (results[better_c][f"{q}_centre_err_px"] or np.inf) / o[f"{q}_centre_err_px"],
                   "diameter": (results[better_d][f"{q}_diameter_err_px"] or np.inf) / o[f"{q}_diameter_err_px"]}
               for q in ("median", "p90", "rms")}
    whole = sum(1 for f in rendered for h in f.holes if not h.partial)
    cut = sum(1 for f in rendered for h in f.holes if h.partial)
    return {
        "frames": frames,
        "seed": seed,
        "envelope": envelope,
        "photometric": photometric,
        "psf": psf or {},
        "frame_size_px": [rendered[0].image.shape[1], rendered[0].image.shape[0]],
        "whole_holes": whole,
        "partial_holes": cut,
        "empty_frames": sum(1 for f in rendered if not f.holes),
        "methods": results,
        "centre_accuracy_ratio_vs_better_baseline": best_c / o["median_centre_err_px"],
        "diameter_accuracy_ratio_vs_better_baseline": best_d / o["median_diameter_err_px"],
        "better_baseline": {"centre": better_c, "diameter": better_d},
        # 95 % bootstrap interval over frames (the holes of a frame share its condition)
        "centre_accuracy_ratio_ci95": list(ci_c),
        "diameter_accuracy_ratio_ci95": list(ci_d),
        "accuracy_ratios_by_statistic": by_stat,
        # issue 23 withdrew the 5x ratio and the worst-case bars: the holes are judged
        # against the frame-aware Cramer-Rao bound (``station bench vision-bound
        # --estimator``); the ratios stay here as secondary figures
        "goals": {"median_err_px": 0.05, "ms_per_frame": 10.0},
        "withdrawn_goals": {"worst_centre_err_px": 0.1, "worst_diameter_err_px": 0.15, "ratio": 5.0},
    }


def fmt_cell(v, digits=3):
    """A table cell of a bench report: "-" for no value, floats to ``digits`` places."""
    return "-" if v is None else (f"{v:.{digits}f}" if isinstance(v, float) else str(v))


def register(bench_app: typer.Typer) -> None:
    @bench_app.command("vision")
    def vision(
        frames: int = typer.Option(400, "--frames", min=1,
                                   help="rendered 1280x1024 frames (400: ~600 whole holes, a ratio known to "
                                        "about +/-10 %; 40 for a quick look)"),
        seed: int = typer.Option(1000, "--seed"),
        envelope: str = typer.Option("station", "--envelope", help="station (default) or wide (stress test)"),
        rays_only: bool = typer.Option(False, "--rays-only",
                                       help="ours without the photometric diameter refinement (on by default)"),
        psf_disc_px: float = PSF_DISC,
        psf_smear_px: float = PSF_SMEAR,
        psf_smear_deg: float = PSF_SMEAR_DEG,
        as_json: bool = typer.Option(False, "--json", help="one JSON object on stdout"),
    ) -> None:
        """Hole measurement: ours vs HoughCircles(ALT) vs contours+fitEllipse."""
        from rich.table import Table

        from rich.progress import Progress

        from station.cli.common import out_console, print_json

        with Progress(console=out_console, transient=True, disable=as_json) as bar:
            task = bar.add_task("rendering, then measuring with 3 methods", total=4 * frames)
            r = run(frames, seed, envelope, photometric=not rays_only, progress=lambda: bar.advance(task),
                    psf=psf_overrides(psf_disc_px, psf_smear_px, psf_smear_deg))
        if as_json:
            print_json(r)
            return
        t = Table(title=f"vision: {r['frames']} frames, {r['whole_holes']} whole + {r['partial_holes']} cut holes, "
                        f"{r['empty_frames']} empty frames{psf_title(r['psf'])} (one core)")
        cols = ("method", "c med", "c worst", "d med", "d worst", "phantom", "miss", "flag err", "ms", "cpu ms")
        for c in cols:
            t.add_column(c, justify="right")
        for name, m in r["methods"].items():
            t.add_row(SHORT[name], fmt_cell(m["median_centre_err_px"]), fmt_cell(m["worst_centre_err_px"]),
                      fmt_cell(m["median_diameter_err_px"]), fmt_cell(m["worst_diameter_err_px"]),
                      fmt_cell(m["phantoms"]), fmt_cell(m["misses"]), fmt_cell(m["partial_flag_errors"]), fmt_cell(m["median_ms_per_frame"], 1),
                      fmt_cell(m["median_cpu_ms_per_frame"], 1))
        out_console.print(t)
        out_console.print("c = centre error, d = diameter error (px, whole holes); ms = median per frame "
                          "(wall clock; cpu = process CPU time), cv2.setNumThreads(1)")
        ci_c, ci_d = r["centre_accuracy_ratio_ci95"], r["diameter_accuracy_ratio_ci95"]
        out_console.print(
            f"ours vs the better baseline: centre {r['centre_accuracy_ratio_vs_better_baseline']:.1f}x "
            f"(95 % interval {ci_c[0]:.1f}-{ci_c[1]:.1f}x), diameter "
            f"{r['diameter_accuracy_ratio_vs_better_baseline']:.2f}x ({ci_d[0]:.2f}-{ci_d[1]:.2f}x) more accurate "
            f"(secondary figures since issue 23; 95 % bootstrap intervals over the frames)"
        )
        tails = r["accuracy_ratios_by_statistic"]
        out_console.print(
            f"the same by the tails: diameter {tails['p90']['diameter']:.2f}x at the 90th percentile, "
            f"{tails['rms']['diameter']:.2f}x in RMS; centre {tails['p90']['centre']:.1f}x / "
            f"{tails['rms']['centre']:.1f}x"
        )
        out_console.print("issue 23's criteria (error over the frame-aware Cramer-Rao bound, coverage of u): "
                          "station bench vision-bound --estimator")
        o = r["methods"]["ours"]
        if o.get("holes_with_u"):
            out_console.print(
                f"ours' own uncertainties (k = 2) hold {o['diameter_within_2u']:.1%} of the diameter errors and "
                f"{o['centre_within_2u']:.1%} of the centre coordinates' ({o['holes_with_u']} whole holes; ~95 % "
                f"if they are right)"
            )
