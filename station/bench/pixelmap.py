"""``station bench pixel-map``: the camera's flawed pixels found from frames of moving
walls, and what mending them is worth to the surface inspection and the holes.

A sensor with flaws (``sim.camera.sensor.SensorFlaws``: hot and dim pixels, a trap in a
column) renders every frame; the map is found from ``map_frames`` frames of other walls
(``station.vision.pixelmap``, which never sees the twin's pattern) and scored against
the pattern. Then ``frames`` clean and ``frames`` defect frames are inspected three
ways: from a flawless sensor (the same walls, defects and noise), raw from the flawed
one, and mended by the map; and ``frames`` hole frames (the vision bench's) measured
the same three ways, their diameters' error over their own u. The bench imports ``sim``
(the CLI side may)."""

from __future__ import annotations

import time

import numpy as np
import typer


def run(frames: int = 50, seed: int = 7_500_000, map_frames: int = 16, flaws=None, progress=None) -> dict:
    import cv2

    from sim.camera.defects import random_defect_frame
    from sim.camera.render import random_frame
    from sim.camera.sensor import SensorFlaws, pattern
    from station.bench.defects import match
    from station.vision.defects import detect_defects
    from station.vision.measure import measure_holes, warm_up
    from station.vision.pixelmap import find_pixel_map

    cv2.setNumThreads(1)
    tick = progress or (lambda: None)
    flaws = flaws or SensorFlaws(seed=seed)
    warm_up()

    walls = []
    for i in range(map_frames):
        walls.append(random_defect_frame(seed + 100_000 + i, {}, sensor=flaws).image)
        tick()
    c0 = time.process_time()
    pmap = find_pixel_map(walls)
    map_s = time.process_time() - c0
    truth = pattern(flaws, pmap.width, pmap.height)
    found = {(r, c): k for r, c, k in pmap.pixels}
    hot = dict(zip(zip(truth.hot_rows.tolist(), truth.hot_cols.tolist()), truth.hot_dn.tolist()))
    dead = set(zip(truth.dead_rows.tolist(), truth.dead_cols.tolist()))
    trap_cols = {c for c, _, _ in truth.traps}
    false_pixels = [k for k in found if k not in hot and k not in dead]
    missed_hot = sorted(v for k, v in hot.items() if k not in found and k[1] not in trap_cols)
    columns = [{"col": c, "first_row": a, "last_row": b, "offset_dn": round(o, 2),
                "true": next(({"row": r, "dn": d} for tc, r, d in truth.traps if tc == c), None)}
               for c, a, b, o in pmap.columns]

    ways = ("flawless", "raw", "mended")
    defects = {w: {"false_clean": 0, "false_defect_frames": 0, "found": 0} for w in ways}
    seeded = 0
    for clean in (True, False):
        for i in range(frames):
            s = seed + i + (0 if clean else 200_000)
            kinds = {} if clean else None
            f = random_defect_frame(s, kinds, sensor=flaws)
            bare = random_defect_frame(s, kinds)
            seeded += len(f.defects)
            for w, img in (("flawless", bare.image), ("raw", f.image), ("mended", pmap.repair(f.image))):
                pairs, false = match(f.defects, detect_defects(img, 0.01), 0.01)
                defects[w]["false_clean" if clean else "false_defect_frames"] += len(false)
                defects[w]["found"] += sum(1 for t, d in pairs if d is not None and d.kind == t.kind)
            tick()
    z = {w: [] for w in ways}
    for i in range(frames):
        s = seed + 300_000 + i
        f, bare = random_frame(s, sensor=flaws), random_frame(s)
        for w, img in (("flawless", bare.image), ("raw", f.image), ("mended", pmap.repair(f.image))):
            got = measure_holes(img)
            for h in f.holes:
                if h.partial:
                    continue
                m = [g for g in got if np.hypot(g.x_px - h.x_px, g.y_px - h.y_px) < 3 and g.diameter_u_px]
                z[w].append((m[0].diameter_px - h.diameter_px) / m[0].diameter_u_px if m else np.nan)
        tick()
    holes = {}
    for w in ways:
        v = np.array(z[w], float)
        ok = v[np.isfinite(v)]
        holes[w] = {"holes": int(v.size), "missed": int(v.size - ok.size),
                    "rms_z": float(np.sqrt(np.mean(ok**2))) if ok.size else None,
                    "max_abs_z": float(np.max(np.abs(ok))) if ok.size else None,
                    "beyond_3": int(np.sum(np.abs(ok) > 3))}
    return {
        "seed": seed, "frames": frames, "map_frames": map_frames,
        "sensor": {"hot": len(hot), "dim": len(dead), "traps": len(truth.traps), "hot_median_dn": flaws.hot_median_dn},
        "map": {"hot": sum(1 for k in found.values() if k == "hot"), "dim": sum(1 for k in found.values() if k == "dim"),
                "hot_found_over_20dn": sum(1 for k, v in hot.items() if v >= 20 and k in found),
                "hot_over_20dn": sum(1 for v in hot.values() if v >= 20),
                "dim_found": sum(1 for k in dead if k in found), "false_pixels": len(false_pixels),
                "largest_missed_hot_dn": round(missed_hot[-1], 2) if missed_hot else None,
                "columns": columns, "cpu_s": round(map_s, 2)},
        "defects": {"seeded_in_defect_frames": seeded, **defects},
        "holes": holes,
    }


def register(bench_app: typer.Typer) -> None:
    @bench_app.command("pixel-map")
    def pixel_map(
        frames: int = typer.Option(50, "--frames", min=1, help="clean, defect and hole frames each (1280 x 1024)"),
        seed: int = typer.Option(7_500_000, "--seed", help="first seed (the sensor's flaws are drawn from it too)"),
        map_frames: int = typer.Option(16, "--map-frames", min=12, help="frames of other walls the map is found from"),
        hot_share: float = typer.Option(2e-4, "--hot-share", min=0.0, max=0.05, help="share of hot pixels"),
        hot_dn: float = typer.Option(25.0, "--hot-dn", min=0.0, help="the hot pixels' median dark signal (DN)"),
        dim_share: float = typer.Option(5e-5, "--dim-share", min=0.0, max=0.05, help="share of dim pixels"),
        traps: int = typer.Option(1, "--traps", min=0, help="columns with a charge trap"),
        trap_dn: float = typer.Option(12.0, "--trap-dn", min=0.0, help="the charge a trap takes (DN)"),
        as_json: bool = typer.Option(False, "--json", help="one JSON object on stdout"),
    ) -> None:
        """The camera's flawed pixels: the map found from moving walls against the sensor's truth, and the
        surface inspection's false defects and the holes' errors from a flawless, a raw and a mended sensor."""
        from rich.progress import Progress
        from rich.table import Table

        from sim.camera.sensor import SensorFlaws
        from station.cli.common import out_console, print_json

        flaws = SensorFlaws(seed=seed, hot_share=hot_share, hot_median_dn=hot_dn, dead_share=dim_share, traps=traps,
                            trap_dn=trap_dn)
        with Progress(console=out_console, transient=True, disable=as_json) as bar:
            task = bar.add_task("rendering, mapping and inspecting", total=map_frames + 3 * frames)
            r = run(frames, seed, map_frames, flaws, progress=lambda: bar.advance(task))
        if as_json:
            print_json(r)
            return
        m = r["map"]
        out_console.print(
            f"sensor: {r['sensor']['hot']} hot, {r['sensor']['dim']} dim pixels, {r['sensor']['traps']} trap(s); "
            f"map from {r['map_frames']} frames ({m['cpu_s']} s CPU): hot {m['hot_found_over_20dn']} of "
            f"{m['hot_over_20dn']} over 20 DN (largest missed {m['largest_missed_hot_dn']} DN), dim {m['dim_found']} "
            f"of {r['sensor']['dim']}, {m['false_pixels']} sound pixel(s) flagged", highlight=False)
        for c in m["columns"]:
            out_console.print(f"  column {c['col']}: rows {c['first_row']}-{c['last_row']}, {c['offset_dn']:+.1f} DN"
                              + (f" (true: rows 0-{c['true']['row']}, -{c['true']['dn']:g} DN)" if c["true"]
                                 else " (no trap there)"), highlight=False)
        t = Table(title=f"{r['frames']} clean + {r['frames']} defect frames ({r['defects']['seeded_in_defect_frames']} "
                        f"defects), {r['frames']} hole frames, seed {r['seed']}")
        for col in ("sensor", "false / clean frames", "false / defect frames", "defects found", "holes",
                    "diameter RMS z/u", "max |z|", "beyond 3u"):
            t.add_column(col, justify="right")
        for w in ("flawless", "raw", "mended"):
            d, h = r["defects"][w], r["holes"][w]
            t.add_row(w, str(d["false_clean"]), str(d["false_defect_frames"]), str(d["found"]),
                      f"{h['holes'] - h['missed']} of {h['holes']}", f"{h['rms_z']:.3f}", f"{h['max_abs_z']:.2f}",
                      str(h["beyond_3"]))
        out_console.print(t)
