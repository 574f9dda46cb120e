"""The station's own check of its camera's sensor: frames of the bore wall turning under
the camera, the flawed pixels found in them (``station.vision.pixelmap``), and the map
set beside the one the station mends its frames with (``station check camera``).

Why on the station: a sensor gains hot pixels as it ages and warms, and a charge trap
can open in a CCD's column; each is the same pixel in every frame, read by the vision
stage as the scene (a trapped column is a scratch in every frame of a surface scan).
The part on the table serves as the moving wall: the table turns between frames, so
the wall's features move across the sensor while its flaws stay. No lens cap, no flat
light, no part of known surface.

The check takes raw frames (the station's map is not applied to them), finds the map,
and compares: flaws the station's map lacks are **new** (the map is out of date: the
new file is written, and the config's ``pixel_map`` should name it); flaws of the map
the frames no longer show are listed too (a dim pixel over the dark holes, a hot one
that has cooled) but do not fail the check.
"""

from __future__ import annotations

import asyncio
import json
import math
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

from station.inspection.scan import goto
from station.sequencer import messages as m
from station.vision.pixelmap import MIN_FRAMES, PixelMap, find_pixel_map


@dataclass(frozen=True)
class CameraCheckSettings:
    """``frames`` frames at evenly spaced turns of the table, at ``axial_mm`` along the
    bore (None: the part's first compensating hole's nominal place)."""

    frames: int = 16
    axial_mm: float | None = None

    def __post_init__(self):
        if not isinstance(self.frames, int) or self.frames < MIN_FRAMES:
            raise ValueError(f"the camera check needs at least {MIN_FRAMES} frames, not {self.frames!r}")
        if self.axial_mm is not None and not math.isfinite(self.axial_mm):
            raise ValueError(f"the camera check's axial place must be a number of mm, not {self.axial_mm!r}")


def camera_check_plan(model, axial_mm: float, settings: CameraCheckSettings, scan_settings, motion=None):
    """The frames as a plan (a generator of ``station.sequencer.messages``; returns the
    grey frames): the table turned by 360 / frames degrees between frames."""
    from drivers.interfaces.pixels import to_grey

    c = yield m.ReadAxis("C")
    c0 = float(c) if isinstance(c, (int, float)) and math.isfinite(c) else 0.0
    yield m.Note(f"camera check: {settings.frames} frames of the bore wall at {axial_mm:g} mm, the table turned "
                 f"{360.0 / settings.frames:g} deg between them")
    images = []
    axes_at: dict[str, float] = {}
    for k in range(settings.frames):
        yield m.Checkpoint(f"camera check frame {k + 1}")
        yield from goto(model, axial_mm, (c0 + k * 360.0 / settings.frames) % 360.0, scan_settings, motion, axes_at)
        frame = yield m.Capture()
        images.append(to_grey(frame.image))
        yield m.Progress(k + 1, settings.frames, f"camera check frame {k + 1} of {settings.frames}")
    return images


@dataclass
class CameraCheckOutcome:
    """What the check found: ``state`` complete | faulted | aborted, the map from the
    frames, and against the station's: ``new_pixels`` / ``new_columns`` (flaws it
    lacks), ``unseen_pixels`` / ``unseen_columns`` (its flaws the frames did not show)."""

    state: str
    reason: str = ""
    found: PixelMap | None = None
    new_pixels: list[tuple[int, int, str]] = field(default_factory=list)
    new_columns: list[tuple[int, int, int, float]] = field(default_factory=list)
    unseen_pixels: list[tuple[int, int, str]] = field(default_factory=list)
    unseen_columns: list[tuple[int, int, int, float]] = field(default_factory=list)
    had_map: bool = False
    out_dir: Path | None = None
    files: list[Path] = field(default_factory=list)

    @property
    def up_to_date(self) -> bool:
        return self.state == "complete" and not self.new_pixels and not self.new_columns

    def summary(self) -> str:
        if self.state != "complete":
            return f"camera check {self.state}: {self.reason}"
        f = self.found
        hot = sum(1 for p in f.pixels if p[2] == "hot")
        text = (f"camera check: {hot} hot and {len(f.pixels) - hot} dim pixel(s), {len(f.columns)} flawed column "
                f"stretch(es) in {f.frames} frames; ")
        if self.up_to_date:
            return text + ("the station's pixel map holds them all" if self.had_map else "no flaw, and no map needed")
        return text + (f"{len(self.new_pixels)} pixel(s) and {len(self.new_columns)} column stretch(es) the "
                       + ("station's map lacks" if self.had_map else "station has no map for")
                       + f": name {self.out_dir / 'pixel_map.json'} as the camera's pixel_map")

    def to_json(self) -> dict:
        return {"state": self.state, "reason": self.reason, "up_to_date": self.up_to_date, "had_map": self.had_map,
                "found": None if self.found is None else self.found.to_json(),
                "new_pixels": [list(p) for p in self.new_pixels],
                "new_columns": [[c, a, b, round(o, 3)] for c, a, b, o in self.new_columns],
                "unseen_pixels": [list(p) for p in self.unseen_pixels],
                "unseen_columns": [[c, a, b, round(o, 3)] for c, a, b, o in self.unseen_columns],
                "out_dir": None if self.out_dir is None else str(self.out_dir),
                "files": [str(p) for p in self.files], "summary": self.summary()}


def compare(found: PixelMap, known: PixelMap | None):
    """(new pixels, new columns, unseen pixels, unseen columns) of ``found`` against
    ``known``. A column stretch is the same flaw when it lies in the same column and
    their rows overlap; a pixel inside a known stretch is no new flaw."""
    known_px = {(r, c) for r, c, _ in known.pixels} if known else set()
    known_cols = list(known.columns) if known else []

    def in_known_column(r, c):
        return any(kc == c and a <= r <= b for kc, a, b, _ in known_cols)

    def overlaps(col, cols):
        c, a, b, _ = col
        return any(kc == c and ka <= b and a <= kb for kc, ka, kb, _ in cols)

    new_px = [p for p in found.pixels if (p[0], p[1]) not in known_px and not in_known_column(p[0], p[1])]
    new_cols = [col for col in found.columns if not overlaps(col, known_cols)]
    found_px = {(r, c) for r, c, _ in found.pixels}
    unseen_px = [p for p in (known.pixels if known else []) if (p[0], p[1]) not in found_px]
    unseen_cols = [col for col in known_cols if not overlaps(col, found.columns)]
    return new_px, new_cols, unseen_px, unseen_cols


async def run_camera_check(session, family, *, settings: CameraCheckSettings | None = None,
                           out_dir: str | Path | None = None) -> CameraCheckOutcome:
    """Run the check on a session's station (``station check camera``): home when needed,
    the frames by a plan on its engine, the map found in a worker thread, compared with
    the station's (``Station.pixel_map``); the map and ``check.json`` in ``out_dir``
    (default ``<data>/checks/camera/<UTC time>``), a "check" event in the log."""
    from station.inspection.service import ensure_ready, motion_limits
    from station.sequencer.engine import PlanEnded

    settings = settings or CameraCheckSettings()
    st = session.station
    if session.engine.devices.camera is None:
        raise ValueError("the station has no camera to check")
    axial = settings.axial_mm if settings.axial_mm is not None else float(family.holes[0].position.nominal)
    stamp = datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%S")
    out = Path(out_dir) if out_dir is not None else Path(session.store.data_dir) / "checks" / "camera" / stamp
    known = getattr(st, "pixel_map", None)
    try:
        await ensure_ready(session.engine)
        plan = camera_check_plan(st.model, axial, settings, session.settings, motion_limits(session.engine.devices))
        images = await session.engine.run(plan)
    except PlanEnded as ended:
        res = CameraCheckOutcome("faulted" if ended.outcome == "faulted" else "aborted", ended.reason)
        await asyncio.to_thread(session.store.log_event, "check", res.summary())
        return res
    found = await asyncio.to_thread(find_pixel_map, images, f"station check camera, {len(images)} frames at "
                                                            f"{axial:g} mm")
    new_px, new_cols, unseen_px, unseen_cols = compare(found, known)
    res = CameraCheckOutcome("complete", "", found, new_px, new_cols, unseen_px, unseen_cols, known is not None, out)
    await asyncio.to_thread(out.mkdir, parents=True, exist_ok=True)
    await asyncio.to_thread(found.save, out / "pixel_map.json")
    res.files = [out / "pixel_map.json", out / "check.json"]
    await asyncio.to_thread((out / "check.json").write_text, json.dumps(res.to_json(), indent=1) + "\n")
    await asyncio.to_thread(session.store.log_event, "check", res.summary())
    return res
