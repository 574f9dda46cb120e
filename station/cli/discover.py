"""``station discover``: what does the axis model miss in a recording?

Contract: ``shared/spec/discovery.md`` section 3.  Exit 0 when the analysis ran
(whatever it found); exit 2 with the file, line and column on bad input, no traceback.
"""

from __future__ import annotations

from pathlib import Path

import typer

from station.cli.common import err_console, fail


def register(app: typer.Typer) -> None:
    @app.command("discover")
    def discover_cmd(
        model: Path = typer.Option(..., "--model", help="axis model (TOML) the twin currently uses"),
        recording: Path = typer.Option(..., "--recording", help="laser / rotary-calibrator recording (CSV)"),
        out: Path = typer.Option(..., "--out", help="output folder: report.json, model.toml, plots"),
        plots: bool = typer.Option(True, "--plots/--no-plots", help="write the PNG plots"),
    ) -> None:
        """Replay a recording through an axis model, find and explain the mismatch."""
        from station.axis_model import AxisModelError, read_axis_model
        from station.recording import RecordingError, read_recording

        try:
            axis_model = read_axis_model(model)
        except AxisModelError as exc:
            fail(str(exc))
        try:
            rec = read_recording(recording)
        except RecordingError as exc:
            fail(str(exc))
        from station.discovery import discover, write_outputs

        try:
            result = discover(axis_model, rec)
        except ValueError as exc:
            fail(str(exc))
        try:
            write_outputs(result, out, plots=plots)
        except OSError as exc:
            fail(f"{out}: cannot write the outputs: {exc.strerror or exc}")
        r = result.report
        err_console.print(
            f"[bold]{r['verdict']}[/]: rms {r['before']['rms']:.3g} -> {r['after']['rms']:.3g} "
            f"(noise floor {r['noise_floor']:.3g}); effects: "
            + (", ".join(e["name"] for e in r["effects"]) or "none")
            + f"; written to {out}",
            highlight=False,
        )
