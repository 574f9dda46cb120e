"""One inspection, from the part spec to the committed result.

The service owns the engine and the store: it begins the inspection record, runs
the bore scan, judges every characteristic, saves the hole crops and commits the
result (all characteristics and the final state in one transaction) before it
reports anything. A plan that ends early (stopped, aborted, faulted) is recorded
with its reason; a crash leaves the record ``running``, which the next start of
the store marks ``interrupted``.

Decision rule: simple acceptance (ISO 14253-1's "shared risk"): a value inside the
limits, inclusive, conforms; the expanded uncertainty is recorded beside it.
"""

from __future__ import annotations

import asyncio
import hashlib
import math
import platform
from dataclasses import dataclass, field
from typing import Callable, Mapping

from station import __version__
from station.inspection.scan import (CameraGeometry, HoleResult, HoleTarget, ScanFinding, ScanResult, ScanSettings,
                                     bore_scan)
from station.inspection.scanlog import write_scan_log
from station.kinematics.model import StationModel
from station.motion import AxisLimits
from station.parts.spec import PartSpec
from drivers.interfaces import DriverError
from station.sequencer.cycle import cycle_summary, lower_bound, machine_time
from station.sequencer.engine import Engine, EngineEvent, PlanEnded, State
from station.store.errors import StoreError
from station.store.records import FindingRecord, Measurement


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
                "alarms": [a.to_json() for a in self.alarms]}


#: per store (by id): inspections whose record could not be finished (store failure),
#: with the reason to finish them with once the store takes writes again
_UNFINISHED: dict[int, dict[str, str]] = {}


def model_fingerprint(model: StationModel) -> str:
    """16 hex digits that change with any number of the model (its version for a record)."""
    return hashlib.sha256(repr((model.endoscope_offset_mm, model.table_offset_mm, sorted(model.static_errors.items()),
                                sorted(model.motions.items()))).encode()).hexdigest()[:16]


def hole_targets(part: PartSpec) -> list[HoleTarget]:
    """The spec's holes with their search zones: the position limits widened by the
    part's axial placement uncertainty, the drawing's angular band (docs/part-specs.md)."""
    pad_mm = part.placement.axial_mm
    return [HoleTarget(h.id, h.position.nominal, h.angle_deg, h.diameter.nominal,
                       axial_lo_mm=h.position.lower_limit - pad_mm, axial_hi_mm=h.position.upper_limit + pad_mm,
                       angle_half_deg=h.angle_search_deg,
                       diameter_lo_mm=h.diameter.lower_limit, diameter_hi_mm=h.diameter.upper_limit,
                       axial_lo_tol_mm=h.position.lower_limit, axial_hi_tol_mm=h.position.upper_limit)
            for h in part.holes]


def scan_plan(model: StationModel, part: PartSpec, geometry: CameraGeometry, settings: ScanSettings,
              motion: Mapping[str, AxisLimits] | None = None):
    """The bore scan of ``part`` (a plan returning a ``ScanResult``)."""
    return bore_scan(model, hole_targets(part), geometry, settings, datum=part.placement.angular_datum,
                     placement_angle_deg=part.placement.angle_deg, motion=motion)


def motion_limits(devices) -> dict[str, AxisLimits]:
    """The axes' limits as their drivers state them ("Z", "C"; an axis without is left out)."""
    out = {}
    for name in ("Z", "C"):
        ax = devices.axis(name)
        v, a = getattr(ax, "velocity_limit", None), getattr(ax, "acceleration_limit", None)
        if isinstance(v, (int, float)) and isinstance(a, (int, float)) and v > 0 and a > 0:
            out[name] = AxisLimits(float(v), float(a))
    return out


def run_cycle(ledger_steps, devices, settings: ScanSettings, time_scale: float | None) -> dict:
    """The machine time of a run (with its breakdown) and, when the axes' limits and
    the camera's timing are known, the lower bound of the same plan and the ratio
    (station.sequencer.cycle)."""
    steps = list(ledger_steps)
    camera = getattr(devices.camera, "timing", None) if devices.camera is not None else None
    poll = {n: float(getattr(devices.axis(n), "poll_s", 0.0) or 0.0) for n in ("Z", "C")}
    machine = machine_time(steps, time_scale=time_scale, camera=camera, poll_s=poll)
    limits = motion_limits(devices)
    bound = None
    if camera is not None and set(limits) >= {"Z", "C"}:
        bound = lower_bound(steps, limits=limits, approach={"Z": settings.approach_z_mm, "C": settings.approach_c_deg},
                            settle_s=settings.settle_s, camera=camera)
    return cycle_summary(machine, bound)


class InspectionService:
    def __init__(self, engine: Engine, store, model: StationModel, geometry: CameraGeometry,
                 settings: ScanSettings | None = None, *, traceability: dict | None = None,
                 truth: Callable[[str, str], float | None] | None = None, time_scale: float | None = None):
        self.engine = engine
        self.store = store
        self.model = model
        self.geometry = geometry
        self.settings = settings or ScanSettings()
        self.traceability = traceability or {}
        #: simulation only: (hole id, kind) -> the twin's true value
        self.truth = truth
        #: simulation only: how much faster than real time the twin's motion runs (the
        #: machine time is then replayed, station.sequencer.cycle); None: measured
        self.time_scale = time_scale

    async def ensure_ready(self) -> None:
        """Home when needed; after a fault or a released e-stop, reset first. A ready
        engine's axes are asked first: a drive that faulted (or lost its reference)
        while nothing ran is reset and homed again, instead of failing the next move."""
        if self.engine.state == State.READY:
            try:
                problem = await self.engine.axes_problem()
            except DriverError as exc:
                await self.engine._fault(exc)
                raise PlanEnded("faulted", self.engine.reason) from exc
            if problem:
                self.engine._emit("note", f"{problem}: reset and home before the inspection")
                await self.engine.reset()
        if self.engine.state in (State.FAULTED, State.ESTOPPED):
            await self.engine.reset()
        if self.engine.state == State.IDLE:
            await self.engine.home()

    async def inspect(self, part: PartSpec, serial: str, *, order_id: str | None = None,
                      idempotency_key: str | None = None) -> InspectionOutcome:
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
        await self._close_unfinished()
        iid = await asyncio.to_thread(self.store.begin_inspection, part.part_number, serial=serial, order_id=order_id,
                                      traceability=trace, idempotency_key=idempotency_key)
        log = lambda ev: self._log(iid, ev)  # noqa: E731
        self.engine.subscribe(log)
        try:
            try:
                await self.ensure_ready()
                plan = scan_plan(self.model, part, self.geometry, self.settings, motion_limits(self.engine.devices))
                scan: ScanResult = await self.engine.run(plan)
            except PlanEnded as ended:
                state = "faulted" if ended.outcome == "faulted" else "aborted"
                cycle = self._cycle()
                await asyncio.to_thread(self.store.finish, iid, state, None, ended.reason,
                                        **self._cycle_fields(cycle))
                return InspectionOutcome(iid, part.part_number, serial, state, None, ended.reason, cycle=cycle)
            results = scan.holes
            outcome = self._judge(iid, part, serial, results)
            outcome.findings = scan.findings
            outcome.cycle = self._cycle()
            measurements = [Measurement(c.id, c.nominal, c.lower_limit, c.upper_limit, c.measured, c.passed,
                                        uncertainty_k2=c.uncertainty_k2, true_value=c.true_value)
                            for c in outcome.characteristics]
            try:
                for r in results:
                    if r.crop is not None and r.crop.size:
                        await asyncio.to_thread(self.store.add_image, iid, r.name, f"{r.name}", r.crop)
                await asyncio.to_thread(self.store.finish, iid, "complete", outcome.result, outcome.reason or None,
                                        measurements=measurements,
                                        findings=[FindingRecord.of(f) for f in scan.findings],
                                        **self._cycle_fields(outcome.cycle))
            except StoreError as exc:
                return await self._not_stored(iid, part, serial, exc)
            # after the commit: the log is for discovery, the result must not wait on it
            try:
                await asyncio.to_thread(write_scan_log, self.store.data_dir, iid, results)
            except OSError as exc:
                self.store.log_event("alarm", f"scan log not written: {exc}", iid)
            return outcome
        finally:
            self.engine.unsubscribe(log)

    def _cycle(self) -> dict | None:
        """The last run's machine time (and lower bound); None when it cannot be told
        (a bug there must not cost the result: the record is the product)."""
        try:
            return run_cycle(self.engine.ledger.steps, self.engine.devices, self.settings, self.time_scale)
        except Exception as exc:  # noqa: BLE001
            self.engine._emit("note", f"cycle time not computed: {type(exc).__name__}: {exc}")
            return None

    @staticmethod
    def _cycle_fields(cycle: dict | None) -> dict:
        if cycle is None or not math.isfinite(cycle.get("machine_s", math.nan)):
            return {}
        return {"machine_s": cycle["machine_s"], "cycle": cycle}

    async def _not_stored(self, iid: str, part: PartSpec, serial: str, exc: StoreError) -> InspectionOutcome:
        """The result could not be committed: nothing of it is reported as a result. The
        record is finished ``faulted`` with the reason and an alarm when the store takes
        that much; when it takes nothing, it stays ``running`` and the next inspection
        (or the next start: recovery) closes it."""
        reason = f"result not stored: {type(exc).__name__}: {exc}"
        self._alarm(iid, reason)
        try:
            await asyncio.to_thread(self.store.finish, iid, "faulted", None, reason)
        except StoreError:
            _UNFINISHED.setdefault(id(self.store), {})[iid] = reason
        return InspectionOutcome(iid, part.part_number, serial, "faulted", None, reason)

    def _alarm(self, iid: str | None, text: str) -> None:
        try:
            self.store.log_event("alarm", text, iid)
        except Exception:  # noqa: BLE001 - the store is what failed; the outcome carries the reason
            pass

    async def _close_unfinished(self) -> None:
        """Records an earlier inspection could not finish because the store failed."""
        pending = _UNFINISHED.get(id(self.store)) or {}
        for iid, reason in sorted(pending.items()):
            try:
                await asyncio.to_thread(self.store.finish, iid, "faulted", None, reason)
                self._alarm(iid, "closed as faulted once the results store was back")
            except StoreError:
                continue
            pending.pop(iid, None)

    def _judge(self, iid: str, part: PartSpec, serial: str, results: list[HoleResult]) -> InspectionOutcome:
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
            truth = self.truth(c.hole_id, c.kind) if self.truth is not None else None
            chars.append(CharacteristicOutcome(c.id, c.nominal, c.lower_limit, c.upper_limit, value, u, ok, truth))
        result = "pass" if all(c.passed for c in chars) else "fail"
        reason = "; ".join(dict.fromkeys(reasons))
        if result == "fail" and not reason:
            reason = "out of tolerance: " + ", ".join(c.id for c in chars if not c.passed)
        return InspectionOutcome(iid, part.part_number, serial, "complete", result, reason, chars, results)

    def _log(self, iid: str, ev: EngineEvent) -> None:
        if ev.kind in ("state", "fault", "retry", "note"):
            try:
                self.store.log_event(ev.kind, f"{ev.state.value}: {ev.text}" if ev.kind == "state" else ev.text, iid)
            except Exception:  # noqa: BLE001 - the event log must not stop the inspection
                pass
