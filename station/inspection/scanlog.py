"""Scan logs: what every inspection learns about the Z axis, as recordings.

At each measurement frame the station knows the commanded slide position and the
grating's reading of where the carriage really is. Written in the recording format
of the discovery contract (``shared/spec/discovery.md``: deviation = actual minus
commanded, um), these logs let ``station discover`` compare the station's own
everyday data with its error model, between laser campaigns: a growing thermal
drift or a worn screw shows up without stopping production.

One file per inspection, ``<data>/scanlogs/<inspection id>.csv``; ``merge_scan_logs``
joins them into one recording (one run per inspection, time running on).
"""

from __future__ import annotations

import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from station.recording import Recording, read_recording

SCANLOG_DIR = "scanlogs"


def scan_log(inspection_id: str, holes, written_unix: float | None = None) -> Recording | None:
    """The recording of one inspection (None when no frame read the grating): one row
    per approach. The frames of one hole are taken at one approach, so they share one
    carriage position; logging each would count one approach as several."""
    rows = []
    for h in holes:
        read = [f for f in h.frames if f.grating_mm is not None and f.time_s is not None]
        if read:
            rows.append((read[0].time_s, read[0].z_cmd_mm, float(np.mean([f.grating_mm for f in read]))))
    if not rows:
        return None
    t = np.array([r[0] for r in rows])
    target = np.array([r[1] for r in rows])
    dev_um = (np.array([r[2] for r in rows]) - target) * 1e3
    n = len(rows)
    # the wall-clock start of the scan orders the logs when they are merged: the order
    # of the runs is data (drift, whiteness), an inspection id is not an order
    end = time.time() if written_unix is None else written_unix
    started = datetime.fromtimestamp(end - float(t[-1] - t[0]), timezone.utc).isoformat(timespec="milliseconds")
    return Recording(
        time_s=t - t[0], run=np.ones(n, dtype=int),
        # every hole is approached from below (station.inspection.scan.goto)
        direction=np.ones(n, dtype=int), target=target, deviation=dev_um,
        metadata={"axis": "Z", "kind": "linear", "instrument": "station grating (scan log)",
                  "inspection": inspection_id, "started_utc": started},
        source=f"scan log {inspection_id}",
    )


def write_scan_log(data_dir: str | Path, inspection_id: str, holes) -> Path | None:
    rec = scan_log(inspection_id, holes)
    if rec is None:
        return None
    folder = Path(data_dir) / SCANLOG_DIR
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{inspection_id}.csv"
    tmp = path.with_suffix(".tmp")
    rec.to_csv(tmp)
    tmp.replace(path)  # never a half-written log under its real name
    return path


def merge_scan_logs(paths) -> Recording:
    """Join scan logs into one recording: run k is the k-th log in order of the scans'
    start (``started_utc``; the file's modification time for a log without it), time
    runs on from one log to the next (each log's own time starts at 0)."""
    paths = sorted(Path(p) for p in paths)
    if not paths:
        raise ValueError("no scan logs to merge")

    def started(item) -> tuple[float, str]:
        path, rec = item
        stamp = rec.metadata.get("started_utc")
        try:
            when = datetime.fromisoformat(stamp).timestamp() if stamp else path.stat().st_mtime
        except ValueError:
            when = path.stat().st_mtime
        return when, str(path)

    recs = [r for _, r in sorted(((p, read_recording(p)) for p in paths), key=started)]
    parts, t0 = [], 0.0
    for k, r in enumerate(recs, start=1):
        parts.append((r.time_s + t0, np.full(len(r), k), r.direction, r.target, r.deviation))
        t0 += float(r.time_s[-1]) + 1.0
    cat = [np.concatenate([p[i] for p in parts]) for i in range(5)]
    return Recording(cat[0], cat[1].astype(int), cat[2].astype(int), cat[3], cat[4],
                     metadata={"axis": "Z", "kind": "linear", "instrument": "station grating (scan logs)",
                               "inspections": str(len(recs))},
                     source=f"{len(recs)} scan logs")
