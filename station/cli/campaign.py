"""``station campaign``, ``station check master``, ``station check axis`` and ``station
check camera``: the station judged over a production run on a scenario's world, on its
certified master, by its own check of Z against its grating (docs/monitor.md), and its
camera's sensor against its pixel map (docs/vision.md)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer
from rich.table import Table

from station.cli.common import err_console, fail, out_console, print_json


def _station_check(config, scenario, time_scale: float, data: Path, part: str, settings_of, check):
    """Run one of the station's own checks in a session: the scenario file, the check's
    settings (``settings_of()``) and the part family ``part`` made first, then
    ``await check(session, family, settings)``; a bad input or a fault ends the command
    with exit 2, naming it. Returns the check's outcome."""
    import asyncio

    from drivers.interfaces import DriverError
    from station.parts import load_part
    from station.runtime import ConfigError, open_session
    from station.store.errors import StoreError

    if scenario is not None and not scenario.is_file():
        fail(f"{scenario}: no such scenario file", 2)
    try:
        settings = settings_of()
        family = load_part(part)
    except ValueError as exc:
        fail(str(exc), 2)

    async def go():
        async with open_session(config, scenario=scenario, time_scale=time_scale, data_dir=data) as s:
            return await check(s, family, settings)

    try:
        return asyncio.run(go())
    except (ConfigError, StoreError, DriverError, OSError, ValueError) as exc:
        fail(str(exc), 2)


def register(app: typer.Typer) -> None:
    @app.command("campaign")
    def campaign(
        scenario: Optional[Path] = typer.Option(None, "--scenario", help="twin scenario TOML (default: the default world)"),
        parts: int = typer.Option(20, "--parts", help="parts to inspect"),
        master_every: int = typer.Option(0, "--master-every", help="check on the master after every K parts (0: never)"),
        seed: int = typer.Option(0, "--seed", help="the master's making (its errors within its certificate)"),
        time_scale: float = typer.Option(4.0, "--time-scale", help="moves run this much faster than real time"),
        data: Optional[Path] = typer.Option(None, "--data", help="keep the records here (default: a temporary folder)"),
        auto_approve: bool = typer.Option(False, "--auto-approve", help="approve each model proposal (stands in "
                                                                          "for the engineer)"),
        json: bool = typer.Option(False, "--json", help="one JSON object on stdout"),
    ) -> None:
        """A production campaign in simulation: the station with its own model on the scenario's world."""
        from rich.progress import Progress

        from station.bench.campaign import run_campaign

        if scenario is not None and not scenario.is_file():
            fail(f"{scenario}: no such scenario file", 2)
        try:
            with Progress(console=err_console, transient=True) as prog:
                task = prog.add_task("campaign", total=parts)
                res = run_campaign(scenario, parts, master_every, data, time_scale, seed,
                                   progress=lambda: prog.advance(task), auto_approve=auto_approve)
        except ValueError as exc:
            fail(str(exc), 2)
        if json:
            print_json(res)
            return
        t = Table(title=f"campaign: {parts} parts on {res['scenario']}")
        for col in ("part", "result", "worst error um", "U um", "model"):
            t.add_column(col, justify="right")
        for r in res["inspections"]:
            t.add_row(str(r["index"]), r["result"] or r["state"],
                      "-" if r["worst_error_um"] is None else f"{r['worst_error_um']:.2f}",
                      "-" if r["u_um"] is None else f"{r['u_um']:.2f}", r["model_version"])
        out_console.print(t)
        for a in res["alarms"]:
            out_console.print(f"[yellow]alarm after part {a['index']}:[/] {a['reason']}")
        c = res["cost"]
        out_console.print(f"[dim]{c['wall_s_per_inspection']:.2f} s of this PC per inspection; machine time "
                          f"{c['machine_s_per_inspection_median']:.2f} s per part[/]")

    check_app = typer.Typer(help="checks of the station itself", no_args_is_help=True)
    app.add_typer(check_app, name="check")

    @check_app.command("master")
    def check_master(
        master: str = typer.Option("MC-22.2-A", "--master", help="a built-in master's id or a certificate file"),
        config: Optional[Path] = typer.Option(None, "--config", help="station config TOML (default: simulated)"),
        scenario: Optional[Path] = typer.Option(None, "--scenario", help="twin scenario TOML (simulation only)"),
        data: Path = typer.Option(Path("var"), "--data", help="data folder: database, images"),
        time_scale: float = typer.Option(20.0, "--time-scale", help="simulation: moves this much faster"),
        seed: int = typer.Option(0, "--seed", help="simulation: the master's making"),
        json: bool = typer.Option(False, "--json", help="one JSON object on stdout"),
    ) -> None:
        """Inspect the certified master and judge the station by its certificate.
        Exit 0 in control, 1 out of its stated U, 2 error."""
        import asyncio

        from drivers.interfaces import DriverError
        from station.checks.master import load_master
        from station.runtime import open_session
        from station.parts import load_part
        from station.runtime import ConfigError
        from station.store.errors import StoreError

        try:
            cert = load_master(master)
            family = load_part(cert.part_number)
        except ValueError as exc:
            fail(str(exc), 2)

        async def go():
            async with open_session(config, scenario=scenario, time_scale=time_scale, data_dir=data) as s:
                return await s.check_master(cert, family, seed=seed), s.station.world is not None

        try:
            res, simulated = asyncio.run(go())
        except (ConfigError, StoreError, DriverError, OSError) as exc:
            fail(str(exc), 2)
        if json:
            print_json(res.to_json(with_truth=simulated))
        else:
            t = Table(title=f"master {res.master_id}: {'in control' if res.in_control else 'OUT OF ITS STATED U'}")
            for col in ("characteristic", "measured", "certified", "diff um", "E_n"):
                t.add_column(col, justify="right")
            for c in res.checks:
                t.add_row(c.id, "-" if c.measured is None else f"{c.measured:.4f}", f"{c.certified:.4f}",
                          "-" if c.measured is None else f"{(c.measured - c.certified) * 1e3:+.2f}",
                          "-" if c.en is None else f"{c.en:+.2f}")
            out_console.print(t)
            for a in res.alarms:
                out_console.print(f"[yellow]alarm:[/] {a.reason}")
        raise typer.Exit(0 if res.in_control else (1 if res.inspection.state == "complete" else 2))

    @check_app.command("axis")
    def check_axis(
        runs: int = typer.Option(3, "--runs", help="bidirectional runs (ISO 230-2 asks 5 of a full test)"),
        targets: int = typer.Option(11, "--targets", help="targets over the stroke the bore scans use"),
        out: Optional[Path] = typer.Option(None, "--out", help="folder for recording.csv, axis_model.toml and "
                                                               "discovery's outputs (default <data>/checks/axis/<time>)"),
        part: str = typer.Option("ZDZG-22.2-12.3851", "--part", help="the part family whose stroke is checked "
                                                                    "(built-in part number or spec file)"),
        config: Optional[Path] = typer.Option(None, "--config", help="station config TOML (default: simulated)"),
        scenario: Optional[Path] = typer.Option(None, "--scenario", help="twin scenario TOML (simulation only)"),
        data: Path = typer.Option(Path("var"), "--data", help="data folder: database, model proposals"),
        time_scale: float = typer.Option(20.0, "--time-scale", help="simulation: moves this much faster"),
        propose: bool = typer.Option(False, "--propose", help="add a model proposal when discovery names what the "
                                                              "model of Z lacks"),
        plots: bool = typer.Option(True, "--plots/--no-plots", help="discovery's residual plots (PNG)"),
        json: bool = typer.Option(False, "--json", help="one JSON object on stdout"),
    ) -> None:
        """The station's own short ISO 230-2 check of Z against its grating, and discovery
        on it (docs/monitor.md). Exit 0 when the model agrees (no-mismatch), 1 when
        discovery finds a mismatch, 2 error."""
        from station.checks.axis import AxisCheckSettings

        res = _station_check(config, scenario, time_scale, data, part,
                             lambda: AxisCheckSettings(targets=targets, runs=runs),
                             lambda s, family, settings: s.check_axis(family, settings=settings, out_dir=out,
                                                                      propose=propose, plots=plots))
        if json:
            print_json(res.to_json())
        elif res.report is None:
            out_console.print(f"[red]{res.summary()}[/]")
        else:
            r = res.report
            out_console.print(f"axis check of Z ({len(res.data.points)} points, {len(res.data.targets_mm)} targets "
                              f"{res.data.targets_mm[0]:g}..{res.data.targets_mm[-1]:g} mm, {runs} run(s) each way, "
                              f"C held at {res.data.c_deg if res.data.c_deg is not None else '?'} deg) on "
                              f"{res.model_version}: [bold]{r['verdict']}[/]")
            out_console.print(f"rms of grating - model {r['before']['rms']:.3f} um before, {r['after']['rms']:.3f} um "
                              f"after; noise floor {r['noise_floor']:.3f} um; machine time "
                              + (f"{res.machine_s:.1f} s" if res.machine_s is not None else "unknown"))
            for e in r["effects"]:
                params = ", ".join(f"{k} {v:.4g}" for k, v in e["parameters"].items())
                out_console.print(f"  effect [bold]{e['name']}[/] ({params}): {e['explanation']}")
            for f in r["findings"]:
                out_console.print(f"  finding ({f.get('stage', '')}): {f['description']}")
            for c in res.changes:
                out_console.print(f"  change {c.term} {c.delta:+.4g}")
            if res.proposal is not None:
                out_console.print(f"[yellow]model proposal {res.proposal.id}[/] (station model proposals; approve "
                                  f"with station model approve {res.proposal.id} --who NAME)")
            out_console.print(f"[dim]files in {res.out_dir}/[/]")
        raise typer.Exit(2 if res.report is None else (0 if res.verdict == "no-mismatch" else 1))

    @check_app.command("camera")
    def check_camera(
        frames: int = typer.Option(16, "--frames", help="frames of the bore wall, the table turned between them"),
        axial: Optional[float] = typer.Option(None, "--axial-mm", help="where along the bore (default: the part's "
                                                                      "first compensating hole)"),
        part: str = typer.Option("ZDZG-22.2-12.3851", "--part", help="the part family on the table (built-in part "
                                                                    "number or spec file)"),
        out: Optional[Path] = typer.Option(None, "--out", help="folder for pixel_map.json and check.json (default "
                                                               "<data>/checks/camera/<time>)"),
        config: Optional[Path] = typer.Option(None, "--config", help="station config TOML (default: simulated)"),
        scenario: Optional[Path] = typer.Option(None, "--scenario", help="twin scenario TOML (simulation only)"),
        data: Path = typer.Option(Path("var"), "--data", help="data folder: database, checks"),
        time_scale: float = typer.Option(20.0, "--time-scale", help="simulation: moves this much faster"),
        json: bool = typer.Option(False, "--json", help="one JSON object on stdout"),
    ) -> None:
        """The camera's flawed pixels (hot, dim, a trapped column) found in frames of the bore
        wall turning under it, against the station's pixel map (docs/vision.md). Exit 0 when
        the map holds them all, 1 when the sensor has flaws the map lacks, 2 error."""
        from station.checks.camera import CameraCheckSettings

        res = _station_check(config, scenario, time_scale, data, part,
                             lambda: CameraCheckSettings(frames=frames, axial_mm=axial),
                             lambda s, family, settings: s.check_camera(family, settings=settings, out_dir=out))
        if json:
            print_json(res.to_json())
        else:
            out_console.print(res.summary(), highlight=False)
            for c, a, b, o in res.new_columns:
                out_console.print(f"  new: column {c}, rows {a}-{b}, {o:+.1f} DN", highlight=False)
            if res.out_dir is not None:
                out_console.print(f"[dim]files in {res.out_dir}/[/]")
        raise typer.Exit(2 if res.state != "complete" else (0 if res.up_to_date else 1))
