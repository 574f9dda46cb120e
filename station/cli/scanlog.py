"""``station scanlog ...``: the station's own scan logs as recordings, and discovery on them."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from station.cli.common import fail, out_console, print_json

scanlog_app = typer.Typer(help="Scan logs: commanded vs grating position of every inspection, as recordings.",
                          no_args_is_help=True)


def _merged(data: Path):
    from station.inspection.scanlog import SCANLOG_DIR, merge_scan_logs
    from station.recording import RecordingError

    paths = sorted((data / SCANLOG_DIR).glob("*.csv"))
    if not paths:
        fail(f"no scan logs in {data / SCANLOG_DIR} (run inspections first)")
    try:
        return merge_scan_logs(paths), len(paths)
    except RecordingError as exc:
        fail(str(exc))


@scanlog_app.command("export")
def export(data: Path = typer.Option(Path("var"), "--data"), out: Path = typer.Option(..., "--out")) -> None:
    """Merge every scan log into one recording (the discovery contract's CSV)."""
    rec, n = _merged(data)
    rec.to_csv(out)
    out_console.print(f"{n} scan logs, {len(rec)} approaches -> {out}")


@scanlog_app.command("discover")
def discover_cmd(
    data: Path = typer.Option(Path("var"), "--data"),
    out: Path = typer.Option(Path("out/scanlog-discovery"), "--out"),
    model: Optional[Path] = typer.Option(None, "--model", help="station model TOML (default: built-in)"),
    json: bool = typer.Option(False, "--json"),
) -> None:
    """Discovery on the scan logs against what the station model believes of Z (EZZ)."""
    from station.axis_model import AxisModel
    from station.discovery.engine import discover, write_outputs
    from station.kinematics.model import ModelConfigError, load_model

    rec, _ = _merged(data)
    try:
        m = load_model(model)
    except ModelConfigError as exc:
        fail(str(exc))
    belief = AxisModel(name="Z", kind="linear", curve=m.motions_of("Z").z)
    d = discover(belief, rec)
    write_outputs(d, out)
    if json:
        print_json(d.report)
    else:
        r = d.report
        out_console.print(f"verdict {r['verdict']}: rms {r['before']['rms']:.3f} -> {r['after']['rms']:.3f} um; "
                          f"effects {', '.join(e['name'] for e in r['effects']) or 'none'}; report in {out}/")


def register(app: typer.Typer) -> None:
    app.add_typer(scanlog_app, name="scanlog")
