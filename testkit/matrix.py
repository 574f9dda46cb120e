"""One cell of the fault matrix, run on a live session, and what it observed.

:func:`run_cell` inspects a part with the cell's fault (:class:`testkit.injector.Injector`),
clears the fault, and inspects the next part in the same session; :meth:`CellResult.problems`
says what differs from what docs/reliability.md specifies.
"""

from __future__ import annotations

import asyncio
import dataclasses
import time
from dataclasses import dataclass

from testkit.cells import Cell
from testkit.injector import Injector

#: how close to the twin's truth a correct result is (docs/reliability.md: "within 3 um")
TRUTH_TOLERANCE_MM = 3e-3
#: the characteristics the sample part has: a complete record stores all of them
CHARACTERISTICS = 4
#: longest one inspection of the cell may take (a faulted one ends much sooner)
INSPECTION_TIMEOUT_S = 90.0


@dataclass
class CellResult:
    cell: Cell
    fired: bool = False
    state: str = ""
    result: str | None = None
    reason: str = ""
    engine_state: str = ""
    retries: int = 0
    stored_state: str = ""
    stored_reason: str = ""
    stored_chars: int = 0
    fault_events: int = 0
    alarm_events: int = 0
    axes_moving_after: bool = False
    max_error_mm: float = float("nan")
    next_state: str = ""
    next_result: str | None = None
    next_reason: str = ""
    next_max_error_mm: float = float("nan")
    wall_s: float = 0.0
    error: str = ""

    def problems(self) -> list[str]:
        """What is wrong with this cell's behaviour (empty: as specified)."""
        c, out = self.cell, []
        if self.error:
            out.append(f"raised {self.error}")
            return out
        if not self.fired:
            out.append("the fault was never switched on (phase not reached)")
        exp = c.expected
        if self.state != exp:
            out.append(f"ended {self.state!r} ({self.reason}), expected {exp!r}")
        if exp == "complete":
            if self.result != "pass":
                out.append(f"result {self.result!r}, expected pass ({self.reason})")
            if not self.max_error_mm <= TRUTH_TOLERANCE_MM:
                out.append(f"measured {self.max_error_mm * 1e3:.1f} um from the truth")
        if exp == "faulted":
            if not self.reason:
                out.append("no reason given")
            if self.stored_state != "faulted" or self.stored_reason != self.reason:
                out.append(f"stored as {self.stored_state!r} ({self.stored_reason!r})")
            if c.device != "store" and self.fault_events < 1:
                out.append("no fault event logged")
            if c.device == "store" and self.alarm_events < 1:
                out.append("no alarm logged")
            if c.device == "store" and self.stored_chars:
                out.append(f"half-written: {self.stored_chars} characteristics stored for a result not stored")
        elif self.stored_state != "complete" or self.stored_chars != CHARACTERISTICS:
            out.append(f"stored as {self.stored_state!r} with {self.stored_chars} characteristics")
        if self.axes_moving_after:
            out.append("an axis was still moving after the outcome")
        if (self.next_state != "complete" or self.next_result != "pass"
                or not self.next_max_error_mm <= TRUTH_TOLERANCE_MM):
            out.append(f"next inspection: {self.next_state} {self.next_result} ({self.next_reason})")
        return out

    def to_json(self) -> dict:
        d = dataclasses.asdict(self)
        d["cell"] = self.cell.id
        d["problems"] = self.problems()
        return d


def max_error_mm(out) -> float:
    """The largest distance of a measured characteristic from the twin's truth (NaN
    unless every characteristic has both)."""
    errs = [abs(c.measured - c.true_value) for c in out.characteristics
            if c.measured is not None and c.true_value is not None]
    return max(errs) if len(errs) == len(out.characteristics) and errs else float("nan")


async def run_cell(s, spec, cell: Cell, serial: str = "SN-CELL") -> CellResult:
    """Run one inspection with ``cell``'s fault, clear it, run the next one; observe everything."""
    from station.sequencer.engine import State

    res = CellResult(cell)
    t0 = time.perf_counter()
    if cell.phase == "homing" and s.engine.state == State.READY:
        await s.engine.reset()  # the next inspection homes first
    inj = Injector(s, cell)
    retries: list[str] = []
    unsubscribe = s.engine.subscribe(lambda ev: retries.append(ev.text) if ev.kind == "retry" else None)
    inj.install()
    try:
        try:
            out = await asyncio.wait_for(s.inspect(spec, serial), INSPECTION_TIMEOUT_S)
        except Exception as exc:  # noqa: BLE001 - the cell reports it
            res.error = f"{type(exc).__name__}: {exc}"
            return res
        res.fired = inj.fired > 0
        res.state, res.result, res.reason = out.state, out.result, out.reason
        res.engine_state = s.engine.state.value
        res.retries = len(retries)  # homing's included (retries_used counts a plan's only)
        res.max_error_mm = max_error_mm(out)
        twins = s.station.twins
        res.axes_moving_after = any(
            twins.call(lambda n=n: twins.station.physics[n].snapshot().moving) for n in ("Z", "C"))
    finally:
        inj.clear()
        unsubscribe()
    try:
        nxt = await asyncio.wait_for(s.inspect(spec, serial + "-NEXT"), INSPECTION_TIMEOUT_S)
        res.next_state, res.next_result, res.next_reason = nxt.state, nxt.result, nxt.reason
        res.next_max_error_mm = max_error_mm(nxt)
        nrec = await asyncio.to_thread(s.store.get, nxt.id)
        if nrec.state != nxt.state:
            res.next_state = f"{nxt.state} (stored {nrec.state})"
    except Exception as exc:  # noqa: BLE001
        res.next_state, res.next_reason = "raised", f"{type(exc).__name__}: {exc}"
    # the faulted inspection's record, as it stands once the station is running again
    rec = await asyncio.to_thread(s.store.get, out.id)
    res.stored_state, res.stored_reason, res.stored_chars = rec.state, rec.reason or "", len(rec.characteristics)
    events = await asyncio.to_thread(s.store.events, out.id, limit=1000)
    res.fault_events = sum(1 for e in events if e.kind == "fault")
    res.alarm_events = sum(1 for e in events if e.kind == "alarm")
    res.wall_s = time.perf_counter() - t0
    return res
