"""One inspection, from the part spec to the judged result, as a stream of documents.

The service plans the bore scan, runs it on the engine and judges every
characteristic; it publishes what happened as documents (``station.inspection.
documents``: start, frames, holes, checks, stop) and leaves every side effect to their
subscribers. The store writer is a required one: the result (all characteristics and
the final state in one transaction) is committed before the service returns it; when
it is not, the outcome says so and the stop published is the faulted one. A plan that
ends early (stopped, aborted, faulted) is published with its reason; a crash leaves
the record ``running``, which the next start of the store marks ``interrupted``.

Decision rule: simple acceptance (ISO 14253-1's "shared risk"): a value inside the
limits, inclusive, conforms; the expanded uncertainty is recorded beside it.
"""

from __future__ import annotations

import hashlib
import math
import platform
import uuid
from dataclasses import dataclass, field
from typing import Mapping

from station import __version__
from station.inspection.documents import (CheckDocument, DocumentStream, FrameDocument, HoleDocument,
                                          InspectionStart, InspectionStop, SurfaceDocument)
from station.inspection.scan import (CameraGeometry, HoleResult, HoleTarget, ScanFinding, ScanResult, ScanSettings,
                                     bore_scan, hole_targets)
from station.inspection.surface import SurfaceResult
from station.inspection.surface_scan import SurfaceSettings, physical_limit, surface_scan
from station.inspection.writers import ResultNotStored
from station.kinematics.model import StationModel
from station.motion import AxisLimits
from station.parts.spec import SURFACE_RIM_KINDS, PartSpec
from drivers.interfaces import DriverError
from station.sequencer.cycle import cycle_summary, lower_bound, machine_time
from station.sequencer import messages as m
from station.sequencer.engine import Engine, PlanEnded, State


@dataclass
class CharacteristicOutcome:
    id: str
    nominal: float
    lower_limit: float
    upper_limit: float
    measured: float | None
    uncertainty_k2: float | None
    passed: bool
    true_value: float | None = None

    def to_json(self) -> dict:
        return dict(self.__dict__)


@dataclass
class InspectionOutcome:
    id: str
    part_number: str
    serial: str
    state: str  # complete | aborted | faulted
    result: str | None  # pass | fail | None
    reason: str = ""
    characteristics: list[CharacteristicOutcome] = field(default_factory=list)
    holes: list[HoleResult] = field(default_factory=list)
    #: what the scan saw that the spec does not expect (unexpected holes, an ambiguous
    #: identity) and how the part's angular datum was set
    findings: list[ScanFinding] = field(default_factory=list)
    #: machine time of the run and its breakdown, with the plan's lower bound
    #: (station.sequencer.cycle.cycle_summary); None when not known
    cycle: dict | None = None
    #: the alarms the station's charts raised on this inspection's evidence
    alarms: list = field(default_factory=list)
    #: the coverage scan's defects and unrolled picture (station.inspection.surface);
    #: None when the part spec asks for no surface inspection
    surface: SurfaceResult | None = None

    def to_json(self, with_truth: bool = False) -> dict:
        chars = []
        for c in self.characteristics:
            d = c.to_json()
            if not with_truth:
                d.pop("true_value", None)
            chars.append(d)
        return {"id": self.id, "part_number": self.part_number, "serial": self.serial, "state": self.state,
                "result": self.result, "reason": self.reason, "characteristics": chars,
                "findings": [dict(f.__dict__) for f in self.findings], "cycle": self.cycle,
                "alarms": [a.to_json() for a in self.alarms],
                "surface": None if self.surface is None else self.surface.to_json(with_truth)}


def model_fingerprint(model: StationModel) -> str:
    """16 hex digits that change with any number of the model (its version for a record)."""
    return hashlib.sha256(repr((model.endoscope_offset_mm, model.table_offset_mm, sorted(model.static_errors.items()),
                                sorted(model.motions.items()))).encode()).hexdigest()[:16]


def scan_plan(model: StationModel, part: PartSpec, geometry: CameraGeometry, settings: ScanSettings,
              motion: Mapping[str, AxisLimits] | None = None, *, surface: bool = False):
    """The bore scan of ``part`` (a plan returning a ``ScanResult``), and with
    ``surface`` the coverage scan of its surface band after the holes (the result's
    ``surface``)."""
    holes = bore_scan(model, hole_targets(part), geometry, settings, datum=part.placement.angular_datum,
                      placement_angle_deg=part.placement.angle_deg, motion=motion)
    if not surface:
        return holes

    def both():
        scan = yield from holes
        scan.surface = yield from surface_scan(model, part, geometry, settings, scan.holes, motion=motion,
                                               findings=scan.findings)
        return scan

    return both()


def wants_surface(part: PartSpec, asked: bool | None) -> bool:
    """Whether this inspection scans the surface: as the job asks, else as the part spec
    says (``[surface] every_part``); never for a spec without surface criteria."""
    if part.surface is None:
        if asked:
            raise ValueError(f"{part.part_number} has no [surface] table: its surface has no criteria to judge")
        return False
    return part.surface.every_part if asked is None else bool(asked)


def judge_surface(part: PartSpec, surface: SurfaceResult,
                  holes: list[HoleResult] | None = None) -> list[CharacteristicOutcome]:
    """The spec's surface criteria against the defects found: per criterion the largest
    defect of its kind where it applies (0 when none), with that defect's size
    uncertainty; each defect over a limit names the criterion it breaks. A rim
    criterion of a hole the scan did not find (``holes``) has no value (fails)."""
    out = []
    missing = {h.name for h in holes or [] if not h.found}
    for c in part.surface_characteristics():
        if c.kind in SURFACE_RIM_KINDS and c.hole_id in missing:
            out.append(CharacteristicOutcome(c.id, c.nominal, c.lower_limit, c.upper_limit, None, None, False))
            continue
        if c.hole_id == "surface":
            zone_ids = {z.id for z in part.surface.zones if getattr(z, f"max_{c.kind}_mm") is not None}
            mine = [d for d in surface.defects if d.kind == c.kind and d.hole is None and d.zone not in zone_ids]
        elif c.kind in SURFACE_RIM_KINDS:
            mine = [d for d in surface.defects if d.kind == c.kind and d.hole == c.hole_id]
        else:
            mine = [d for d in surface.defects if d.kind == c.kind and d.hole is None and d.zone == c.hole_id]
        worst = max(mine, key=lambda d: d.length_mm, default=None)
        value = 0.0 if worst is None else worst.length_mm
        u = None if worst is None else worst.size_u_mm
        for d in mine:
            if not c.conforms(d.length_mm) and d.rejects is None:
                d.rejects = c.id
        out.append(CharacteristicOutcome(c.id, c.nominal, c.lower_limit, c.upper_limit, value, u, c.conforms(value)))
    return out


def motion_limits(devices) -> dict[str, AxisLimits]:
    """The axes' limits as their drivers state them ("Z", "C"; an axis without is left out)."""
    out = {}
    for name in ("Z", "C"):
        ax = devices.axis(name)
        v, a = getattr(ax, "velocity_limit", None), getattr(ax, "acceleration_limit", None)
        if isinstance(v, (int, float)) and isinstance(a, (int, float)) and v > 0 and a > 0:
            out[name] = AxisLimits(float(v), float(a))
    return out


def camera_timing(devices):
    """The camera's sensor timing (``CameraTiming``), None when it has none."""
    return getattr(devices.camera, "timing", None) if devices.camera is not None else None


def devices_machine_time(steps, devices, time_scale: float | None):
    """The machine time of ledger ``steps`` with these devices' camera timing and axes'
    status polls (station.sequencer.cycle.machine_time)."""
    poll = {n: float(getattr(devices.axis(n), "poll_s", 0.0) or 0.0) for n in ("Z", "C")}
    return machine_time(steps, time_scale=time_scale, camera=camera_timing(devices), poll_s=poll)


def run_cycle(ledger_steps, devices, settings: ScanSettings, time_scale: float | None) -> dict:
    """The machine time of a run (with its breakdown) and, when the axes' limits and
    the camera's timing are known, the lower bound of the same plan and the ratio
    (station.sequencer.cycle)."""
    steps = list(ledger_steps)
    camera = camera_timing(devices)
    machine = devices_machine_time(steps, devices, time_scale)
    limits = motion_limits(devices)
    bound = None
    if camera is not None and set(limits) >= {"Z", "C"}:
        bound = lower_bound(steps, limits=limits, approach={"Z": settings.approach_z_mm, "C": settings.approach_c_deg},
                            settle_s=settings.settle_s, camera=camera)
    return cycle_summary(machine, bound)


async def ensure_ready(engine: Engine) -> None:
    """Home when needed; after a fault or a released e-stop, reset first. A ready
    engine's axes are asked first: a drive that faulted (or lost its reference) while
    nothing ran is reset and homed again, instead of failing the next move. Every job
    that moves the axes starts here (inspections, checks, calibrations)."""
    if engine.state == State.READY:
        try:
            problem = await engine.axes_problem()
        except DriverError as exc:
            await engine.report_fault(exc)
            raise PlanEnded("faulted", engine.reason) from exc
        if problem:
            engine.note(f"{problem}: reset and home before the inspection")
            await engine.reset()
    if engine.state in (State.FAULTED, State.ESTOPPED):
        await engine.reset()
    if engine.state == State.IDLE:
        await engine.home()


class InspectionService:
    """Runs and judges inspections; what it finds goes out as documents to
    ``documents``' subscribers (the store writer among them, required)."""

    def __init__(self, engine: Engine, documents: DocumentStream, model: StationModel, geometry: CameraGeometry,
                 settings: ScanSettings | None = None, *, traceability: dict | None = None,
                 time_scale: float | None = None, purpose: str = "production"):
        self.engine = engine
        self.documents = documents
        self.model = model
        self.geometry = geometry
        self.settings = settings or ScanSettings()
        self.traceability = traceability or {}
        #: simulation only: how much faster than real time the twin's motion runs (the
        #: machine time is then replayed, station.sequencer.cycle); None: measured
        self.time_scale = time_scale
        #: "production" or "master" (the start document's purpose)
        self.purpose = purpose
        #: where in the engine's ledger the running inspection's surface scan began
        self._surface_from: int | None = None

    async def ensure_ready(self) -> None:
        await ensure_ready(self.engine)

    async def inspect(self, part: PartSpec, serial: str, *, order_id: str | None = None,
                      idempotency_key: str | None = None, surface: bool | None = None) -> InspectionOutcome:
        """Inspect one part. ``surface``: scan the whole surface too (None: as the part
        spec says, ``[surface] every_part``)."""
        with_surface = wants_surface(part, surface)
        self._surface_from: int | None = None
        trace = {
            "software_version": __version__,
            "python": platform.python_version(),
            "model": self.model.name,
            # which numbers the compensation used: a change of any error value changes it
            "model_fingerprint": model_fingerprint(self.model),
            "camera_mm_per_px": self.geometry.mm_per_px,
            "part_spec": part.part_number,
            **self.traceability,
        }
        iid = str(uuid.uuid4())
        # the record begins here (the store writer is a required subscriber): a refused
        # start (a repeated idempotency key, a store that takes nothing) ends it all
        await self.documents.publish(InspectionStart(iid, part.part_number, serial, order_id, idempotency_key, trace,
                                                     self.purpose))
        try:
            await self.ensure_ready()
            plan = scan_plan(self.model, part, self.geometry, self.settings, motion_limits(self.engine.devices),
                             surface=with_surface)
            restore = self.engine.register_command(m.Emit, self._frame_command(iid))
            try:
                scan: ScanResult = await self.engine.run(plan)
            finally:
                restore()
        except PlanEnded as ended:
            state = "faulted" if ended.outcome == "faulted" else "aborted"
            outcome = InspectionOutcome(iid, part.part_number, serial, state, None, ended.reason, cycle=self._cycle())
            await self._stop(outcome, [])
            return outcome
        except BaseException as exc:
            # a bug or a cancellation before the plan ended: the subscribers must still
            # see the inspection end (the record is finished; the event log let go)
            why = str(exc) or "the inspection's task ended"
            reason = f"{type(exc).__name__}: {why}"
            outcome = InspectionOutcome(iid, part.part_number, serial, "faulted", None, reason)
            try:
                await self._stop(outcome, [])
            except Exception:  # noqa: BLE001 - the first error is the one to raise
                pass
            raise
        for r in scan.holes:
            await self.documents.publish(HoleDocument(iid, r))
        if scan.surface is not None:
            await self.documents.publish(SurfaceDocument(iid, scan.surface))
        outcome = self._judge(iid, part, serial, scan.holes, scan.surface)
        outcome.findings = scan.findings
        outcome.cycle = self._cycle(part)
        for c in outcome.characteristics:
            await self.documents.publish(CheckDocument(iid, c))
        return await self._stop(outcome, scan.holes)

    async def _stop(self, outcome: InspectionOutcome, holes: list[HoleResult]) -> InspectionOutcome:
        """Publish the stop; a result the store did not take is reported as the faulted
        inspection it is (and its faulted stop published), never as a result."""
        try:
            await self.documents.publish(InspectionStop(outcome.id, outcome, holes))
        except ResultNotStored as exc:
            faulted = InspectionOutcome(outcome.id, outcome.part_number, outcome.serial, "faulted", None, exc.reason,
                                        cycle=outcome.cycle)
            await self.documents.publish(InspectionStop(outcome.id, faulted, []))
            return faulted
        return outcome

    def _frame_command(self, iid: str):
        """The engine's command for the plan's ``Emit`` messages during this
        inspection: a frame's observation becomes a frame document; the surface scan's
        start marks where its part of the cycle begins."""
        async def emit(engine, msg: m.Emit) -> None:
            if msg.name == "surface":
                self._surface_from = len(engine.ledger.steps)
            elif msg.name == "frame":
                hole, index, frame = msg.body
                await self.documents.publish(FrameDocument(iid, hole, index, frame))

        return emit

    def _cycle(self, part: PartSpec | None = None) -> dict | None:
        """The last run's machine time (and lower bound); with a surface scan, its part
        of the time against the physical limit of covering the band (``surface``).
        None when it cannot be told (a bug there must not cost the result: the record
        is the product)."""
        try:
            out = run_cycle(self.engine.ledger.steps, self.engine.devices, self.settings, self.time_scale)
            if part is not None and self._surface_from is not None:
                out["surface"] = self._surface_cycle(part)
            return out
        except Exception as exc:  # noqa: BLE001
            self.engine.note(f"cycle time not computed: {type(exc).__name__}: {exc}")
            return None

    def _surface_cycle(self, part: PartSpec) -> dict:
        """The coverage scan's machine time (from its start to the end of the plan) and
        the physical limit of covering the band (``surface_scan.physical_limit``)."""
        devices = self.engine.devices
        steps = list(self.engine.ledger.steps)[self._surface_from:]
        camera = camera_timing(devices)
        machine = devices_machine_time(steps, devices, self.time_scale)
        out = {"machine_s": machine.total_s,
               "breakdown": {k: machine.breakdown.get(k, 0.0) for k in machine.breakdown}}
        limits = motion_limits(devices)
        if camera is not None and "C" in limits:
            lim = physical_limit(part.surface_band_mm(), self.geometry, SurfaceSettings().overlap_mm, camera,
                                 limits["C"], self.settings.settle_s)
            out.update(limit_frames=lim["frames"], limit_s=lim["limit_s"],
                       ratio=machine.total_s / lim["limit_s"] if lim["limit_s"] > 0 else None)
        return out

    def _judge(self, iid: str, part: PartSpec, serial: str, results: list[HoleResult],
               surface: SurfaceResult | None = None) -> InspectionOutcome:
        by_hole = {r.name: r for r in results}
        chars = []
        reasons = []
        for c in part.characteristics():
            r = by_hole.get(c.hole_id)
            if r is None or not r.found:
                value, u = None, None
                reasons.append(r.reason if r is not None else f"{c.hole_id} not scanned")
            elif c.kind == "position":
                value, u = r.position_mm, r.position_u_mm
            else:
                value, u = r.diameter_mm, r.diameter_u_mm
            ok = value is not None and math.isfinite(value) and c.conforms(value)
            chars.append(CharacteristicOutcome(c.id, c.nominal, c.lower_limit, c.upper_limit, value, u, ok))
        if surface is not None:
            surface_chars = judge_surface(part, surface, results)
            chars.extend(surface_chars)
            broken = [d for d in surface.defects if d.rejects]
            if broken:
                reasons.append("surface: " + "; ".join(
                    f"{d.kind} of {d.length_mm:.3f} mm at {d.axial_mm:.2f} mm, {round(d.angle_deg, 1) % 360.0:.1f} deg "
                    f"over {d.rejects}'s limit" for d in broken[:5]) + (f" (and {len(broken) - 5} more)"
                                                                         if len(broken) > 5 else ""))
        result = "pass" if all(c.passed for c in chars) else "fail"
        reason = "; ".join(dict.fromkeys(reasons))
        if result == "fail" and not reason:
            reason = "out of tolerance: " + ", ".join(c.id for c in chars if not c.passed)
        return InspectionOutcome(iid, part.part_number, serial, "complete", result, reason, chars, results,
                                 surface=surface)
