"""Axis recordings (contract ``shared/spec/discovery.md`` section 1).

A recording is one measurement campaign on one axis, laser interferometer or
rotary calibrator, in ISO 230-2 runs.  Bad input is refused with the file, line
and column named; nothing is guessed silently.  Extra columns are kept.
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

REQUIRED_COLUMNS = ("time_s", "run", "direction", "target", "deviation")
OPTIONAL_COLUMNS = ("temperature_c",)


class LocatedInputError(ValueError):
    """Bad input, with where it is: the message names file, line and column.
    The base of every file-reading error of the station's text formats."""

    def __init__(self, path: str, line: int | None, column: str | None, message: str):
        self.path, self.line, self.column = path, line, column
        where = path
        if line is not None:
            where += f", line {line}"
        if column is not None:
            where += f", column '{column}'"
        super().__init__(f"{where}: {message}")


class RecordingError(LocatedInputError):
    """A recording that cannot be read; the message names file, line and column."""


@dataclass
class Recording:
    """Columns as numpy arrays of shape (N,), in file order."""

    time_s: np.ndarray
    run: np.ndarray
    direction: np.ndarray
    target: np.ndarray
    deviation: np.ndarray
    temperature_c: np.ndarray | None = None
    metadata: dict[str, str] = field(default_factory=dict)
    extra: dict[str, list[str]] = field(default_factory=dict)
    source: str = "<memory>"
    #: 1-based file line of each data row (for messages that point back to the file)
    line: np.ndarray | None = None

    @property
    def kind(self) -> str:
        """``linear`` or ``rotary`` from the metadata (default linear)."""
        return self.metadata.get("kind", "linear")

    @property
    def axis(self) -> str:
        return self.metadata.get("axis", "")

    def __len__(self) -> int:
        return int(self.target.size)

    def numeric_channels(self) -> dict[str, np.ndarray]:
        """The extra columns whose every value is a finite number (e.g. ``angle_arcsec``)."""
        out = {}
        for name, values in self.extra.items():
            try:
                arr = np.array([float(v) for v in values])
            except ValueError:
                continue
            if arr.size and np.all(np.isfinite(arr)):
                out[name] = arr
        return out

    @property
    def runs(self) -> np.ndarray:
        return np.unique(self.run)

    def subset(self, mask: np.ndarray) -> "Recording":
        """Rows where ``mask`` is true (a new recording; metadata shared)."""
        mask = np.asarray(mask)
        return Recording(
            time_s=self.time_s[mask],
            run=self.run[mask],
            direction=self.direction[mask],
            target=self.target[mask],
            deviation=self.deviation[mask],
            temperature_c=None if self.temperature_c is None else self.temperature_c[mask],
            metadata=dict(self.metadata),
            extra={k: [v for v, m in zip(vals, mask) if m] for k, vals in self.extra.items()},
            source=self.source,
            line=None if self.line is None else self.line[mask],
        )

    def to_csv(self, path: str | Path | None = None) -> str:
        """Write in the contract's format (metadata lines, then the columns)."""
        buf = io.StringIO()
        for k, v in self.metadata.items():
            buf.write(f"# {k}: {v}\n")
        cols = list(REQUIRED_COLUMNS) + (["temperature_c"] if self.temperature_c is not None else []) + list(self.extra)
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(cols)
        for i in range(len(self)):
            row = [repr(float(self.time_s[i])), int(self.run[i]), f"{int(self.direction[i]):+d}",
                   repr(float(self.target[i])), repr(float(self.deviation[i]))]
            if self.temperature_c is not None:
                row.append(repr(float(self.temperature_c[i])))
            row += [self.extra[k][i] for k in self.extra]
            w.writerow(row)
        text = buf.getvalue()
        if path is not None:
            Path(path).write_text(text)
        return text


def _number(text: str, path: str, line: int, col: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise RecordingError(path, line, col, f"not a number: {text!r}") from None
    if not math.isfinite(v):
        raise RecordingError(path, line, col, f"not a finite number: {text!r}")
    return v


def parse_recording(text: str, source: str = "<text>") -> Recording:
    """Parse recording text; raise :class:`RecordingError` naming line and column.
    A UTF-8 byte-order mark (a spreadsheet's export) is dropped."""
    text = text.removeprefix("\ufeff")
    metadata: dict[str, str] = {}
    lines = text.splitlines()
    i = 0
    # leading metadata lines "# key: value" (and blank lines) before the header
    while i < len(lines) and (lines[i].startswith("#") or not lines[i].strip()):
        body = lines[i][1:].strip() if lines[i].startswith("#") else ""
        if ":" in body:
            key, _, value = body.partition(":")
            metadata[key.strip()] = value.strip()
        i += 1
    if i >= len(lines):
        raise RecordingError(source, None, None, "no header row (expected columns: " + ", ".join(REQUIRED_COLUMNS) + ")")
    header_line = i + 1
    header = [h.strip() for h in next(csv.reader([lines[i]]))]
    for req in REQUIRED_COLUMNS:
        if req not in header:
            raise RecordingError(source, header_line, req, "required column is missing; header is " + ",".join(header))
    seen: set[str] = set()
    for h in header:
        if h in seen:
            raise RecordingError(source, header_line, h, "column appears twice")
        seen.add(h)
    if "kind" in metadata and metadata["kind"] not in ("linear", "rotary"):
        raise RecordingError(source, None, None, f"metadata 'kind' must be linear or rotary, not {metadata['kind']!r}")
    idx = {h: j for j, h in enumerate(header)}
    has_temp = "temperature_c" in idx
    extras = [h for h in header if h not in REQUIRED_COLUMNS and h not in OPTIONAL_COLUMNS]
    cols: dict[str, list[float]] = {c: [] for c in REQUIRED_COLUMNS + (("temperature_c",) if has_temp else ())}
    extra: dict[str, list[str]] = {h: [] for h in extras}
    line_no: list[int] = []
    prev_t = -math.inf
    for j in range(i + 1, len(lines)):
        raw = lines[j]
        ln = j + 1
        if not raw.strip() or raw.lstrip().startswith("#"):
            continue
        row = next(csv.reader([raw]))
        if len(row) != len(header):
            raise RecordingError(source, ln, None, f"{len(row)} fields, the header has {len(header)}")
        t = _number(row[idx["time_s"]].strip(), source, ln, "time_s")
        if t < prev_t:
            raise RecordingError(source, ln, "time_s", f"time goes backwards ({t} after {prev_t})")
        prev_t = t
        run_text = row[idx["run"]].strip()
        try:
            run = int(run_text)
        except ValueError:
            raise RecordingError(source, ln, "run", f"not an integer: {run_text!r}") from None
        if run < 1:
            raise RecordingError(source, ln, "run", f"run numbers start at 1, got {run}")
        d_text = row[idx["direction"]].strip()
        if d_text in ("+1", "1", "1.0", "+1.0"):
            direction = 1
        elif d_text in ("-1", "-1.0"):
            direction = -1
        else:
            raise RecordingError(source, ln, "direction", f"unknown direction {d_text!r} (expected +1 or -1)")
        cols["time_s"].append(t)
        cols["run"].append(run)
        cols["direction"].append(direction)
        cols["target"].append(_number(row[idx["target"]].strip(), source, ln, "target"))
        cols["deviation"].append(_number(row[idx["deviation"]].strip(), source, ln, "deviation"))
        if has_temp:
            cols["temperature_c"].append(_number(row[idx["temperature_c"]].strip(), source, ln, "temperature_c"))
        for h in extras:
            extra[h].append(row[idx[h]])
        line_no.append(ln)
    if not line_no:
        raise RecordingError(source, header_line, None, "no data rows after the header")
    return Recording(
        time_s=np.asarray(cols["time_s"], dtype=float),
        run=np.asarray(cols["run"], dtype=int),
        direction=np.asarray(cols["direction"], dtype=int),
        target=np.asarray(cols["target"], dtype=float),
        deviation=np.asarray(cols["deviation"], dtype=float),
        temperature_c=np.asarray(cols["temperature_c"], dtype=float) if has_temp else None,
        metadata=metadata,
        extra=extra,
        source=source,
        line=np.asarray(line_no, dtype=int),
    )


def read_text_file(path: str | Path, error: type[LocatedInputError] = LocatedInputError) -> str:
    """A text file's content; a missing, unreadable or non-UTF-8 file raises ``error``
    naming the file (the common first step of every text format the station reads)."""
    p = Path(path)
    try:
        return p.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise error(str(p), None, None, "no such file") from None
    except UnicodeDecodeError as exc:
        raise error(str(p), None, None, f"not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except OSError as exc:
        raise error(str(p), None, None, f"cannot read: {exc.strerror}") from None


def read_recording(path: str | Path) -> Recording:
    """Read a recording file; an unreadable or malformed file raises :class:`RecordingError`."""
    return parse_recording(read_text_file(path, RecordingError), str(path))
