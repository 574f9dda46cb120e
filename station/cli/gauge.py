"""``station gauge``: a type-1 gauge study on the standard part (formulas in
``station/inspection/gauge.py``), with a histogram plot."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Optional

import typer
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from station.cli.common import err_console, fail, out_console, print_json
from station.cli.inspect import ConfigOpt, DataOpt, ScenarioOpt, TimeScaleOpt


async def run_study(part, repeats: int, *, config=None, scenario=None, time_scale=50.0, data=Path("var"),
                    reference: str = "nominal", settings=None, progress=None):
    """Inspect the part ``repeats`` times (a full re-approach each time) and return
    the type-1 results per characteristic."""
    from station.inspection.gauge import type1
    from station.runtime import open_session

    values: dict[str, list[float]] = {c.id: [] for c in part.characteristics()}
    truths: dict[str, float | None] = {}
    async with open_session(config, scenario=scenario, time_scale=time_scale, data_dir=data, settings=settings) as s:
        for i in range(repeats):
            out = await s.inspect(part, f"GAUGE-{i + 1:03d}")
            if out.state != "complete":
                raise RuntimeError(f"repeat {i + 1} ended {out.state}: {out.reason}")
            for c in out.characteristics:
                if c.measured is None:
                    raise RuntimeError(f"repeat {i + 1}: {c.id} not measured ({out.reason})")
                values[c.id].append(c.measured)
                truths[c.id] = c.true_value
            if progress is not None:
                progress(i + 1)
    results = []
    for c in part.characteristics():
        ref = c.nominal
        if reference == "truth":
            if truths.get(c.id) is None:
                raise ValueError("--reference truth needs a simulated station")
            ref = truths[c.id]
        results.append(type1(c.id, values[c.id], ref, c.lower_limit, c.upper_limit))
    return results


def register(app: typer.Typer) -> None:
    @app.command("gauge")
    def gauge(
        part: str = typer.Option("ZDZG-22.2-12.3851", "--part", help="the reference part's number or spec file"),
        repeats: int = typer.Option(25, "--repeats", help="measurements per characteristic (type-1: 25 to 50)"),
        reference: str = typer.Option("nominal", "--reference",
                                      help="reference value: 'nominal' (the standard's certified values are the spec's nominals) or 'truth' (simulation)"),
        plot: Path = typer.Option(Path("out/gauge.png"), "--plot", help="histogram PNG"),
        config: Optional[Path] = ConfigOpt,
        scenario: Optional[Path] = ScenarioOpt,
        data: Path = DataOpt,
        time_scale: float = TimeScaleOpt,
        json: bool = typer.Option(False, "--json"),
    ) -> None:
        """Type-1 gauge study: Cg and Cgk per characteristic, with a histogram plot."""
        from station.inspection.gauge import plot_gauge
        from station.parts import load_part

        if repeats < 2:
            fail("--repeats must be at least 2")
        if reference not in ("nominal", "truth"):
            fail("--reference must be 'nominal' or 'truth'")
        try:
            spec = load_part(part)
        except (ValueError, KeyError, FileNotFoundError) as exc:
            fail(str(exc))
        with Progress(TextColumn("gauge study"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                      console=err_console, transient=json) as prog:
            task = prog.add_task("repeats", total=repeats)
            try:
                results = asyncio.run(run_study(spec, repeats, config=config, scenario=scenario, time_scale=time_scale,
                                                data=data, reference=reference,
                                                progress=lambda k: prog.update(task, completed=k)))
            except (RuntimeError, ValueError, OSError) as exc:
                fail(str(exc))
        plot.parent.mkdir(parents=True, exist_ok=True)
        plot_gauge(results, plot)
        if json:
            print_json({"part": spec.part_number, "repeats": repeats, "reference": reference,
                        "characteristics": [r.to_json() for r in results], "plot": str(plot)})
            return
        t = Table(title=f"Type-1 gauge study, {spec.part_number}, n = {repeats} (Cg = 0.2T/6s, Cgk = (0.1T-|bias|)/3s)")
        for col in ("characteristic", "reference", "mean", "bias um", "s um", "Cg", "Cgk"):
            t.add_column(col, justify="right", no_wrap=True)
        for r in results:
            t.add_row(r.characteristic, f"{r.reference:.4f}", f"{r.mean:.5f}", f"{r.bias * 1e3:+.2f}", f"{r.s * 1e3:.3f}",
                      f"{r.cg:.1f}", f"{r.cgk:.1f}")
        out_console.print(t)
        out_console.print(f"[dim]histograms: {plot}[/]")
