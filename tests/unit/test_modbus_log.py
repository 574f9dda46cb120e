"""pymodbus' frame dump is cut off its error records (``drivers.modbus_axis._NoFrameDump``)."""

from __future__ import annotations

import logging

from pymodbus.logging import Log

import drivers.modbus_axis  # noqa: F401  (puts the filter on pymodbus' logger)


def test_an_error_keeps_its_line_and_loses_the_process_wide_frame_dump(caplog, monkeypatch):
    caplog.set_level(logging.INFO, logger="pymodbus")
    # the dump is class-wide: earlier tests' links left their frames in it
    monkeypatch.setattr(Log, "frame_dump", [])
    for i in range(3):  # frames of any link of the process, kept while pymodbus is not at DEBUG
        Log.transport_dump(Log.SEND_DATA, bytes([0, i, 0, 0, 0, 6, 1, 3]), b"")
    Log.error("Connection to ({}, {}) lost: {}", "127.0.0.1", 5020, "reset")
    (rec,) = [r for r in caplog.records if r.name == "pymodbus.logging"]
    text = rec.getMessage()
    assert text.startswith("Connection to (127.0.0.1, 5020) lost: reset")
    assert ">>>>>" not in text and "\n" not in text
    assert "3 frames of pymodbus' process-wide dump cut" in text
    # a record with nothing appended passes unchanged
    caplog.clear()
    Log.warning("plain {}", "warning")
    (rec,) = [r for r in caplog.records if r.name == "pymodbus.logging"]
    assert rec.getMessage() == "plain warning"


def test_the_filter_is_put_on_once():
    drivers.modbus_axis._quiet_frame_dumps()
    filters = [f for f in logging.getLogger("pymodbus.logging").filters if type(f).__name__ == "_NoFrameDump"]
    assert len(filters) == 1
