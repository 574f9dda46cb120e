"""``station inspect``: one inspection, on the default simulated station unless the
config names hardware. Exit 0 pass, 1 fail, 2 error (including aborted or faulted)."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Optional

import typer
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from station.cli.common import err_console, fail, out_console, print_json

EXIT_PASS, EXIT_FAIL, EXIT_ERROR = 0, 1, 2

ConfigOpt = typer.Option(None, "--config", help="station config TOML (default: simulated station)")
ScenarioOpt = typer.Option(None, "--scenario", help="twin scenario TOML (simulation only)")
DataOpt = typer.Option(Path("var"), "--data", help="data folder: database, images")
TimeScaleOpt = typer.Option(20.0, "--time-scale", help="simulation: moves run this much faster than real time")


def result_table(outcome, with_truth: bool) -> Table:
    t = Table(title=f"{outcome.part_number}  serial {outcome.serial}  ->  "
                    f"{(outcome.result or outcome.state).upper()}")
    t.add_column("characteristic", no_wrap=True)
    for col in ("nominal", "tol", "measured", "U k=2", ""):
        t.add_column(col, justify="right", no_wrap=True)
    if with_truth:
        t.add_column("truth", justify="right", no_wrap=True)
        t.add_column("err um", justify="right", no_wrap=True)
    for c in outcome.characteristics:
        measured = "-" if c.measured is None else f"{c.measured:.4f}"
        u = "-" if c.uncertainty_k2 is None else f"{c.uncertainty_k2 * 1e3:.1f}um"
        row = [c.id, f"{c.nominal:.3f}", f"{c.lower_limit - c.nominal:+.3f}/{c.upper_limit - c.nominal:+.3f}", measured, u,
               "[green]ok[/]" if c.passed else "[bold red]OUT[/]"]
        if with_truth:
            tv = c.true_value
            row += ["-" if tv is None else f"{tv:.4f}",
                    "-" if tv is None or c.measured is None else f"{(c.measured - tv) * 1e3:+.2f}"]
        t.add_row(*row)
    return t


def surface_table(surface, simulated: bool) -> Table:
    """The coverage scan's defects, one row each (with the twin's truth in simulation)."""
    t = Table(title=f"surface {surface.axial_from_mm:g}..{surface.axial_to_mm:g} mm: {surface.frames} frames, "
                    f"{surface.recentred} re-centred, {len(surface.defects)} defect(s)")
    cols = ["defect", "kind", "axial mm", "angle deg", "length mm", "U mm", "where", "verdict"]
    if simulated:
        cols += ["truth: place off um", "length off um"]
    for c in cols:
        t.add_column(c)
    for d in surface.defects:
        row = [d.id, d.kind, f"{d.axial_mm:.3f}", f"{d.angle_deg:.2f}", f"{d.length_mm:.3f}", f"{d.size_u_mm:.3f}",
               d.hole or d.zone or "-", "[red]over " + d.rejects + "[/]" if d.rejects else "ok"]
        if simulated:
            tr = d.truth or {}
            row += [f"{tr['place_error_mm'] * 1e3:.0f}" if "place_error_mm" in tr else "unmatched",
                    f"{(d.length_mm - tr['length_mm']) * 1e3:+.0f}" if "length_mm" in tr else "-"]
        t.add_row(*row)
    return t


def register(app: typer.Typer) -> None:
    @app.command("inspect")
    def inspect(
        part: str = typer.Option(..., "--part", help="part number of a built-in spec, or a spec file"),
        serial: str = typer.Option(..., "--serial", help="the part's serial number"),
        order: Optional[str] = typer.Option(None, "--order", help="production order id"),
        config: Optional[Path] = ConfigOpt,
        scenario: Optional[Path] = ScenarioOpt,
        data: Path = DataOpt,
        time_scale: float = TimeScaleOpt,
        json: bool = typer.Option(False, "--json", help="one JSON object on stdout (with the twin's truth in simulation)"),
        surface: Optional[bool] = typer.Option(None, "--surface/--no-surface",
                                               help="scan the whole inner surface too (default: as the part spec's "
                                                    "[surface] every_part says)"),
    ) -> None:
        """Run one inspection and print the result table."""
        from drivers.interfaces import DriverError
        from station.runtime import open_session
        from station.parts import load_part
        from station.runtime import ConfigError
        from station.store.errors import StoreError

        try:
            spec = load_part(part)
        except (ValueError, KeyError, FileNotFoundError) as exc:
            fail(str(exc), EXIT_ERROR)
        if surface and spec.surface is None:
            fail(f"--surface: {spec.part_number} has no [surface] table (docs/part-specs.md, Surface): its surface has "
                 f"no criteria to judge", EXIT_ERROR)

        async def go():
            async with open_session(config, scenario=scenario, time_scale=time_scale, data_dir=data) as session:
                simulated = session.station.world is not None
                with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                              console=err_console, transient=json) as progress:
                    task = progress.add_task(f"inspecting {spec.part_number} {serial}", total=None)

                    def on_event(ev):
                        if ev.kind == "progress":
                            progress.update(task, completed=ev.data["done"], total=ev.data["total"],
                                            description=f"{ev.text}")
                        elif ev.kind in ("fault", "retry"):
                            progress.console.print(f"[yellow]{ev.kind}:[/] {ev.text}")

                    session.engine.subscribe(on_event)
                    outcome = await session.inspect(spec, serial, order_id=order, surface=surface)
                return outcome, simulated

        try:
            outcome, simulated = asyncio.run(go())
        except (ConfigError, StoreError, DriverError, OSError) as exc:
            fail(str(exc), EXIT_ERROR)
        if json:
            print_json(outcome.to_json(with_truth=simulated))
        else:
            out_console.print(result_table(outcome, simulated))
            if outcome.reason:
                out_console.print(f"reason: {outcome.reason}")
            for f in outcome.findings:
                style = "dim" if f.kind == "datum" else "yellow"
                out_console.print(f"[{style}]{f.kind.replace('_', ' ')}: {f.message}[/]")
            cyc = outcome.cycle
            if cyc is not None:
                bound = (f", {cyc['ratio']:.2f} x the plan's lower bound of {cyc['lower_bound_s']:.2f} s"
                         if cyc.get("ratio") is not None else "")
                out_console.print(f"[dim]machine time {cyc['machine_s']:.2f} s ({cyc['basis']}){bound}[/]")
                sc = cyc.get("surface")
                if sc is not None:
                    limit = (f", {sc['ratio']:.2f} x the physical limit of {sc['limit_s']:.2f} s "
                             f"({sc['limit_frames']} frames)" if sc.get("ratio") is not None else "")
                    out_console.print(f"[dim]surface scan {sc['machine_s']:.2f} s of it{limit}[/]")
            if outcome.surface is not None:
                out_console.print(surface_table(outcome.surface, simulated))
            for a in outcome.alarms:
                out_console.print(f"[bold yellow]station needs a check:[/] {a.reason}")
            out_console.print(f"[dim]inspection {outcome.id} stored in {data}/[/]")
        if outcome.state != "complete":
            raise typer.Exit(EXIT_ERROR)
        raise typer.Exit(EXIT_PASS if outcome.result == "pass" else EXIT_FAIL)
