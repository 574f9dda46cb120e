"""``station iso230 REC.csv [--json] [--plot FILE.png]``: ISO 230-2:2014 report of a recording.

A readable table by default; with ``--json`` stdout carries exactly one JSON object
(:meth:`station.iso230.Iso230Result.to_json`) and anything else goes to stderr.
Bad input exits non-zero with the reader's message (file, line, column).
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import numpy as np
import typer
from rich.table import Table

from station.cli.common import err_console, fail, out_console, print_json
from station.iso230 import Iso230Result, analyse, plot_result
from station.recording import RecordingError, read_recording


def _num(v: float, digits: int = 3) -> str:
    return "–" if v is None or not np.isfinite(v) else f"{v:.{digits}f}"


def render_table(result: Iso230Result) -> None:
    """Per-target table, then the figures, then the warnings (all to stdout)."""
    u, pu = result.unit, result.position_unit
    st = result.stats
    title = f"ISO 230-2:2014 — {result.source}" + (f" (axis {result.axis})" if result.axis else "")
    per_target = Table(title=title, title_justify="left")
    for name in (f"target / {pu}", "n↑", "x̄↑", "s↑", "n↓", "x̄↓", "s↓", "x̄", "B_i"):
        per_target.add_column(name, justify="right")
    reversal = st.reversal
    mean = st.bidirectional_mean
    for i in range(len(st)):
        per_target.add_row(
            f"{st.target[i]:g}", str(int(st.n_up[i])), _num(st.mean_up[i]), _num(st.s_up[i]),
            str(int(st.n_down[i])), _num(st.mean_down[i]), _num(st.s_down[i]), _num(mean[i]), _num(reversal[i]),
        )
    out_console.print(per_target)

    figures = Table(title=f"Figures ({u})", title_justify="left")
    for name in ("figure", "value", "meaning"):
        figures.add_column(name, justify="right" if name == "value" else "left")
    meanings = {
        "A": "accuracy, bidirectional", "A_up": "accuracy, up", "A_down": "accuracy, down",
        "E": "systematic positional deviation, bidirectional", "E_up": "systematic, up",
        "E_down": "systematic, down", "M": "mean bidirectional positional deviation",
        "R": "repeatability, bidirectional", "R_up": "repeatability, up", "R_down": "repeatability, down",
        "B": "reversal value (max |B_i|)", "B_mean": "mean reversal value",
    }
    for name in ("A", "A_up", "A_down", "E", "E_up", "E_down", "M", "R", "R_up", "R_down", "B", "B_mean"):
        figures.add_row(name, _num(getattr(result, name)), meanings[name])
    out_console.print(figures)
    for w in result.warnings:
        out_console.print(f"[yellow]warning:[/] {w}", highlight=False)


def iso230_command(
    recording: Path = typer.Argument(..., help="recording CSV (contract shared/spec/discovery.md, section 1)"),
    as_json: bool = typer.Option(False, "--json", help="print exactly one JSON object on stdout"),
    plot: Optional[Path] = typer.Option(None, "--plot", help="write a PNG plot of x̄ ± 2s per direction and B_i"),
) -> None:
    """ISO 230-2:2014 positioning accuracy and repeatability of one axis."""
    try:
        rec = read_recording(recording)
    except RecordingError as exc:
        fail(str(exc))
    result = analyse(rec)
    if plot is not None:
        try:
            plot_result(result, plot)
        except OSError as exc:
            fail(f"{plot}: cannot write the plot: {exc.strerror or exc}")
    if as_json:
        print_json(result.to_json())
    else:
        render_table(result)
    if plot is not None:
        err_console.print(f"plot written to {plot}", highlight=False)


def register(app: typer.Typer) -> None:
    app.command("iso230")(iso230_command)
