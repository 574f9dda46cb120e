"""The fault matrix: every twin fault kind in every phase of an inspection, on the twins.

Each cell (``testkit.cells.matrix_cells``) switches its fault on (``testkit.injector``:
hooks on the engine's messages) when the inspection reaches its phase (homing, moving,
settling, capturing, measuring, storing), on the device that phase uses, and off after
the outcome (persistent) or after the first call it met (transient, ``-once``). Then,
in the SAME session (no restart), the next part is inspected. Every cell must end clean:

* persistent faults: the inspection is faulted, with the reason (naming the device and
  the error), stored as faulted with that reason and a fault (or, for the store, an
  alarm) event; a device fault after the scan (``storing``) leaves the result intact;
* transient faults within the retry budget (one garbled reply, one dropped link, a
  delay inside the timeout, one black or frozen frame): the inspection completes,
  passes, and every value is within 3 um of the twin's truth;
* the axes are at rest after the outcome, and the next inspection passes.

One session per fault kind (sessions are shared by that kind's cells, which is the
point: the station recovers without a restart, cell after cell). The bench
(``station bench reliability``) runs the same cells with repeats.
"""

from __future__ import annotations

import pytest

from station.parts import load_part
from testkit.cells import Cell, matrix_cells
from testkit.matrix import run_cell
from testkit.session import SessionThread

PART = "ZDZG-22.2-12.3851"
CELLS = sorted(matrix_cells(), key=lambda c: (c.kind, c.transient))


@pytest.fixture(scope="module")
def spec():
    return load_part(PART)


class _Sessions:
    """One live session at a time, for the kind of fault the cells now being run have."""

    def __init__(self, root):
        self.root = root
        self.kind = None
        self.current: SessionThread | None = None

    def get(self, kind: str) -> SessionThread:
        if kind != self.kind:
            self.close()
            self.current = SessionThread(self.root / kind).start()
            self.kind = kind
        return self.current

    def close(self):
        if self.current is not None:
            self.current.close()
            self.current, self.kind = None, None


@pytest.fixture(scope="module")
def sessions(tmp_path_factory):
    s = _Sessions(tmp_path_factory.mktemp("matrix"))
    yield s
    s.close()


@pytest.mark.timeout(240)
@pytest.mark.parametrize("cell", CELLS, ids=lambda c: c.id)
def test_cell(cell: Cell, sessions, spec):
    st = sessions.get(cell.kind)
    r = st.run(lambda s: run_cell(s, spec, cell, serial=f"SN-{cell.id}"), timeout=200)
    assert not r.error, r.error
    assert r.fired, "the fault was never switched on: the phase was not reached"
    assert not r.axes_moving_after, "an axis was still moving after the outcome"
    if cell.expected == "faulted":
        assert r.state == "faulted", f"{r.state} {r.result}: {r.reason}"
        assert r.result is None and r.reason
        assert r.stored_state == "faulted" and r.stored_reason == r.reason
        if cell.device == "store":
            assert "not stored" in r.reason and "StoreUnavailable" in r.reason
            assert r.alarm_events >= 1
            assert r.stored_chars == 0, "half-written: characteristics of a result that was not stored"
        else:
            assert r.fault_events >= 1
            assert r.engine_state == "faulted"
            device_name = {"Z": "Z:", "encoder": "encoder:", "camera": "camera", "vision": "vision"}[cell.device]
            assert device_name in r.reason, r.reason
    else:
        assert r.state == "complete" and r.result == "pass", f"{r.state} {r.result}: {r.reason}"
        assert r.max_error_mm <= 3e-3, f"{r.max_error_mm * 1e3:.2f} um from the truth"
        assert r.stored_state == "complete" and r.stored_chars == 4
    if cell.transient and cell.kind in ("garbage", "checksum", "black_frame", "frozen_frame"):
        assert r.retries >= 1, "the transient fault did not make the engine retry (it was never met)"
    # the same session inspects the next part correctly once the fault is cleared
    assert r.next_state == "complete" and r.next_result == "pass", f"{r.next_state}: {r.next_reason}"
    assert r.next_max_error_mm <= 3e-3
    assert r.problems() == []
