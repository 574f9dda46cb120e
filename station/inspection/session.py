"""An inspection session: the station, the store, the engine and the inspections'
document stream, kept together for as long as the station runs.

The CLI (``station inspect``, ``station gauge``, ``station paper``), the benches, the API
and the end-to-end tests all run inspections through this one object, so they exercise
the same code the plant runs. The composition root builds it
(``station.runtime.open_session``); this module knows the station only by what it
offers (its model, its camera geometry, its traceability, the part on its table).
"""

from __future__ import annotations

import asyncio
import math
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from station.inspection.documents import DocumentStream, InspectionStart, InspectionStop
from station.inspection.scan import CameraGeometry, ScanSettings
from station.inspection.service import InspectionOutcome, InspectionService
from station.inspection.writers import EngineEventLog, ScanLogWriter, StoreWriter
from station.monitor.evidence import WINDOW, Explanation, MasterRecord, explain
from station.monitor.watch import Alarm, CharacteristicCheck, StationWatch
from station.parts.spec import PartSpec
from station.sequencer.engine import Engine


def vision_measure(mm_per_px: float, pixel_map=None):
    """The vision stage as the engine calls it: image -> hole measurements.  Its compiled
    kernels are loaded here, before any inspection (``warm_up``). ``pixel_map``: the
    camera's flawed pixels (``station.vision.pixelmap.PixelMap``), mended in each frame
    first; None: none known."""
    from station.vision.measure import measure_holes, warm_up

    warm_up()

    def measure(image):
        return measure_holes(_mended(image, pixel_map), mm_per_px=mm_per_px)

    return measure


def _mended(image, pixel_map):
    """``image`` with the camera's flawed pixels mended (grey frames; a colour frame is
    made grey first, as the vision stage would)."""
    if pixel_map is None:
        return image
    from drivers.interfaces.pixels import to_grey

    return pixel_map.repair(to_grey(image))


def vision_defects(mm_per_px: float, pixel_map=None):
    """The surface inspection as the engine calls it: image -> defects
    (``station.vision.defects.detect_defects``: pores, scratches, and burrs and chips at
    the frame's holes, which it measures itself). ``blur_px``: the camera's blur as the
    bore scan read it at the holes' edges (``MeasureSurface.blur_px``); None: read in
    the frame itself. ``hole_places``: where the part's holes may show in the frame
    (``MeasureSurface.hole_places``); None: every dark disc of a hole's size is a hole.
    ``pixel_map``: as ``vision_measure``'s."""
    from station.vision.defects import detect_defects

    def surface(image, blur_px: float | None = None, hole_places=None):
        return detect_defects(_mended(image, pixel_map), mm_per_px, blur_px=blur_px, hole_places=hole_places)

    return surface


@dataclass
class MasterCheckOutcome:
    """A check of the station on its certified master: the inspection, each
    characteristic against the certificate, and the alarms it raised (none: in
    control, and the station's ``needs_check`` cleared)."""

    master_id: str
    inspection: InspectionOutcome
    checks: list[CharacteristicCheck]
    alarms: list[Alarm]

    @property
    def in_control(self) -> bool:
        return self.inspection.state == "complete" and not self.alarms

    def to_json(self, with_truth: bool = False) -> dict:
        return {"master_id": self.master_id, "in_control": self.in_control,
                "inspection": self.inspection.to_json(with_truth),
                "checks": [{"id": c.id, "measured": c.measured, "certified": c.certified,
                            "u_station": c.u_station, "u_certificate": c.u_certificate, "z": c.z, "en": c.en}
                           for c in self.checks],
                "alarms": [a.to_json() for a in self.alarms]}


@dataclass
class Session:
    station: Any  # station.runtime.Station
    store: Any  # station.store.Store
    engine: Engine
    settings: ScanSettings
    #: the station's control charts over its own evidence (docs/monitor.md)
    watch: StationWatch | None = None

    def __post_init__(self):
        from station.monitor.proposals import ProposalBook, apply_changes, part_scale_ppm

        #: every inspection's documents (station.inspection.documents); the record is
        #: a required subscriber, the engine's event log and the scan log follow it. The
        #: event log writes off the station loop, and its queue is flushed at the stop
        #: before the record's end is written
        self.documents = DocumentStream()
        self.writer = StoreWriter(self.store)
        self.event_log = EngineEventLog(self.store, self.engine)
        self.documents.subscribe(self.event_log.flush)
        self.documents.subscribe(self.writer, required=True)
        self.documents.subscribe(self.event_log)
        self.documents.subscribe(ScanLogWriter(self.store))
        if self.watch is None:
            self.watch = StationWatch(gate_um=self.settings.model_u_um)
        #: the station's control charts watch every production inspection's documents
        self._purposes: dict[str, str] = {}
        self.documents.subscribe(self._watch_documents)
        #: model proposals and the approved changes (docs/monitor.md, The loop)
        self.proposals = ProposalBook(self.store.data_dir)
        approved = self.proposals.approved_changes()
        if approved:
            # what engineers approved is the station's model from now on, over its configured one
            self.station.model = apply_changes(self.station.model, approved, f"+{len(approved)}")
            self.settings = replace(self.settings, part_scale_ppm=self.settings.part_scale_ppm + part_scale_ppm(approved))
        #: position errors (um) of the last master check, when it was out of control
        self._out_of_control: dict[str, list[float]] = {}
        #: the master checks since the start, in the starting model's frame, and what
        #: they say together (station.monitor.evidence)
        self.history: list[MasterRecord] = []
        self.explanation: Explanation | None = None
        #: per master hole: how much the changes approved since the start moved its reading (um)
        self.applied_um: dict[str, float] = {}
        #: the part expansion (ppm) the changes approved since the start correct
        self.applied_scale_ppm = 0.0

    def clock_s(self) -> float:
        """The station's machine clock (s): the host's, times the time scale its config
        runs the drives at (1 on hardware; in simulation the drives' clock, which the
        world's physics runs on)."""
        return time.monotonic() * float(self.station.time_scale or 1.0)

    def evidence_bound_um(self, positions_mm: list[float]) -> float:
        """What the master checks show the station has not corrected (um, a bound added
        to the expanded U) for a part whose holes are at ``positions_mm``: while they
        show a drift, the error they showed at the last check and not corrected plus the
        drift since; a scale seen and not corrected (or the one corrected, at twice its
        standard uncertainty), over the holes' distance from where the checks pin the
        datum."""
        ex = self.explanation
        if ex is None or not self.history:
            return 0.0
        last = self.history[-1]
        bound_um = 0.0
        if ex.drifting:
            bias = abs(float(sum(ex.now_um[h] + self.applied_um.get(h, 0.0) for h in ex.now_um)) / len(ex.now_um))
            rate = abs(ex.rate_um_per_h) + 2.0 * (ex.rate_u_um_per_h or 0.0)  # the rate's own bound, k = 2
            bound_um = bias + rate * max(0.0, self.clock_s() - last.time_s) / 3600.0
        scale = self.uncorrected_scale()
        if ex.scale_ppm is not None and positions_mm and (scale is not None or self.applied_scale_ppm):
            # a scale seen and not corrected, or the one corrected with its own uncertainty,
            # over the holes' distance from where the checks pin the datum
            ref = sum(last.position_mm.values()) / len(last.position_mm)
            s_ppm = math.hypot(scale or 0.0, 2.0 * ex.scale_u_ppm)
            bound_um += s_ppm * 1e-3 * max(abs(a - ref) for a in positions_mm)
        return bound_um

    def uncorrected_scale(self) -> float | None:
        """The part expansion (ppm) the checks show beyond 3 u and the present settings do
        not correct; None when there is none (or fewer than three checks to pool)."""
        ex = self.explanation
        if ex is None or ex.scale_ppm is None or ex.checks < 3:
            return None
        s = ex.scale_ppm - self.applied_scale_ppm
        return s if abs(s) > 3.0 * ex.scale_u_ppm else None

    @property
    def model_version(self) -> str:
        from station.inspection.service import model_fingerprint

        return f"{self.station.model.name}@{model_fingerprint(self.station.model)[:8]}"

    async def propose(self, reason: str, holes_mm: dict[str, float]):
        """A model proposal from the last master check, when it was out of control (None
        when it was not, or when its evidence is not one datum shift); logged. Files and the store are written
        off the event loop (it carries the drives' heartbeats)."""
        from station.monitor.proposals import ProposalError, datum_proposal

        if not self._out_of_control:
            return None
        try:
            p = datum_proposal(self.station.model, self.model_version, reason, dict(self._out_of_control), holes_mm,
                               explanation=self.explanation, scale_ppm=self.uncorrected_scale())
        except ProposalError as exc:
            await asyncio.to_thread(self.store.log_event, "alarm", f"no model proposal: {exc}")
            return None
        # the checks it rests on, in the present model's frame: its before/after picture
        p.explanation["points"] = [{"time_s": r.time_s, "hole": h, "error_um": e + self.applied_um.get(h, 0.0),
                                    "u_um": r.u_um[h]} for r in self.history[-WINDOW:] for h, e in r.error_um.items()]
        await asyncio.to_thread(self.proposals.add, p)
        await asyncio.to_thread(self.store.log_event, "proposal", f"model proposal {p.id} on {p.base_version}: "
                                + "; ".join(c.why for c in p.changes))
        return p

    async def decide(self, proposal_id: str, approve: bool, who: str, note: str = ""):
        """An engineer's decision on a proposal (audit-logged); approved, the station
        uses the changed model from its next inspection and its charts start again.
        The changed model is made before the decision is recorded, so a change that
        cannot be applied is refused and nothing is recorded."""
        from station.monitor.proposals import apply_changes, part_scale_ppm

        new_model = None
        if approve:
            pending = await asyncio.to_thread(self.proposals.get, proposal_id)
            n = len(await asyncio.to_thread(self.proposals.approved_changes)) + len(pending.changes)
            new_model = apply_changes(self.station.model, pending.changes, f"+{n}")
        p = await asyncio.to_thread(self.proposals.decide, proposal_id, approve, who, note)
        if approve:
            before = self.model_version
            self.station.model = new_model
            self.watch.model_changed()
            for hole, v in p.expected_change_um.items():
                self.applied_um[hole] = self.applied_um.get(hole, 0.0) + v
            scale = part_scale_ppm(p.changes)
            self.applied_scale_ppm += scale
            self.settings = replace(self.settings, part_scale_ppm=self.settings.part_scale_ppm + scale)
            await asyncio.to_thread(self.store.log_event, "approval", f"model proposal {p.id} approved by {who}: "
                                    f"{before} -> {self.model_version}" + (f" ({note})" if note else ""))
        else:
            await asyncio.to_thread(self.store.log_event, "rejection",
                                    f"model proposal {p.id} rejected by {who}" + (f": {note}" if note else ""))
        return p

    def service_for(self, part: PartSpec, *, evidence: bool = True) -> InspectionService:
        """The inspection service for ``part``; ``evidence``: its stated U includes what the
        master checks show uncorrected (production). A check on the master itself is
        judged on the station's own U, or a drift it has to catch would hide in it."""
        st = self.station
        extra = self.evidence_bound_um([h.position.nominal for h in part.holes]) if evidence else 0.0
        settings = replace(self.settings, evidence_bound_um=extra)
        geo = CameraGeometry(st.mm_per_px, st.frame_size_px[0], st.frame_size_px[1], part.bore.diameter_mm / 2.0,
                             calibration=getattr(st, "camera_calibration", None))
        return InspectionService(self.engine, self.documents, st.model, geo, settings,
                                 traceability=st.traceability(), time_scale=st.time_scale,
                                 purpose="production" if evidence else "master")

    async def inspect(self, part: PartSpec, serial: str, **kw) -> InspectionOutcome:
        """One production inspection; its evidence goes on the station's charts (the
        charts subscribe to its documents)."""
        return await self.service_for(part).inspect(part, serial, **kw)

    async def _watch_documents(self, doc) -> None:
        """A subscriber: a complete production inspection's holes on the station's charts,
        the alarms they raise logged and kept on the outcome (checks on the master are
        judged by their certificate instead, ``check_master``)."""
        if isinstance(doc, InspectionStart):
            self._purposes[doc.inspection_id] = doc.purpose
        elif isinstance(doc, InspectionStop):
            purpose = self._purposes.pop(doc.inspection_id, None)
            out = doc.outcome
            if purpose == "production" and out is not None and out.state == "complete":
                out.alarms = await self._log_alarms(self.watch.observe_inspection(out.holes), out.id)

    async def check_master(self, cert, family: PartSpec, *, seed: int = 0) -> MasterCheckOutcome:
        """Inspect the certified master (``cert``: a ``MasterCertificate`` of the part
        family ``family``) and judge the station by it. On hardware the operator has put
        the master on the table; in simulation the composition root puts it into the
        twin's world for the check (``seed``: its making)."""
        from station.checks.master import compare

        spec = cert.as_part_spec(family)
        with self.station.master_on_table(cert, bore_diameter_mm=family.bore.diameter_mm, seed=seed):
            out = await self.service_for(spec, evidence=False).inspect(spec, cert.master_id)
        checks = compare(cert, out.characteristics) if out.state == "complete" else []
        positions = [c for c in checks if c.id.endswith(".position")]
        recorded = bool(positions) and all(c.measured is not None and c.u_station is not None for c in positions)
        if recorded:
            holes = [c.id.rsplit(".", 1)[0] for c in positions]
            self.history.append(MasterRecord(
                self.clock_s(), self.watch.index, {h: c.certified for h, c in zip(holes, positions)},
                {h: (c.measured - c.certified) * 1e3 - self.applied_um.get(h, 0.0) for h, c in zip(holes, positions)},
                {h: math.hypot(c.u_station, c.u_certificate) * 1e3 for h, c in zip(holes, positions)},
                {h.id: h.angle_deg for h in spec.holes if h.id in holes}))
            self.explanation = explain(self.history)
        if out.state != "complete":
            alarms = await self._log_alarms([Alarm(self.watch.index, "master", f"master check {cert.master_id} did "
                                                                                  f"not complete: {out.reason}")], out.id)
        else:
            alarms = await self._log_alarms(self.watch.observe_master(positions), out.id)
        if not alarms:
            self._out_of_control = {}
            await asyncio.to_thread(self.store.log_event, "check", f"master check {cert.master_id} in control: the "
                                                                   f"station is within its stated U", out.id)
        else:
            # the present state is the last check's: a proposal rests on it alone (an
            # earlier check may straddle the change)
            ex = self.explanation
            if recorded and ex is not None:
                # the error now as the checks together say it (less noisy than one check),
                # in the present model's frame
                self._out_of_control = {f"{h}.position": [v + self.applied_um.get(h, 0.0)] for h, v in ex.now_um.items()}
            else:
                self._out_of_control = {c.id: [(c.measured - c.certified) * 1e3] for c in positions
                                        if c.measured is not None}
        return MasterCheckOutcome(cert.master_id, out, checks, alarms)

    async def _log_alarms(self, alarms: list[Alarm], inspection_id: str | None) -> list[Alarm]:
        for a in alarms:
            await asyncio.to_thread(self.store.log_event, "alarm", f"station needs a check: {a.reason}", inspection_id)
        return alarms

    async def check_axis(self, family: PartSpec, *, settings=None, out_dir: str | Path | None = None,
                         propose: bool = False, plots: bool = True, holes_mm: dict[str, float] | None = None):
        """The station's own short ISO 230-2 check of Z against its grating over the
        stroke ``family``'s scans use, and discovery on it (``station.checks.axis``;
        ``settings``: an ``AxisCheckSettings``): the files in ``out_dir`` (default
        ``<data>/checks/axis/<time>``), a "check" event in the log, and with ``propose``
        a model proposal when discovery names what the model lacks. Returns an
        ``AxisCheckOutcome``."""
        from station.checks.axis import run_axis_check

        return await run_axis_check(self, family, settings=settings, out_dir=out_dir, propose=propose, plots=plots,
                                    holes_mm=holes_mm)

    async def check_camera(self, family: PartSpec, *, settings=None, out_dir: str | Path | None = None):
        """The station's own check of its camera's sensor on the part in place
        (``station.checks.camera``; ``settings``: a ``CameraCheckSettings``): the flawed
        pixels found in frames of the turning wall against the station's pixel map, the
        map in ``out_dir`` (default ``<data>/checks/camera/<time>``). Returns a
        ``CameraCheckOutcome``."""
        from station.checks.camera import run_camera_check

        return await run_camera_check(self, family, settings=settings, out_dir=out_dir)
