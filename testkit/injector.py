"""A matrix cell's fault, switched on and off through the station's public seams.

No device is wrapped and no private attribute replaced: where a phase begins is a
message of the plan, and the engine calls its message hooks (``Engine.add_msg_hook``)
with every message before it runs -- homing's too, since homing is the messages
``Enable``, ``Home`` and ``Wait``. The fault goes on, on the twin the phase uses
(``Cell.device``), just before:

=========  ==========================================================================
phase      message (or call)
=========  ==========================================================================
homing     the first ``Home("Z")``
moving     the first ``Move`` of Z
settling   the first ``Settle``
capturing  the first ``Capture``
measuring  the first ``ReadEncoder`` (the measurement frames)
storing    the first ``Store.finish`` (the store's method, replaced on the instance
           for the cell, and a SQLAlchemy event listener for the full disk)
=========  ==========================================================================

A persistent fault stays on until :meth:`Injector.clear` (after the outcome). A
transient one lasts one call: the first message that uses the faulted device while
it is on meets it; it goes off at the engine's next "retry" event (the engine's
events, ``Engine.subscribe``: the retry does not see it) or, when that message
succeeded without a retry (a delay inside the timeout), before the next message.

The vision stage's failure is a hook too: it raises at the first ``Measure`` (a hook
that raises fails the step, as the vision stage raising would).
"""

from __future__ import annotations

from typing import Any, Callable

from station.sequencer import messages as m
from testkit.cells import DRIVE_FAULT_CODE, LONG_DELAY_S, SHORT_DELAY_S, Cell

#: phase -> whether a message is the one where the phase begins
PHASE_STARTS: dict[str, Callable[[m.Msg], bool]] = {
    "homing": lambda msg: isinstance(msg, m.Home) and msg.axis == "Z",
    "moving": lambda msg: isinstance(msg, m.Move) and msg.axis == "Z",
    "settling": lambda msg: isinstance(msg, m.Settle),
    "capturing": lambda msg: isinstance(msg, m.Capture),
    "measuring": lambda msg: isinstance(msg, m.ReadEncoder),
}


def uses_device(device: str, msg: m.Msg) -> bool:
    """Whether the engine talks to ``device`` ("Z", "encoder", "camera") to carry out
    ``msg`` (a ``Wait`` without axes collects every axis with a move under way)."""
    if device == "camera":
        return isinstance(msg, m.Capture)
    if device == "encoder":
        return isinstance(msg, m.ReadEncoder)
    if isinstance(msg, (m.Move, m.Home, m.Enable, m.ReadAxis)):
        return msg.axis == device
    if isinstance(msg, m.Wait):
        return not msg.axes or device in msg.axes
    return False


class Injector:
    """Switches ``cell``'s fault on when the inspection reaches its phase, on the twin
    the phase uses, and off again after one call (transient) or on :meth:`clear`."""

    def __init__(self, session, cell: Cell):
        self.s = session
        self.cell = cell
        #: times the fault was switched on (0: the phase was never reached)
        self.fired = 0
        self.active = False
        #: messages that used the faulted device while the fault was on
        self.met = 0
        #: transient: a message met the fault and has not ended yet
        self._meeting = False
        #: what :meth:`clear` undoes: hooks to remove, listeners to unsubscribe, ...
        self._undo: list[Callable[[], None]] = []

    # ------------------------------------------------------------------ the fault itself
    def _switch(self):
        """The faulted twin's ``FaultSwitch`` and the twins' thread to change it on (None:
        the camera twin lives in the session's own loop)."""
        twins = self.s.station.twins
        dev = self.cell.device
        if dev == "camera":
            return self.s.station.camera.faults, None
        if dev == "encoder":
            return twins.station.encoder.faults, twins
        return twins.station.drives[dev].faults, twins

    def fault_on(self) -> None:
        from sim.faults import FaultKind

        if self.active:
            return
        self.fired += 1
        self.active = True
        if self.cell.device not in ("Z", "encoder", "camera"):
            return
        kind = self.cell.kind
        switch, twins = self._switch()
        params: dict[str, Any] = {}
        if kind == "delay":
            params["delay_s"] = (SHORT_DELAY_S if self.cell.transient else LONG_DELAY_S)[self.cell.device]
        if kind == "drive_fault":
            params["code"] = DRIVE_FAULT_CODE
        fn = lambda: switch.activate(FaultKind(kind), **params)  # noqa: E731
        twins.call(fn) if twins is not None else fn()

    def fault_off(self) -> None:
        self._meeting = False
        if not self.active:
            return
        self.active = False
        if self.cell.device not in ("Z", "encoder", "camera"):
            return
        switch, twins = self._switch()
        twins.call(switch.clear) if twins is not None else switch.clear()

    # ------------------------------------------------------------------ the seams
    def install(self) -> None:
        """Hook the cell's trigger into the engine (or the store, for ``storing``)."""
        eng = self.s.engine
        if self.cell.kind == "vision_error":
            self._undo.append(eng.add_msg_hook(self._vision_hook))
        elif self.cell.phase == "storing":
            self._install_store()
        else:
            self._undo.append(eng.add_msg_hook(self._msg_hook))
            if self.cell.transient:
                self._undo.append(eng.subscribe(self._on_event))

    def _msg_hook(self, msg: m.Msg) -> None:
        if self._meeting:
            # the message that met the transient fault is over, and no retry came
            self.fault_off()
        if not self.fired and PHASE_STARTS[self.cell.phase](msg):
            self.fault_on()
        if self.active and uses_device(self.cell.device, msg):
            self.met += 1
            self._meeting = self.cell.transient

    def _on_event(self, ev) -> None:
        """The engine retries the call that met the transient fault: the retry must not see it."""
        if ev.kind == "retry" and self._meeting:
            self.fault_off()

    def _vision_hook(self, msg: m.Msg) -> None:
        if not isinstance(msg, m.Measure):
            return
        if not self.fired:
            self.fault_on()
        if self.active:
            self.met += 1
            raise RuntimeError("vision stage crashed (injected)")

    def _install_store(self) -> None:
        """``storing``: the fault goes on at the first ``finish``, the store's commit of
        the result (replaced on this store instance for the cell; :meth:`clear` takes
        the replacement away and the class's method shows again)."""
        store = self.s.store
        orig = store.finish
        inj = self

        def finish(*a, **k):
            first = not inj.fired
            if first and inj.cell.kind == "store_unavailable":
                inj.fired += 1
                from station.store import StoreUnavailable

                raise StoreUnavailable("results store: database is locked (injected: the commit failed once)")
            if first and inj.cell.kind == "store_disk_full":
                inj.fired += 1
                inj._fill_disk()
            elif first:
                inj.fault_on()
            return orig(*a, **k)

        store.finish = finish
        self._undo.append(lambda: store.__dict__.pop("finish", None))

    def _fill_disk(self) -> None:
        """The disk holding the database is full: from now on every INSERT INTO event (the
        last statement of ``finish``'s transaction, after its characteristics and the
        state change) fails as the database fails it, so the transaction must roll back
        whole: SQLite's "database or disk is full", PostgreSQL's "could not extend file
        ...: No space left on device" (SQLSTATE 53100), each raised as its own driver's
        exception. (SQLite's max_page_count cannot show this: the few rows of a finish
        fit in the free space of pages the database already has.)"""
        from sqlalchemy import event

        engine = self.s.store.engine
        if engine.dialect.name == "postgresql":
            import psycopg.errors

            def error():
                return psycopg.errors.DiskFull('could not extend file "base/16384/16390": No space left on device')
        else:
            import sqlite3

            def error():
                return sqlite3.OperationalError("database or disk is full")

        def full(conn, cursor, statement, parameters, context, executemany):
            if statement.lstrip().upper().startswith("INSERT INTO EVENT"):
                raise error()

        event.listen(engine, "before_cursor_execute", full)
        self.active = True
        self._undo.append(lambda: event.remove(engine, "before_cursor_execute", full))

    def clear(self) -> None:
        """The cause is gone: switch the fault off and take the hooks away."""
        self.fault_off()
        for undo in reversed(self._undo):
            undo()
        self._undo.clear()
        self.active = False
