"""``station compensation check|convert|build``: compensation tables and segment models.

``check FILE`` prints every problem (with line/position and size) and exits 1 if any
error or warning was found, 0 with a one-line OK otherwise; an unreadable file exits 2
with a message naming file and line.  ``docs/compensation.md`` describes the formats.
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from station.cli.common import err_console, fail, out_console
from station.compensation.build import BUILD_MODES, table_from_recording
from station.compensation.check import check, failing
from station.compensation.files import (
    READ_FORMATS,
    FormatError,
    check_linuxcnc,
    format_for_output,
    read_compensation,
    render,
)
from station.compensation.segments import DEFAULT_JUNCTION_TOLERANCE, SegmentModel
from station.compensation.table import CompensationTable, TableError
from station.recording import RecordingError, read_recording

compensation_app = typer.Typer(help="Compensation tables: check, convert, build from a recording.",
                               no_args_is_help=True)

FORMAT_HELP = "input format: " + "|".join(READ_FORMATS) + " (default: by extension and header)"
KIND_HELP = "axis kind for LinuxCNC files, which do not say it: linear (mm, um) or rotary (deg, arcsec)"


def _load(path: Path, fmt: Optional[str], kind: str):
    if fmt is not None and fmt not in READ_FORMATS:
        fail(f"unknown --format {fmt!r}; one of {', '.join(READ_FORMATS)}")
    if kind not in ("linear", "rotary"):
        fail(f"--kind must be linear or rotary, not {kind!r}")
    try:
        return read_compensation(path, fmt, kind=kind)
    except FormatError as exc:
        fail(str(exc))


def _describe(obj) -> str:
    if isinstance(obj, SegmentModel):
        return f"{len(obj)} segments ({obj.kind}, y = {obj.quantity})"
    return f"{len(obj)} positions ({obj.kind}, {obj.mode}, error in {obj.error_unit})"


def _print_problem(p) -> None:
    colour = {"error": "red", "warning": "yellow", "note": "cyan"}[p.severity]
    out_console.print(f"[{colour}]{p.severity}[/{colour}]: ", end="", highlight=False)
    out_console.print(p.message, markup=False, highlight=False, soft_wrap=True)


@compensation_app.command("check")
def check_command(
    file: Path = typer.Argument(..., help="table CSV, segment CSV, JSON or LinuxCNC comp file"),
    fmt: Optional[str] = typer.Option(None, "--format", help=FORMAT_HELP),
    kind: str = typer.Option("linear", "--kind", help=KIND_HELP),
    max_step: Optional[float] = typer.Option(None, "--max-step",
                                             help="warn where the error changes by more than this between "
                                                  "neighbouring positions (deviation units)"),
    tolerance: float = typer.Option(DEFAULT_JUNCTION_TOLERANCE, "--tolerance",
                                    help="segments: largest gap/jump taken as continuous (model units)"),
) -> None:
    """Name every problem of a compensation file; exit 1 if there is any."""
    obj = _load(file, fmt, kind)
    problems = check(obj, max_step=max_step, tolerance=tolerance)
    if isinstance(obj, CompensationTable) and (obj.notes and "LinuxCNC" in obj.notes[0]):
        problems += check_linuxcnc(obj)
    for p in problems:
        _print_problem(p)
    bad = failing(problems)
    if bad:
        n_err = sum(p.severity == "error" for p in bad)
        n_warn = len(bad) - n_err
        err_console.print(f"{file}: {n_err} error(s), {n_warn} warning(s)", highlight=False)
        raise typer.Exit(1)
    out_console.print(f"OK: {file}: {_describe(obj)}", markup=False, highlight=False, soft_wrap=True)


def _write(obj, out: Path, to: Optional[str]) -> str:
    try:
        fmt = format_for_output(out, to)
        text = render(obj, fmt)
    except (TableError, ValueError) as exc:
        fail(str(exc))
    try:
        out.write_text(text, encoding="utf-8")
    except OSError as exc:
        fail(f"{out}: cannot write: {exc.strerror or exc}")
    return fmt


@compensation_app.command("convert")
def convert_command(
    src: Path = typer.Argument(..., metavar="IN", help="file to read"),
    dst: Path = typer.Argument(..., metavar="OUT", help="file to write"),
    to: Optional[str] = typer.Option(None, "--to", help="csv|json|linuxcnc0|linuxcnc1 (default: by OUT's extension)"),
    fmt: Optional[str] = typer.Option(None, "--format", help=FORMAT_HELP),
    kind: str = typer.Option("linear", "--kind", help=KIND_HELP),
) -> None:
    """Convert between the station's CSV/JSON and LinuxCNC COMP_FILE types 0 and 1."""
    obj = _load(src, fmt, kind)
    try:
        out_fmt = format_for_output(dst, to)
    except ValueError as exc:
        fail(str(exc))
    errors = [p for p in check(obj) if p.severity == "error"]
    # a segment list written as segments keeps its junction problems faithfully (the
    # reader of OUT will see them); anything else, and non-finite numbers, is refused
    keeps_segments = isinstance(obj, SegmentModel) and out_fmt in ("csv", "json")
    blocking = [p for p in errors if not keeps_segments or p.code == "non-finite"]
    if blocking:
        for p in blocking:
            _print_problem(p)
        fail(f"{src}: not converted ({len(blocking)} error(s); see `station compensation check`)", code=1)
    if errors:
        err_console.print(f"note: {len(errors)} problem(s) of {src} carried over as they are "
                          "(see `station compensation check`)", highlight=False)
    written = _write(obj, dst, out_fmt)
    err_console.print(f"wrote {dst} ({written}): {_describe(obj)}", highlight=False)


@compensation_app.command("build")
def build_command(
    recording: Path = typer.Argument(..., help="recording CSV (ISO 230-2 runs)"),
    out: Path = typer.Option(..., "--out", help="table file to write (.csv, .json, or LinuxCNC .comp)"),
    mode: str = typer.Option("bidirectional", "--mode", help="bidirectional (x̄↑, x̄↓) or averaged (x̄ + backlash B̄)"),
    to: Optional[str] = typer.Option(None, "--to", help="csv|json|linuxcnc0|linuxcnc1 (default: by extension)"),
) -> None:
    """Build a compensation table from a recording's ISO 230-2 per-target means."""
    if mode not in BUILD_MODES:
        fail(f"--mode must be one of {', '.join(BUILD_MODES)}, not {mode!r}")
    try:
        rec = read_recording(recording)
    except RecordingError as exc:
        fail(str(exc))
    try:
        table = table_from_recording(rec, mode)
    except ValueError as exc:
        fail(f"{recording}: {exc}")
    written = _write(table, out, to)
    err_console.print(f"wrote {out} ({written}): {_describe(table)}", highlight=False)


def register(app: typer.Typer) -> None:
    app.add_typer(compensation_app, name="compensation")
