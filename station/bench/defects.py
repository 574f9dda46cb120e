"""``station bench defects``: surface defects found and measured on rendered frames (issue 23).

Frames with seeded defects (``sim.camera.defects.random_defect_frame``: the vision
bench's envelope of walls, 0-2 compensating holes of 0.6-1.0 mm, 0-2 pores, scratches,
burrs and chips each) and as many clean frames (the same walls and holes, no defect) go
through ``station.vision.defects.detect_defects``. The figures are the issue's
acceptance: recall of the defects above the spec's limit size, per kind; false defects
per 100 clean frames; size errors (length and width: median, 90th percentile, the share
within 10 % or 0.02 mm, the share within the stated 2 u); and CPU ms per frame on one
core. The benchmark needs the renderer, so it imports ``sim`` (the CLI is allowed to;
the measuring code never does).

The limits (mm). The part spec names no surface criteria yet (part B adds them); the
issue's example is "no pore over 0.2 mm in the sealing zones" and "no burr at a
compensating hole". So: pores and scratches 0.2 mm long; burrs and chips at least
0.05 mm along the rim and 0.02 mm high (deep), the smallest a 10 um/px camera resolves
from a rim whose edge wanders by ~0.003 mm where grooves cross it (docs/surface.md).
Smaller defects are found too, and counted apart.

The twin's long scratches. The random frames hold scratches of 0.1-2 mm anywhere in
0-2 holes' frames, under the bench's envelope (grooves 3-8 % deep, 20-60 e-/DN, no lens
distortion): few long scratches in frames without a hole, and none under the camera
twin's own optics (``sim.camera.twin.CameraOptics``: grooves 10 % deep, 10 e-/DN, the
endoscope's lens), which the whole-surface scan re-centres each defect in. There the
scan found long scratches' ends lost or carried on and their widths a third of the
truth. So the bench also renders ``twin_frames`` such frames, each with one scratch of
1.1-2 mm near the centre and no hole (``twin_scratch_frame``), and reports their
lengths, widths and places (within 0.05 mm, the issue's bar for a defect's place);
and, of the random frames, the scratches of 1 mm and more in frames without a hole.
"""

from __future__ import annotations

import statistics
import time
from collections import defaultdict
from typing import Optional

import numpy as np
import typer

from station.bench.psf import PSF_DISC, PSF_SMEAR, PSF_SMEAR_DEG, psf_overrides, psf_title
from station.bench.vision import fmt_cell

#: (length, width) limits per kind, mm: recall is judged on the defects at or above both
LIMITS_MM = {"pore": (0.2, 0.0), "scratch": (0.2, 0.0), "burr": (0.05, 0.02), "chip": (0.05, 0.02)}

#: a size is right within 10 % or 0.02 mm, whichever is larger (issue 23)
SIZE_TOL_REL, SIZE_TOL_MM = 0.10, 0.02
KINDS = ("pore", "scratch", "burr", "chip")
#: a defect's place on the part is right within this (issue 23; ``station.bench.surface``)
PLACE_TOL_MM = 0.05
#: the twin frames' scratches (mm): long, as the whole-surface scan met them; the width
#: as the random frames draw it, at most a fifth of the length
TWIN_SCRATCH_MM = dict(length=(1.1, 2.0), width=(0.015, 0.06))
#: ... placed this far from the frame's centre at most (mm, each way): the surface scan
#: measures a defect in a frame centred on it
TWIN_OFFSET_MM = 1.0
#: a scratch this long (mm) in a frame without a hole is reported apart in the random frames
LONG_SCRATCH_MM = 1.0
#: the scale the twin's wall texture is drawn for (``--texture-in-mm`` scales it from here)
STATION_MM_PER_PX = 0.010


def above_limit(kind: str, length_mm: float, width_mm: float) -> bool:
    """A defect of this size is at or above its kind's limit (``LIMITS_MM``): recall is judged there."""
    lim_l, lim_w = LIMITS_MM[kind]
    return length_mm >= lim_l and width_mm >= lim_w


def match(truths, found, mm_per_px: float) -> tuple[list[tuple], list[int]]:
    """Pair each true defect with the nearest unclaimed detection whose centre lies
    within half its length (at least 0.06 mm): (truth, detection or None) pairs, and the
    indices of the detections no truth claimed (false defects). Nearest first, so two
    defects side by side do not swap."""
    pairs, used = [], set()
    cand = []
    for ti, t in enumerate(truths):
        for di, d in enumerate(found):
            dist = float(np.hypot(d.x_px - t.x_px, d.y_px - t.y_px))
            if dist < max(0.06 / mm_per_px, 0.5 * t.length_px):
                cand.append((dist, ti, di))
    taken: dict[int, int] = {}
    for dist, ti, di in sorted(cand):
        if ti in taken or di in used:
            continue
        taken[ti] = di
        used.add(di)
    for ti, t in enumerate(truths):
        pairs.append((t, found[taken[ti]] if ti in taken else None))
    return pairs, [di for di in range(len(found)) if di not in used]


def _within(err_mm: float, truth_mm: float) -> bool:
    return abs(err_mm) <= max(SIZE_TOL_REL * truth_mm, SIZE_TOL_MM)


def _sizes(rows: list[tuple]) -> dict:
    """Size errors (mm) of matched defects of the right kind: rows of (truth, detection)."""
    out = {}
    for dim in ("length", "width"):
        err = np.array([getattr(d, f"{dim}_mm") - getattr(t, f"{dim}_mm") for t, d in rows])
        u = np.array([(d.size_u_mm if dim == "length" else d.width_u_mm) for t, d in rows])
        ok = [_within(e, getattr(t, f"{dim}_mm")) for e, (t, _) in zip(err, rows)]
        out[dim] = {
            "n": len(rows),
            "median_abs_err_mm": float(np.median(np.abs(err))) if rows else None,
            "p90_abs_err_mm": float(np.percentile(np.abs(err), 90)) if rows else None,
            "mean_err_mm": float(np.mean(err)) if rows else None,
            "within_tol": float(np.mean(ok)) if rows else None,
            "within_2u": float(np.mean(np.abs(err) <= 2 * u)) if rows else None,
        }
    return out


def twin_scratch_frame(seed: int, mm_per_px: float = 0.010):
    """A frame as the camera twin renders it (``CameraOptics().params``: the endoscope's
    lens, blur 1.2 px, grooves 10 % deep, grain 3 %, 10 e-/DN; the renderer the twin's
    process runs, ``render_frame`` over a wall patch), no hole, and one scratch of
    ``TWIN_SCRATCH_MM`` near the centre, crossing the hatch by at least 10 deg, of the
    scenario's default reflectance (a ``SurfaceDefect`` names none). The frame (its
    ``defects`` in mm)."""
    from sim.camera.defects import SCRATCH_MIN_ELONGATION, DefectSpec, random_scratch_angle
    from sim.camera.render import render_frame, wall_patch
    from sim.camera.twin import CameraOptics

    rng = np.random.default_rng(seed)
    p = CameraOptics().params
    length = rng.uniform(*TWIN_SCRATCH_MM["length"]) / mm_per_px
    width = min(rng.uniform(*TWIN_SCRATCH_MM["width"]) / mm_per_px, length / SCRATCH_MIN_ELONGATION)
    # the twin renders a wall direction mirrored (image y runs against the axis): the
    # hatch is symmetric, so a direction drawn clear of it stays clear
    angle = -random_scratch_angle(rng)
    off = TWIN_OFFSET_MM / mm_per_px
    x = (p.width_px - 1) / 2.0 + rng.uniform(-off, off)
    y = (p.height_px - 1) / 2.0 + rng.uniform(-off, off)
    spec = DefectSpec("scratch", float(x), float(y), float(length), float(width), float(angle), None, None,
                      int(rng.integers(2**31)))
    wall = wall_patch(p, int(rng.integers(2**31)))
    f = render_frame(p, [], seed=int(rng.integers(2**31)), wall=wall, defects=[spec])
    f.defects = [d.with_scale(mm_per_px) for d in f.defects]
    return f


def _twin_scratches(frames: int, seed: int, mm_per_px: float, tick) -> dict:
    """``twin_scratch_frame`` on ``frames`` seeds from ``seed``: each scratch found as a
    scratch, its length, width and place (the centroid where the lens put it) against
    the tolerances, and any other detection (false)."""
    import time

    from station.vision.defects import detect_defects

    rows, false, cpu = [], [], []
    for i in range(frames):
        f = twin_scratch_frame(seed + i, mm_per_px)
        c0 = time.process_time()
        found = detect_defects(f.image, mm_per_px)
        cpu.append(1000.0 * (time.process_time() - c0))
        t = f.defects[0]
        pairs, extra = match([t], found, mm_per_px)
        false.extend((seed + i, found[k]) for k in extra)
        d = pairs[0][1]
        if d is None or d.kind != "scratch":
            rows.append((t, None, None))
        else:
            place = float(np.hypot(d.x_px - t.image_x_px, d.y_px - t.image_y_px)) * mm_per_px
            rows.append((t, d, place))
        tick()
    right = [(t, d) for t, d, _ in rows if d is not None]
    places = np.array([p for _, d, p in rows if d is not None])
    return {
        "frames": frames,
        "seed": seed,
        "found": len(right),
        "sizes": _sizes(right),
        "place_within_tol": float(np.mean(places <= PLACE_TOL_MM)) if right else None,
        "place_median_mm": float(np.median(places)) if right else None,
        "place_max_mm": float(np.max(places)) if right else None,
        "false": [dict(seed=s, kind=d.kind, x_px=round(d.x_px, 1), y_px=round(d.y_px, 1),
                       length_mm=round(d.length_mm, 4), significance=round(d.significance, 1)) for s, d in false],
        "misses": [dict(seed=seed + i, length_mm=round(t.length_mm, 4), width_mm=round(t.width_mm, 4))
                   for i, (t, d, _) in enumerate(rows) if d is None],
        # the frames to look at: a scratch found off its place or outside the size tolerance
        "outside_tol": [dict(seed=seed + i, length_mm=round(t.length_mm, 4), found_length_mm=round(d.length_mm, 4),
                             width_mm=round(t.width_mm, 4), found_width_mm=round(d.width_mm, 4),
                             place_mm=round(p, 4))
                        for i, (t, d, p) in enumerate(rows) if d is not None
                        and (p > PLACE_TOL_MM or not _within(d.length_mm - t.length_mm, t.length_mm)
                             or not _within(d.width_mm - t.width_mm, t.width_mm))],
        "median_cpu_ms_per_frame": statistics.median(cpu) if cpu else None,
    }


def run(frames: int = 100, seed: int = 50000, envelope: str = "station", mm_per_px: float = 0.010,
        progress=None, twin_frames: int = 0, hatch_deg: float | None = None, texture_in_mm: bool = False,
        scratch_clearance_deg: float | None = None, scratch_within_deg: float | None = None,
        groove_breaks: float = 0.0, psf_disc_px: float = 0.0, psf_smear_px: float = 0.0,
        psf_smear_deg: float = 0.0, pores_on_scratches: float = 0.0) -> dict:
    """``frames`` frames with defects and ``frames`` clean ones, and ``twin_frames``
    frames of the camera twin with a long scratch (``twin_scratch_frame``, seeds from
    ``seed + 2,000,000``); ``progress()`` after each. ``hatch_deg``: the cross-hatch's
    half-angle (None: the renderer's 30 deg); ``texture_in_mm``: the wall's texture
    drawn at the frames' scale (grooves, grain and blotches as large in mm as at the
    station's 0.010 mm/px), not in px. ``scratch_clearance_deg``: how far the random
    scratches keep from the hatch's directions (None: the renderer's 10 deg; 0: any
    direction, along the grooves too); ``scratch_within_deg``: instead, every random
    scratch at most that far from a groove family (scratches along the hatch).
    ``groove_breaks``: the share of the grooves' length missing (a honing whose grooves
    stop short, with cut ends; 0: they run on). ``psf_disc_px``, ``psf_smear_px``,
    ``psf_smear_deg``: the lens's spread beyond the Gaussian (``psf_overrides``); the
    twin's long-scratch frames keep the camera twin's own optics. ``pores_on_scratches``:
    the chance that a pore of a frame with a scratch lies on the scratch's line
    (``random_defects``; 0: every defect clear of the others)."""
    import cv2

    from sim.camera.defects import HONING_CLEARANCE_DEG, random_defect_frame  # the CLI side may import sim
    from sim.camera.render import HONING_ANGLE_DEG
    from station.vision.defects import detect_defects
    from station.vision.measure import warm_up

    cv2.setNumThreads(1)
    tick = progress or (lambda: None)
    wall = {}
    if hatch_deg is not None:
        wall["hatch_deg"] = float(hatch_deg)
    if texture_in_mm:
        wall["texture_scale"] = STATION_MM_PER_PX / mm_per_px
    if groove_breaks:
        wall["groove_breaks"] = float(groove_breaks)
    wall |= psf_overrides(psf_disc_px, psf_smear_px, psf_smear_deg)
    clearance = HONING_CLEARANCE_DEG if scratch_clearance_deg is None else float(scratch_clearance_deg)
    warm_up()
    per_kind: dict[str, list[tuple]] = defaultdict(list)
    long_no_hole: list[tuple] = []
    false_clean, false_defect = [], []
    misses = []  # the frames to look at: a defect above its kind's limit not found as that kind
    cpu_ms, n_holes = [], 0
    for clean in (False, True):
        for i in range(frames):
            # clean frames from their own seeds: other walls than the defect frames'
            s = seed + i + (1_000_000 if clean else 0)
            f = random_defect_frame(s, {} if clean else None, mm_per_px=mm_per_px, envelope=envelope,
                                    scratch_clearance_deg=clearance, scratch_within_deg=scratch_within_deg,
                                    pores_on_scratches=pores_on_scratches, **wall)
            n_holes += len(f.holes)
            c0 = time.process_time()
            found = detect_defects(f.image, mm_per_px)
            cpu_ms.append(1000.0 * (time.process_time() - c0))
            pairs, false = match(f.defects, found, mm_per_px)
            for t, d in pairs:
                per_kind[t.kind].append((t, d))
                if above_limit(t.kind, t.length_mm, t.width_mm) and (d is None or d.kind != t.kind):
                    misses.append(dict(seed=s, kind=t.kind, length_mm=round(t.length_mm, 4),
                                       width_mm=round(t.width_mm, 4), x_px=round(t.image_x_px, 1),
                                       y_px=round(t.image_y_px, 1), found_as=None if d is None else d.kind))
                if t.kind == "scratch" and not f.holes and t.length_mm >= LONG_SCRATCH_MM:
                    long_no_hole.append((t, d))
            (false_clean if clean else false_defect).extend((s, found[k]) for k in false)
            tick()
    kinds = {}
    for kind in KINDS:
        rows = per_kind.get(kind, [])
        lo_len, lo_wid = LIMITS_MM[kind]
        above = [(t, d) for t, d in rows if above_limit(kind, t.length_mm, t.width_mm)]
        right = [(t, d) for t, d in rows if d is not None and d.kind == kind]
        kinds[kind] = {
            "seeded": len(rows),
            "found": len(right),
            "found_other_kind": sum(1 for _, d in rows if d is not None and d.kind != kind),
            "limit_mm": {"length": lo_len, "width": lo_wid},
            "above_limit": len(above),
            "above_limit_found": sum(1 for _, d in above if d is not None and d.kind == kind),
            "recall_above_limit": (sum(1 for _, d in above if d is not None and d.kind == kind) / len(above)
                                   if above else None),
            "below_limit": len(rows) - len(above),
            "recall_below_limit": (sum(1 for t, d in rows if not above_limit(kind, t.length_mm, t.width_mm)
                                       and d is not None and d.kind == kind) / (len(rows) - len(above))
                                   if len(rows) > len(above) else None),
            "sizes": _sizes(right),
        }
    all_right = [(t, d) for rows in per_kind.values() for t, d in rows if d is not None and d.kind == t.kind]
    sizes_all = _sizes(all_right)
    long_right = [(t, d) for t, d in long_no_hole if d is not None and d.kind == "scratch"]
    twin = _twin_scratches(twin_frames, seed + 2_000_000, mm_per_px, tick) if twin_frames else None
    return {
        "frames_with_defects": frames,
        "clean_frames": frames,
        "seed": seed,
        "envelope": envelope,
        "mm_per_px": mm_per_px,
        "hatch_deg": hatch_deg if hatch_deg is not None else HONING_ANGLE_DEG,
        "texture": "mm" if texture_in_mm else "px",
        "scratch_clearance_deg": clearance,
        "scratch_within_deg": scratch_within_deg,
        "groove_breaks": groove_breaks,
        "pores_on_scratches": pores_on_scratches,
        "psf": psf_overrides(psf_disc_px, psf_smear_px, psf_smear_deg),
        "holes": n_holes,
        "kinds": kinds,
        "false_per_100_clean_frames": 100.0 * len(false_clean) / frames,
        "false_per_100_defect_frames": 100.0 * len(false_defect) / frames,
        "false_clean": [dict(seed=s, kind=d.kind, x_px=round(d.x_px, 1), y_px=round(d.y_px, 1),
                             length_mm=round(d.length_mm, 4), significance=round(d.significance, 1))
                        for s, d in false_clean],
        "false_defect_frames": [dict(seed=s, kind=d.kind, x_px=round(d.x_px, 1), y_px=round(d.y_px, 1),
                                     length_mm=round(d.length_mm, 4), significance=round(d.significance, 1))
                                for s, d in false_defect],
        "misses_above_limit": misses,
        "sizes_all": sizes_all,
        "long_scratches_without_hole": {"min_length_mm": LONG_SCRATCH_MM, "seeded": len(long_no_hole),
                                        "found": len(long_right), "sizes": _sizes(long_right)},
        "twin_long_scratches": twin,
        "median_cpu_ms_per_frame": statistics.median(cpu_ms),
        "p90_cpu_ms_per_frame": float(np.percentile(cpu_ms, 90)),
        "acceptance": {"recall_above_limit": 0.95, "false_per_100_clean_frames": 1.0,
                       "size_tolerance": f"{SIZE_TOL_REL:.0%} or {SIZE_TOL_MM} mm"},
    }


def register(bench_app: typer.Typer) -> None:
    @bench_app.command("defects")
    def defects(
        frames: int = typer.Option(100, "--frames", min=1,
                                   help="frames with seeded defects, and as many clean ones (1280x1024; 100: ~400 "
                                        "defects, about a minute)"),
        seed: int = typer.Option(50000, "--seed", help="first seed (the detector was tuned on 7000-7349)"),
        envelope: str = typer.Option("station", "--envelope", help="station (default) or wide (stress test)"),
        twin_frames: int = typer.Option(50, "--twin-frames", min=0,
                                        help="frames of the camera twin's optics with one 1.1-2 mm scratch and no "
                                             "hole (0: none; 50: ~30 s)"),
        mm_per_px: float = typer.Option(0.010, "--mm-per-px", min=0.002, max=0.05,
                                        help="the frames' scale at the wall (the station's camera: 0.010); defects' "
                                             "and holes' sizes are drawn in mm, the wall's texture in px unless "
                                             "--texture-in-mm"),
        hatch_deg: Optional[float] = typer.Option(None, "--hatch-deg", min=6.0, max=84.0,
                                                  help="the honing cross-hatch's half-angle (plateau honing: 20-35 deg, "
                                                       "helical slide honing: 60-75; read from 6 to 84; default: the "
                                                       "renderer's nominal 30)"),
        texture_in_mm: bool = typer.Option(False, "--texture-in-mm",
                                           help="draw the wall's grooves, grain and blotches at the frames' scale (as "
                                                "a finer or coarser camera sees them), not in px"),
        scratch_clearance_deg: Optional[float] = typer.Option(
            None, "--scratch-clearance-deg", min=0.0, max=44.0,
            help="how far the random scratches' directions keep from the hatch's (default: the renderer's 10 deg; "
                 "0: any direction, along the grooves too)"),
        scratch_within_deg: Optional[float] = typer.Option(
            None, "--scratch-within-deg", min=0.1, max=45.0,
            help="instead, draw every random scratch at most this far from a groove family (scratches along the "
                 "hatch; the detector's groove-alignment angle is 7.5)"),
        groove_breaks: float = typer.Option(0.0, "--groove-breaks", min=0.0, max=0.9,
                                            help="the share of the grooves' length missing: a honing whose grooves "
                                                 "stop short, with cut ends (default 0: they run on, fading)"),
        psf_disc_px: float = PSF_DISC,
        psf_smear_px: float = PSF_SMEAR,
        psf_smear_deg: float = PSF_SMEAR_DEG,
        pores_on_scratches: float = typer.Option(0.0, "--pores-on-scratches", min=0.0, max=1.0,
                                                 help="the chance that a pore of a frame with a scratch lies on the "
                                                      "scratch's line, touching it (default 0: every defect clear of "
                                                      "the others)"),
        as_json: bool = typer.Option(False, "--json", help="one JSON object on stdout"),
    ) -> None:
        """Surface defects: recall above the limit per kind, false defects on clean walls, size errors, CPU time."""
        from rich.progress import Progress
        from rich.table import Table

        from station.cli.common import out_console, print_json

        with Progress(console=out_console, transient=True, disable=as_json) as bar:
            task = bar.add_task("rendering and inspecting frames", total=2 * frames + twin_frames)
            r = run(frames, seed, envelope, mm_per_px=mm_per_px, progress=lambda: bar.advance(task),
                    twin_frames=twin_frames, hatch_deg=hatch_deg, texture_in_mm=texture_in_mm,
                    scratch_clearance_deg=scratch_clearance_deg, scratch_within_deg=scratch_within_deg,
                    groove_breaks=groove_breaks, psf_disc_px=psf_disc_px, psf_smear_px=psf_smear_px,
                    psf_smear_deg=psf_smear_deg, pores_on_scratches=pores_on_scratches)
        if as_json:
            print_json(r)
            return
        t = Table(title=f"defects: {r['frames_with_defects']} frames with defects + {r['clean_frames']} clean, "
                        f"seed {r['seed']}, {r['mm_per_px']} mm/px, hatch +/-{r['hatch_deg']:g} deg, texture in "
                        f"{r['texture']}, scratches "
                        + (f"<= {r['scratch_within_deg']:g} deg off a groove family" if r["scratch_within_deg"]
                           else f">= {r['scratch_clearance_deg']:g} deg off it")
                        + (f", {r['groove_breaks']:.0%} of the grooves' length broken out" if r["groove_breaks"] else "")
                        + (f", pores on a scratch's line at {r['pores_on_scratches']:.0%}"
                           if r["pores_on_scratches"] else "")
                        + psf_title(r["psf"])
                        + f", {r['holes']} holes (one core)")
        for c in ("kind", "seeded", "limit mm", "above", "recall", "below: recall", "other kind",
                  "L med mm", "L p90 mm", "L in tol", "W med mm", "W p90 mm", "W in tol", "L in 2u"):
            t.add_column(c, justify="right")
        for kind, k in r["kinds"].items():
            sl, sw = k["sizes"]["length"], k["sizes"]["width"]
            lim = k["limit_mm"]
            t.add_row(kind, str(k["seeded"]), f"{lim['length']}" + (f" x {lim['width']}" if lim["width"] else ""),
                      str(k["above_limit"]), fmt_cell(k["recall_above_limit"]), fmt_cell(k["recall_below_limit"]),
                      str(k["found_other_kind"]), fmt_cell(sl["median_abs_err_mm"], 4),
                      fmt_cell(sl["p90_abs_err_mm"], 4), fmt_cell(sl["within_tol"]),
                      fmt_cell(sw["median_abs_err_mm"], 4), fmt_cell(sw["p90_abs_err_mm"], 4),
                      fmt_cell(sw["within_tol"]), fmt_cell(sl["within_2u"]))
        out_console.print(t)
        out_console.print(
            f"false defects: {r['false_per_100_clean_frames']:.1f} per 100 clean frames (goal <= 1), "
            f"{r['false_per_100_defect_frames']:.1f} per 100 frames with defects; CPU "
            f"{r['median_cpu_ms_per_frame']:.0f} ms per frame (median; 90th percentile "
            f"{r['p90_cpu_ms_per_frame']:.0f} ms), holes measured included")
        out_console.print("recall goal >= 0.95 above the limit; sizes right within 10 % or 0.02 mm "
                          "(L = length, W = width; 'in 2u' = error within twice the stated uncertainty)")
        for m in r["misses_above_limit"]:
            out_console.print(f"missed above the limit: {m['kind']} {m['length_mm']:.3f} x {m['width_mm']:.3f} mm at "
                              f"({m['x_px']:.0f}, {m['y_px']:.0f}) px, frame seed {m['seed']}"
                              + (f", reported as a {m['found_as']}" if m["found_as"] else ""))
        lg = r["long_scratches_without_hole"]
        if lg["seeded"]:
            out_console.print(
                f"scratches >= {lg['min_length_mm']} mm in frames without a hole: {lg['found']} of {lg['seeded']} "
                f"found, L in tol {fmt_cell(lg['sizes']['length']['within_tol'])}, "
                f"W in tol {fmt_cell(lg['sizes']['width']['within_tol'])}")
        tw = r["twin_long_scratches"]
        if tw:
            sl, sw = tw["sizes"]["length"], tw["sizes"]["width"]
            out_console.print(
                f"camera twin's optics, one 1.1-2 mm scratch and no hole ({tw['frames']} frames, seed {tw['seed']}): "
                f"{tw['found']} found; L in tol {fmt_cell(sl['within_tol'])} (median "
                f"{fmt_cell(sl['median_abs_err_mm'], 4)} mm), W in tol {fmt_cell(sw['within_tol'])} (median {fmt_cell(sw['median_abs_err_mm'], 4)} mm), "
                f"place within {PLACE_TOL_MM} mm {fmt_cell(tw['place_within_tol'])} (max "
                f"{fmt_cell(tw['place_max_mm'], 3)} mm); {len(tw['false'])} false")
