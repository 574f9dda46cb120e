"""Compensation of axis positioning errors: tables, segment models, files, validation.

Sign convention, everywhere in this package: the stored quantity is the ERROR
(deviation = actual − commanded, um for a linear axis, arcsec for a rotary one); the
correction to add to the command is its negative.  ``docs/compensation.md`` explains
the formats, including LinuxCNC's COMP_FILE types and their signs.
"""

from station.compensation.build import table_from_recording, table_from_statistics
from station.compensation.check import Problem, check, check_segments, check_table, failing
from station.compensation.files import (
    FormatError,
    read_compensation,
    render,
    segments_from_csv,
    table_from_csv,
    table_from_linuxcnc,
    table_to_csv,
    table_to_json,
    table_to_linuxcnc,
)
from station.compensation.segments import Segment, SegmentModel, segments_to_table, table_to_segments
from station.compensation.table import CompensationTable, TableError

__all__ = [
    "CompensationTable", "FormatError", "Problem", "Segment", "SegmentModel", "TableError", "check",
    "check_segments", "check_table", "failing", "read_compensation", "render", "segments_from_csv",
    "segments_to_table", "table_from_csv", "table_from_linuxcnc", "table_from_recording",
    "table_from_statistics", "table_to_csv", "table_to_json", "table_to_linuxcnc", "table_to_segments",
]
