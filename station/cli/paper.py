"""``station paper``: the seed paper's experiment (section 6, Table 4) on a twin.

The standard sample is measured on the paper's station (``sim/scenarios/paper.toml``)
before compensation (ideal model; the grating's reading taken as the detection
point's position, as the paper's system did) and after (inverse compensation with
the full error model), and our figures are printed beside Table 4. The paper's
reading is then checked: hole 2 out of tolerance before and inside after, hole 1
inside both times, diameters unaffected by compensation.
"""

from __future__ import annotations

import asyncio
import json as jsonlib
import tempfile
from pathlib import Path
from typing import Optional

import typer
from rich.table import Table

from station.cli.common import fail, out_console, print_json

PAPER_TABLE4 = {
    "before": {"hole_1": {"diameter": 0.675, "position": 71.130}, "hole_2": {"diameter": 0.708, "position": 85.080}},
    "after": {"hole_1": {"diameter": 0.675, "position": 71.086}, "hole_2": {"diameter": 0.708, "position": 85.142}},
}
#: diameters count as "the same before and after" within this (mm): a tenth of the
#: smallest step the paper prints (0.001 mm)
SAME_DIAMETER_MM = 1e-4 * 10


async def _measure(scenario: Path, data: Path, compensated: bool, time_scale: float):
    from station.inspection.scan import ScanSettings
    from station.runtime import open_session
    from station.parts import load_part

    from sim.twins import DEFAULT_SCENARIO

    spec = load_part("ZDZG-22.2-12.3851")
    PAPER_MODEL = DEFAULT_SCENARIO.with_name("paper_model.toml")  # its laser's Tables 1-3
    # the paper's station compensated with the model its laser measured, which is all
    # the paper gives of its machine: the paper's world is that model too
    # (sim/scenarios/paper_model.toml), so the two coincide here by the paper's data,
    # not by one being copied into the other
    async with open_session(scenario=scenario, time_scale=time_scale, data_dir=data, model=PAPER_MODEL,
                            settings=ScanSettings(compensated=compensated)) as s:
        return await s.inspect(spec, "STANDARD-SAMPLE"), spec


def run_paper(scenario: Path | None = None, time_scale: float = 50.0, data: Path | None = None,
              timeout_s: float | None = None) -> dict:
    """``timeout_s``: a bound on each of the two inspections; past it the inspection is
    cancelled and TimeoutError raised, chained to the cancellation's traceback, which
    names the await it was stuck in."""
    from sim.twins import DEFAULT_SCENARIO

    scenario = scenario or DEFAULT_SCENARIO.with_name("paper.toml")

    def measure(where: Path, compensated: bool):
        return asyncio.run(asyncio.wait_for(_measure(scenario, where, compensated, time_scale), timeout_s))

    with tempfile.TemporaryDirectory() as tmp:
        where = data or Path(tmp)
        before, spec = measure(where / "before", False)
        after, _ = measure(where / "after", True)
    rows = {}
    for run, out in (("before", before), ("after", after)):
        for c in out.characteristics:
            hole, kind = c.id.split(".")
            rows.setdefault(hole, {}).setdefault(kind, {})[run] = {
                "measured": c.measured, "in_tolerance": c.passed, "true": c.true_value, "paper": PAPER_TABLE4[run][hole][kind]}
    lim = {c.id: (c.lower_limit, c.upper_limit) for c in spec.characteristics()}
    checks = {
        "hole_2_out_before": not rows["hole_2"]["position"]["before"]["in_tolerance"],
        "hole_2_in_after": rows["hole_2"]["position"]["after"]["in_tolerance"],
        "hole_1_in_both": rows["hole_1"]["position"]["before"]["in_tolerance"] and rows["hole_1"]["position"]["after"]["in_tolerance"],
        "diameters_unaffected": all(abs(rows[h]["diameter"]["before"]["measured"] - rows[h]["diameter"]["after"]["measured"]) <= SAME_DIAMETER_MM
                                    for h in rows),
    }
    return {"scenario": str(scenario), "limits": lim, "rows": rows, "checks": checks,
            "reproduced": all(checks.values()), "results": {"before": before.result, "after": after.result}}


def register(app: typer.Typer) -> None:
    @app.command("paper")
    def paper(
        scenario: Optional[Path] = typer.Option(None, "--scenario", help="default: sim/scenarios/paper.toml"),
        time_scale: float = typer.Option(50.0, "--time-scale"),
        json: bool = typer.Option(False, "--json"),
    ) -> None:
        """The paper's experiment: the standard sample before and after compensation, beside Table 4."""
        try:
            res = run_paper(scenario, time_scale)
        except (OSError, ValueError) as exc:
            fail(str(exc))
        if json:
            print_json(res)
        else:
            t = Table(title="Standard sample ZDZG-22.2-12.3851: paper (Table 4) and this station's twin, mm")
            for col in ("hole", "", "tolerance", "paper before", "ours before", "paper after", "ours after", "truth"):
                t.add_column(col, justify="right", no_wrap=True)
            for hole, kinds in res["rows"].items():
                for kind, r in kinds.items():
                    lo, hi = res["limits"][f"{hole}.{kind}"]

                    def cell(run):
                        v = r[run]["measured"]
                        mark = "" if r[run]["in_tolerance"] else " [bold red]OUT[/]"
                        return f"{v:.4f}{mark}"

                    def paper_cell(run):
                        v = r[run]["paper"]
                        return f"{v:.3f}" + ("" if lo <= v <= hi else " OUT")

                    t.add_row(hole, kind, f"{lo:.3f}..{hi:.3f}", paper_cell("before"), cell("before"),
                              paper_cell("after"), cell("after"), f"{r['before']['true']:.4f}")
            out_console.print(t)
            for name, ok in res["checks"].items():
                out_console.print(f"{'[green]yes[/]' if ok else '[bold red]NO[/]'}  {name.replace('_', ' ')}")
            out_console.print("the paper's reading is " + ("[bold green]reproduced[/]" if res["reproduced"] else "[bold red]NOT reproduced[/]"))
        if not res["reproduced"]:
            raise typer.Exit(1)
