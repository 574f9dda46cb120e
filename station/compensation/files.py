"""Compensation files: the station's CSV and JSON, segment CSV, LinuxCNC COMP_FILE types 0 and 1.

Why one module: ``station compensation check/convert`` must read whatever an
engineer hands it and write what the controller wants, and every reader must name
the file and line of anything it cannot read.  Formats (``docs/compensation.md``
has the details and a worked LinuxCNC example):

* **table CSV** -- ``# key: value`` metadata (``kind``, ``mode``, ``backlash``,
  ``axis``), then ``position,error_up,error_down`` (bidirectional) or
  ``position,error_mean`` (averaged); errors are actual − commanded in um / arcsec.
* **segment CSV** -- ``x_from,x_to,slope,intercept``; ``#`` lines are comments or
  ``# key: value`` metadata (``kind``, ``quantity``).
* **JSON** -- ``{"format": "station.compensation-table", ...}`` or
  ``{"format": "station.compensation-segments", ...}``.
* **LinuxCNC** ``[JOINT_n]COMP_FILE`` with ``COMP_FILE_TYPE`` 0 or 1: three numbers per
  line in machine units (mm or degrees assumed).  Type 0: ``nominal  actual-going-up
  actual-going-down``; type 1: ``nominal  trim-up  trim-down`` where a trim is the amount
  LinuxCNC adds to the commanded motor position, i.e. the correction (= −error).

Values are written so that reading them back gives the same doubles bit for bit:
positions as Python ``repr``; errors converted to machine units with exact decimal
arithmetic, using the fewest digits that still round-trip (see ``_encode``).
"""

from __future__ import annotations

import csv
import io
import json
import math
from decimal import Decimal, localcontext
from pathlib import Path
from typing import Any

import numpy as np

from station.recording import LocatedInputError, read_text_file
from station.compensation.check import Problem
from station.compensation.segments import QUANTITIES, Segment, SegmentModel
from station.compensation.table import ERROR_UNIT, POSITION_UNIT, CompensationTable
from station.effects import k_for_kind

TABLE_JSON_FORMAT = "station.compensation-table"
SEGMENTS_JSON_FORMAT = "station.compensation-segments"
JSON_VERSION = 1

#: LinuxCNC's motion controller holds at most this many entries per joint
#: (``EMCMOT_COMP_SIZE`` in src/emc/motion/motion.h); further lines are rejected.
LINUXCNC_MAX_ENTRIES = 256

#: file extensions taken for LinuxCNC compensation files when no --format is given
LINUXCNC_EXTENSIONS = (".comp", ".txt", ".tbl", ".cmp")

READ_FORMATS = ("csv", "segments", "json", "linuxcnc", "linuxcnc0", "linuxcnc1")
WRITE_FORMATS = ("csv", "json", "linuxcnc0", "linuxcnc1")

#: decimal working precision for unit conversion: far beyond a double's 17 digits
_DECIMAL_PRECISION = 80
#: most significant digits tried when looking for the shortest round-tripping text
_MAX_DIGITS = 40


class FormatError(LocatedInputError):
    """A compensation file that cannot be read; the message names file, line and column."""


# ---------------------------------------------------------------- exact unit conversion

def _decode(text: str, scale: float, base: str | None, negate: bool) -> float:
    """Deviation units from machine-unit text: ``±(text − base) · scale`` in exact decimal."""
    with localcontext() as ctx:
        ctx.prec = _DECIMAL_PRECISION
        value = Decimal(text) - (Decimal(base) if base is not None else 0)
        value = value * Decimal(repr(scale))
        if negate:
            value = -value
        return float(value)


def _encode(deviation: float, scale: float, base: str | None = None, negate: bool = False) -> str:
    """Machine-unit text of ``base ± deviation / scale`` that decodes to ``deviation`` exactly.

    ``base`` is the nominal position's text (type 0 writes actual positions);
    ``negate`` writes the correction (type 1 trims).  Shortest text that round-trips,
    so a linear table (scale 1000: an exact decimal shift) gets plain short numbers and
    a rotary one (scale 3600) only as many digits as its doubles need.
    """
    if not math.isfinite(deviation):
        raise ValueError(f"cannot write a non-finite value ({deviation!r})")
    d = Decimal(repr(-deviation if negate else deviation))
    for digits in range(1, _MAX_DIGITS + 1):
        with localcontext() as ctx:
            ctx.prec = digits
            quotient = d / Decimal(repr(scale))
        with localcontext() as ctx:
            ctx.prec = _DECIMAL_PRECISION
            value = quotient + (Decimal(base) if base is not None else 0)
            text = format(value.normalize() if value != 0 else Decimal(0), "f")
        if _decode(text, scale, base, negate) == deviation:
            return text
    raise ValueError(f"no decimal text of {_MAX_DIGITS} digits round-trips {deviation!r}")  # pragma: no cover


# ---------------------------------------------------------------- CSV helpers

def _split_comments(text: str) -> tuple[dict[str, str], list[tuple[int, str]]]:
    """Metadata from ``# key: value`` lines; the other non-blank, non-# lines with line numbers."""
    metadata: dict[str, str] = {}
    rows: list[tuple[int, str]] = []
    for number, raw in enumerate(text.splitlines(), start=1):
        stripped = raw.strip()
        if not stripped:
            continue
        if stripped.startswith("#"):
            body = stripped[1:].strip()
            key, sep, value = body.partition(":")
            if sep and key.strip() and " " not in key.strip():
                metadata[key.strip()] = value.strip()
            continue
        rows.append((number, raw))
    return metadata, rows


def _number(text: str, source: str, line: int, column: str) -> float:
    """A float; 'nan'/'inf' are accepted here so that :func:`check` can name them."""
    try:
        return float(text.strip())
    except ValueError:
        raise FormatError(source, line, column, f"not a number: {text.strip()!r}") from None


def _metadata_number(metadata: dict[str, str], key: str, source: str, default: float = 0.0) -> float:
    """A number from the ``# key: value`` lines; a bad one is a FormatError naming the key."""
    text = metadata.get(key, "")
    if not text:
        return default
    try:
        return float(text)
    except ValueError:
        raise FormatError(source, None, key, f"metadata {key!r} is not a number: {text!r}") from None


def _kind_of(metadata: dict[str, str], source: str, default: str = "linear") -> str:
    kind = metadata.get("kind", default)
    if kind not in ERROR_UNIT:
        raise FormatError(source, None, None, f"metadata 'kind' must be linear or rotary, not {kind!r}")
    return kind


def _header(rows, source: str, what: str) -> tuple[int, list[str]]:
    if not rows:
        raise FormatError(source, None, None, f"no header row (expected {what})")
    number, raw = rows[0]
    return number, [h.strip() for h in next(csv.reader([raw]))]


def _csv_columns(rows, header: list[str], wanted: tuple[str, ...], source: str) -> tuple[dict[str, np.ndarray], np.ndarray]:
    idx = {h: i for i, h in enumerate(header)}
    columns: dict[str, list[float]] = {c: [] for c in wanted}
    lines: list[int] = []
    for number, raw in rows:
        fields = next(csv.reader([raw]))
        if len(fields) != len(header):
            raise FormatError(source, number, None, f"{len(fields)} fields, the header has {len(header)}")
        for c in wanted:
            columns[c].append(_number(fields[idx[c]], source, number, c))
        lines.append(number)
    if not lines:
        raise FormatError(source, None, None, "no data rows after the header")
    return {c: np.asarray(v, dtype=float) for c, v in columns.items()}, np.asarray(lines, dtype=int)


# ---------------------------------------------------------------- table CSV

def table_to_csv(table: CompensationTable) -> str:
    buf = io.StringIO()
    buf.write(f"# kind: {table.kind}\n")
    if table.axis:
        buf.write(f"# axis: {table.axis}\n")
    buf.write(f"# mode: {table.mode}\n")
    if table.mode == "averaged":
        buf.write(f"# backlash: {table.backlash!r}\n")
    buf.write(f"# position in {table.position_unit}; error = actual - commanded in {table.error_unit}; "
              "the correction to apply is -error\n")
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(("position",) + table.columns)
    cols = [getattr(table, c) for c in table.columns]
    for i in range(len(table)):
        w.writerow([repr(float(table.position[i]))] + [repr(float(c[i])) for c in cols])
    return buf.getvalue()


def table_from_csv(text: str, source: str = "<text>") -> CompensationTable:
    metadata, rows = _split_comments(text)
    header_line, header = _header(rows, source, "position,error_up,error_down or position,error_mean")
    kind = _kind_of(metadata, source)
    if "position" not in header:
        raise FormatError(source, header_line, "position", "required column is missing; header is " + ",".join(header))
    if "error_mean" in header:
        mode, wanted = "averaged", ("position", "error_mean")
    elif "error_up" in header and "error_down" in header:
        mode, wanted = "bidirectional", ("position", "error_up", "error_down")
    else:
        raise FormatError(source, header_line, None,
                          "need columns error_up and error_down (bidirectional) or error_mean (averaged); "
                          "header is " + ",".join(header))
    if metadata.get("mode", mode) != mode:
        raise FormatError(source, None, None, f"metadata says mode {metadata['mode']!r} but the columns are {mode}")
    columns, lines = _csv_columns(rows[1:], header, wanted, source)
    common = dict(kind=kind, position=columns["position"], axis=metadata.get("axis", ""), line=lines, source=source)
    backlash = _metadata_number(metadata, "backlash", source)
    if mode == "averaged":
        return CompensationTable.averaged(error_mean=columns["error_mean"], backlash=backlash, **common)
    if backlash != 0.0:
        raise FormatError(source, None, None, "a bidirectional table carries its reversal in its columns; "
                                              "remove the 'backlash' metadata")
    return CompensationTable.bidirectional(error_up=columns["error_up"], error_down=columns["error_down"], **common)


# ---------------------------------------------------------------- segment CSV

SEGMENT_COLUMNS = ("x_from", "x_to", "slope", "intercept")


def segments_from_csv(text: str, source: str = "<text>") -> SegmentModel:
    metadata, rows = _split_comments(text)
    header_line, header = _header(rows, source, ",".join(SEGMENT_COLUMNS))
    for c in SEGMENT_COLUMNS:
        if c not in header:
            raise FormatError(source, header_line, c, "required column is missing; header is " + ",".join(header))
    columns, lines = _csv_columns(rows[1:], header, SEGMENT_COLUMNS, source)
    quantity = metadata.get("quantity", "error")
    if quantity not in QUANTITIES:
        raise FormatError(source, None, None, f"metadata 'quantity' must be error or correction, not {quantity!r}")
    segs = tuple(Segment(*(float(columns[c][i]) for c in SEGMENT_COLUMNS), line=int(lines[i]))
                 for i in range(lines.size))
    return SegmentModel(segs, kind=_kind_of(metadata, source), quantity=quantity, source=source, metadata=metadata)


def segments_to_csv(model: SegmentModel) -> str:
    buf = io.StringIO()
    buf.write(f"# kind: {model.kind}\n# quantity: {model.quantity}\n")
    buf.write("# y = slope * x + intercept on [x_from, x_to]\n")
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(SEGMENT_COLUMNS)
    for s in model.segments:
        w.writerow([repr(float(getattr(s, c))) for c in SEGMENT_COLUMNS])
    return buf.getvalue()


# ---------------------------------------------------------------- JSON

def _floats(values, source: str, key: str) -> np.ndarray:
    if not isinstance(values, list):
        raise FormatError(source, None, key, "expected a list of numbers")
    try:
        return np.array([math.nan if v is None else float(v) for v in values], dtype=float)
    except (TypeError, ValueError):
        raise FormatError(source, None, key, "expected a list of numbers") from None


def table_to_json(table: CompensationTable) -> str:
    doc: dict[str, Any] = {
        "format": TABLE_JSON_FORMAT, "version": JSON_VERSION, "kind": table.kind, "axis": table.axis,
        "mode": table.mode, "position_unit": table.position_unit, "error_unit": table.error_unit,
        "sign": "error = actual - commanded; correction to apply = -error",
        "position": table.position.tolist(),
    }
    for c in table.columns:
        doc[c] = getattr(table, c).tolist()
    if table.mode == "averaged":
        doc["backlash"] = table.backlash
    try:
        return json.dumps(doc, indent=2, allow_nan=False) + "\n"
    except ValueError:
        raise ValueError("the table holds NaN or infinite values; run `station compensation check` on it") from None


def segments_to_json(model: SegmentModel) -> str:
    doc = {"format": SEGMENTS_JSON_FORMAT, "version": JSON_VERSION, "kind": model.kind, "quantity": model.quantity,
           "segments": [{c: getattr(s, c) for c in SEGMENT_COLUMNS} for s in model.segments]}
    return json.dumps(doc, indent=2, allow_nan=False) + "\n"


def from_json(text: str, source: str = "<text>") -> CompensationTable | SegmentModel:
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise FormatError(source, exc.lineno, None, f"not valid JSON ({exc.msg})") from None
    if not isinstance(doc, dict):
        raise FormatError(source, None, None, "expected a JSON object")
    kind = doc.get("kind", "linear")
    if kind not in ERROR_UNIT:
        raise FormatError(source, None, "kind", f"must be linear or rotary, not {kind!r}")
    fmt = doc.get("format")
    if fmt == SEGMENTS_JSON_FORMAT or (fmt is None and "segments" in doc):
        segs = []
        for i, s in enumerate(doc.get("segments", [])):
            try:
                segs.append(Segment(*(math.nan if s[c] is None else float(s[c]) for c in SEGMENT_COLUMNS)))
            except (KeyError, TypeError, ValueError):
                raise FormatError(source, None, f"segments[{i}]", "needs numbers x_from, x_to, slope, intercept") from None
        quantity = doc.get("quantity", "error")
        if quantity not in QUANTITIES:
            raise FormatError(source, None, "quantity", f"must be error or correction, not {quantity!r}")
        return SegmentModel(tuple(segs), kind=kind, quantity=quantity, source=source)
    if fmt not in (TABLE_JSON_FORMAT, None):
        raise FormatError(source, None, "format", f"unknown format {fmt!r}")
    if "position" not in doc:
        raise FormatError(source, None, "position", "missing")
    position = _floats(doc["position"], source, "position")
    common = dict(kind=kind, position=position, axis=str(doc.get("axis", "")), source=source)
    try:
        if "error_mean" in doc:
            backlash = doc.get("backlash", 0.0)
            return CompensationTable.averaged(error_mean=_floats(doc["error_mean"], source, "error_mean"),
                                              backlash=math.nan if backlash is None else float(backlash), **common)
        if "error_up" in doc and "error_down" in doc:
            return CompensationTable.bidirectional(error_up=_floats(doc["error_up"], source, "error_up"),
                                                   error_down=_floats(doc["error_down"], source, "error_down"),
                                                   **common)
    except (TypeError, ValueError) as exc:
        if isinstance(exc, FormatError):
            raise
        raise FormatError(source, None, None, str(exc)) from None
    raise FormatError(source, None, None, "needs error_up and error_down, or error_mean")


# ---------------------------------------------------------------- LinuxCNC

def table_to_linuxcnc(table: CompensationTable, comp_file_type: int) -> str:
    """Text of a LinuxCNC ``COMP_FILE`` of ``COMP_FILE_TYPE`` 0 or 1.

    No comment or header line is written: LinuxCNC stops reading at the first line
    that is not three numbers.  Positions in mm / degrees (the machine units assumed).
    """
    if comp_file_type not in (0, 1):
        raise ValueError(f"COMP_FILE_TYPE is 0 or 1, not {comp_file_type!r}")
    if len(table) > LINUXCNC_MAX_ENTRIES:
        raise ValueError(f"LinuxCNC takes at most {LINUXCNC_MAX_ENTRIES} entries per joint; "
                         f"this table has {len(table)}")
    table.require_valid()
    scale = k_for_kind(table.kind)  # deviation units per machine unit
    up, down = table.column_for(+1), table.column_for(-1)
    lines = []
    for x, e_up, e_down in zip(table.position, up, down):
        nominal = repr(float(x))
        if comp_file_type == 0:
            cols = (_encode(float(e_up), scale, base=nominal), _encode(float(e_down), scale, base=nominal))
        else:
            cols = (_encode(float(e_up), scale, negate=True), _encode(float(e_down), scale, negate=True))
        lines.append(f"{nominal} {cols[0]} {cols[1]}")
    return "\n".join(lines) + "\n"


def _linuxcnc_rows(text: str, source: str) -> list[tuple[int, list[str]]]:
    """The lines LinuxCNC would read, as (line number, three number texts).

    LinuxCNC (``usrmotLoadComp``) reads with ``sscanf("%lf %lf %lf")`` and STOPS at the
    first line that does not give three numbers.  A stop before the last data line would
    silently drop the rest, so it is an error here.
    """
    lines = text.splitlines()
    rows: list[tuple[int, list[str]]] = []
    for i, raw in enumerate(lines):
        tokens = raw.split()
        if len(tokens) >= 3 and _all_numbers(tokens[:3]):
            rows.append((i + 1, tokens[:3]))
            continue
        # LinuxCNC stops reading at this line
        remaining = sum(1 for r in lines[i + 1:] if r.strip())
        if rows and not remaining:
            break  # trailing blank or comment lines lose nothing
        what = "a blank line" if not raw.strip() else f"not three numbers: {raw.strip()!r}"
        if len(tokens) == 2:
            what += " (LinuxCNC reads three numbers per line for COMP_FILE_TYPE 0 and 1 alike)"
        consequence = (f"the {remaining} line(s) after it would be ignored" if rows
                       else "it would load no compensation at all")
        raise FormatError(source, i + 1, None, f"{what}; LinuxCNC stops reading here, so {consequence}")
    if not rows:
        raise FormatError(source, None, None, "no compensation lines (three numbers per line)")
    return rows


def detect_linuxcnc_type(text: str, source: str = "<text>") -> int:
    """Guess COMP_FILE_TYPE from the numbers: 0 if columns 2-3 are near column 1 (actual
    positions), 1 if they are small against it (trims).  Ambiguous files are refused."""
    rows = _linuxcnc_rows(text, source)
    values = np.array([[float(t) for t in r] for _, r in rows])
    as_type0 = float(np.max(np.abs(values[:, 1:] - values[:, :1])))  # error size if type 0
    as_type1 = float(np.max(np.abs(values[:, 1:])))                   # error size if type 1
    # a factor of 10 between the two readings leaves no doubt (a positioning error is
    # far smaller than the travel); anything closer is for the engineer to say
    if as_type0 * 10 < as_type1:
        return 0
    if as_type1 * 10 < as_type0:
        return 1
    raise FormatError(source, None, None, "cannot tell COMP_FILE_TYPE 0 from 1 by the numbers; "
                                          "say --format linuxcnc0 or --format linuxcnc1")


def table_from_linuxcnc(text: str, comp_file_type: int | None = None, kind: str = "linear",
                        source: str = "<text>") -> CompensationTable:
    """Read a LinuxCNC compensation file into a bidirectional table of errors."""
    if comp_file_type is None:
        comp_file_type = detect_linuxcnc_type(text, source)
    rows = _linuxcnc_rows(text, source)
    scale = k_for_kind(kind)
    position, up, down, lines = [], [], [], []
    for number, (nom, fwd, rev) in rows:
        position.append(float(nom))
        if comp_file_type == 0:
            up.append(_decode(fwd, scale, nom, negate=False) if _finite(nom, fwd) else math.nan)
            down.append(_decode(rev, scale, nom, negate=False) if _finite(nom, rev) else math.nan)
        else:
            up.append(_decode(fwd, scale, None, negate=True) if _finite(fwd) else math.nan)
            down.append(_decode(rev, scale, None, negate=True) if _finite(rev) else math.nan)
        lines.append(number)
    return CompensationTable.bidirectional(kind, position, up, down, line=np.asarray(lines), source=source,
                                           notes=(f"LinuxCNC COMP_FILE_TYPE {comp_file_type}",))


def _all_numbers(tokens: list[str]) -> bool:
    """Whether C's strtod would take every token whole (it accepts nan and inf, as float() does)."""
    try:
        for t in tokens:
            float(t)
    except ValueError:
        return False
    return True


def _finite(*texts: str) -> bool:
    return all(math.isfinite(float(t)) for t in texts)


def check_linuxcnc(table: CompensationTable) -> list[Problem]:
    """Limits LinuxCNC itself imposes beyond :func:`check`."""
    if len(table) > LINUXCNC_MAX_ENTRIES:
        return [Problem("linuxcnc-size", "error",
                        f"LinuxCNC takes at most {LINUXCNC_MAX_ENTRIES} entries per joint; this file has "
                        f"{len(table)} (the rest would be rejected)", size=float(len(table) - LINUXCNC_MAX_ENTRIES))]
    return []


# ---------------------------------------------------------------- detection and dispatch

def detect_format(path: Path, text: str) -> str:
    """``csv`` (table), ``segments``, ``json`` or ``linuxcnc`` by extension, then by content."""
    suffix = path.suffix.lower()
    first = next((ln.strip() for ln in text.splitlines() if ln.strip() and not ln.strip().startswith("#")), "")
    if suffix == ".json" or first.startswith("{"):
        return "json"
    if suffix in LINUXCNC_EXTENSIONS:
        return "linuxcnc"
    if suffix == ".csv" or "," in first:
        header = [h.strip() for h in first.split(",")]
        if "x_from" in header:
            return "segments"
        if "position" in header:
            return "csv"
        raise FormatError(str(path), None, None, "CSV header has neither 'position' (a table) nor "
                                                 "'x_from' (segments): " + first)
    if len(first.split()) >= 3:
        return "linuxcnc"
    raise FormatError(str(path), None, None, "cannot tell the format; give --format " + "|".join(READ_FORMATS))


def read_compensation(path: str | Path, fmt: str | None = None, kind: str = "linear") -> CompensationTable | SegmentModel:
    """Read any supported compensation file (``fmt`` overrides detection)."""
    p = Path(path)
    text = read_text_file(p, FormatError)
    fmt = fmt or detect_format(p, text)
    source = str(p)
    if fmt == "csv":
        return table_from_csv(text, source)
    if fmt == "segments":
        return segments_from_csv(text, source)
    if fmt == "json":
        return from_json(text, source)
    if fmt in ("linuxcnc", "linuxcnc0", "linuxcnc1"):
        comp_type = None if fmt == "linuxcnc" else int(fmt[-1])
        return table_from_linuxcnc(text, comp_type, kind=kind, source=source)
    raise ValueError(f"unknown format {fmt!r}; one of {', '.join(READ_FORMATS)}")


def format_for_output(path: Path, to: str | None) -> str:
    if to:
        if to not in WRITE_FORMATS:
            raise ValueError(f"unknown output format {to!r}; one of {', '.join(WRITE_FORMATS)}")
        return to
    suffix = path.suffix.lower()
    if suffix == ".json":
        return "json"
    if suffix == ".csv":
        return "csv"
    if suffix in LINUXCNC_EXTENSIONS:
        return "linuxcnc0"
    raise ValueError(f"cannot tell the output format from {path.name!r}; give --to {'|'.join(WRITE_FORMATS)}")


def render(obj: CompensationTable | SegmentModel, fmt: str) -> str:
    """Text of a table or segment model in an output format (segments become a table
    for LinuxCNC, which refuses discontinuous models)."""
    from station.compensation.segments import segments_to_table

    if isinstance(obj, SegmentModel):
        if fmt == "csv":
            return segments_to_csv(obj)
        if fmt == "json":
            return segments_to_json(obj)
        obj = segments_to_table(obj)
    if fmt == "csv":
        return table_to_csv(obj)
    if fmt == "json":
        return table_to_json(obj)
    if fmt in ("linuxcnc0", "linuxcnc1"):
        return table_to_linuxcnc(obj, int(fmt[-1]))
    raise ValueError(f"unknown output format {fmt!r}; one of {', '.join(WRITE_FORMATS)}")


__all__ = [
    "FormatError", "LINUXCNC_MAX_ENTRIES", "POSITION_UNIT", "check_linuxcnc", "detect_format",
    "detect_linuxcnc_type", "format_for_output", "from_json", "read_compensation", "render",
    "segments_from_csv", "segments_to_csv", "segments_to_json", "table_from_csv", "table_from_linuxcnc",
    "table_to_csv", "table_to_json", "table_to_linuxcnc",
]
