"""``station calibrate master``: self-calibration of the station's error model on a
certified artefact (issue 21, docs/calibration.md)."""

from __future__ import annotations

import json as _json
from pathlib import Path
from typing import Optional

import typer

from station.cli.common import json_default, err_console, fail, out_console, print_json


def register(app: typer.Typer) -> None:
    calibrate_app = typer.Typer(help="self-calibration of the station's error model", no_args_is_help=True)
    app.add_typer(calibrate_app, name="calibrate")

    @calibrate_app.command("master")
    def calibrate_master(
        artefact: str = typer.Option("CA-22.2-5x8", "--artefact", help="a built-in artefact's id or a certificate file"),
        poses: int = typer.Option(40, "--poses", help="poses to measure (chosen for observability)"),
        out: Path = typer.Option(..., "--out", help="folder for calibration.json and observability.json"),
        config: Optional[Path] = typer.Option(None, "--config", help="station config TOML (default: simulated)"),
        scenario: Optional[Path] = typer.Option(None, "--scenario", help="twin scenario TOML (simulation only)"),
        data: Path = typer.Option(Path("var"), "--data", help="data folder: database, model proposals"),
        time_scale: float = typer.Option(20.0, "--time-scale", help="simulation: moves this much faster"),
        seed: int = typer.Option(0, "--seed", help="simulation: the artefact's making"),
        json: bool = typer.Option(False, "--json", help="one JSON object on stdout"),
        propose: bool = typer.Option(False, "--propose", help="make a model proposal of the observable parameters "
                                     "(approve it with station model approve)"),
        min_significance: float = typer.Option(2.0, "--min-significance", help="with --propose: change an observable "
                                               "parameter only when it differs from the present model by more than "
                                               "this many u (0: every one)"),
    ) -> None:
        """Measure the artefact at planned (Z, C) poses with the camera and the grating,
        identify the error model's parameters with the certificate as prior, and report
        which parameters the plan can see. In simulation each parameter carries the
        world's truth as an annotation. Exit 0 done, 2 error."""
        import asyncio

        from drivers.interfaces import DriverError
        from station.calibration.artefact import load_artefact
        from station.calibration.run import calibrate
        from station.runtime import open_session
        from station.runtime import ConfigError
        from station.sequencer.engine import PlanEnded
        from station.store.errors import StoreError

        if scenario is not None and not scenario.is_file():
            fail(f"{scenario}: no such scenario file", 2)
        if poses < 1:
            fail(f"--poses must be at least 1, not {poses}", 2)
        if not 0.0 <= min_significance <= 10.0:
            fail(f"--min-significance must be within 0 ... 10, not {min_significance}", 2)
        try:
            cert = load_artefact(artefact)
        except ValueError as exc:
            fail(str(exc), 2)

        def say(text: str) -> None:
            err_console.print(f"[dim]calibrate:[/] {text}", highlight=False)

        async def go():
            async with open_session(config, scenario=scenario, time_scale=time_scale, data_dir=data) as s:
                outcome = await calibrate(s, cert, n_poses=poses, seed=seed, progress=say)
                proposal = None
                if propose:
                    from station.calibration.proposal import propose_from_calibration
                    from station.monitor.proposals import ProposalError

                    try:
                        proposal = await propose_from_calibration(s, outcome, cert.artefact_id,
                                                                  min_significance=min_significance)
                    except ProposalError as exc:
                        say(f"no model proposal: {exc}")
                return outcome, proposal

        try:
            res, proposal = asyncio.run(go())
        except PlanEnded as exc:
            fail(f"the calibration run did not complete: {exc}", 2)
        except (ConfigError, StoreError, DriverError, OSError, ValueError) as exc:
            fail(str(exc), 2)
        doc = res.to_json(model_version=None if proposal is None else proposal.id)
        try:
            out.mkdir(parents=True, exist_ok=True)
            full = {**doc, "artefact": {"id": cert.artefact_id, "certificate": cert.certificate},
                    "model": res.par.base.name, "nodes": {"z_mm": list(res.par.z_nodes_mm), "c_deg": list(res.par.c_nodes_deg)},
                    "cycle": res.cycle, "wall_s": res.wall_s, "run": res.run.to_json(),
                    "target_deviations_um": [{"name": n, "value": float(v)} for n, v in
                                             zip(res.result.names[res.par.size:], res.result.value[res.par.size:])]}
            (out / "calibration.json").write_text(_json.dumps(full, indent=2, default=json_default, allow_nan=False) + "\n")
            rep = {**res.report.to_dict(), "singular_values": res.report.singular_values,
                   "observable": [n for n, o in zip(res.par.names, res.report.observable) if o]}
            (out / "observability.json").write_text(_json.dumps(rep, indent=2, default=json_default) + "\n")
        except OSError as exc:
            fail(f"{out}: {exc.strerror or exc}", 2)
        say(f"rank {doc['observability']['rank']} of {doc['observability']['n_parameters']}, "
            f"{sum(p['observable'] for p in doc['parameters'])} model parameters observable, residual rms "
            f"{doc['residual_rms_um']:.2f} um, machine time "
            + ("unknown" if doc["machine_s"] is None else f"{doc['machine_s']:.0f} s") + f"; files in {out}/")
        if proposal is not None:
            say(f"model proposal {proposal.id}: {len(proposal.changes)} observable parameter(s) changed, the rest kept "
                f"(station model proposals --data {data}; approve with station model approve)")
        if json:
            print_json(doc)
            return
        for p in doc["parameters"]:
            if p["observable"]:
                t = "" if "truth" not in p else f"  (truth {p['truth']:+.2f})"
                out_console.print(f"{p['name']:>14} {p['value']:+8.2f} +/- {p['u']:.2f} {p['unit']}{t}")
        for c in doc["observability"]["unobservable"]:
            out_console.print(f"[yellow]unobservable:[/] {c['name']}: {c['description']}")
