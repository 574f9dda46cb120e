"""``station parts list / show / check``: the part specs the station inspects against.

``check`` is for someone writing a new spec: it prints every problem of the file
(file, line, field, message) and exits non-zero, so a spec is fixed in one pass.
"""

from __future__ import annotations

from pathlib import Path

import typer
from rich.markup import escape
from rich.table import Table

from station.cli.common import err_console, fail, out_console, print_json
from station.parts import PartSpec, PartSpecError, list_parts, load_part, read_part_file

parts_app = typer.Typer(help="Part specs: bore, compensating holes, tolerances.", no_args_is_help=True)


def _limits_table(spec: PartSpec) -> Table:
    table = Table(title=f"{spec.part_number} — {spec.description}" if spec.description else spec.part_number,
                  title_justify="left")
    for name, justify in (("characteristic", "left"), ("unit", "left"), ("nominal", "right"),
                          ("lower limit", "right"), ("upper limit", "right"), ("angle / deg", "right")):
        table.add_column(name, justify=justify)
    for c in spec.characteristics():
        angle = spec.hole(c.hole_id).angle_deg
        table.add_row(c.id, c.unit, f"{c.nominal:g}", f"{c.lower_limit:g}", f"{c.upper_limit:g}", f"{angle:g}")
    return table


@parts_app.command("list")
def list_command(as_json: bool = typer.Option(False, "--json", help="print exactly one JSON array on stdout")) -> None:
    """The built-in part specs."""
    try:
        specs = list_parts()
    except PartSpecError as exc:
        fail(escape(str(exc)))
    if as_json:
        print_json([{"part_number": s.part_number, "description": s.description,
                     "bore_diameter_mm": s.bore.diameter_mm, "holes": len(s.holes)} for s in specs])
        return
    table = Table(title="Built-in part specs", title_justify="left")
    for name in ("part number", "description", "bore / mm", "holes"):
        table.add_column(name)
    for s in specs:
        table.add_row(s.part_number, s.description, f"{s.bore.diameter_mm:g}", str(len(s.holes)))
    out_console.print(table)


@parts_app.command("show")
def show_command(
    part: str = typer.Argument(..., help="a built-in part number, or a path to a .toml spec"),
    as_json: bool = typer.Option(False, "--json", help="print exactly one JSON object on stdout"),
) -> None:
    """One part spec: bore and every characteristic with its limits."""
    try:
        spec = load_part(part)
    except PartSpecError as exc:
        fail(escape(str(exc)))
    if as_json:
        print_json(spec.to_json())
        return
    out_console.print(f"bore: diameter {spec.bore.diameter_mm:g} mm, depth {spec.bore.depth_mm:g} mm", highlight=False)
    out_console.print(_limits_table(spec))


@parts_app.command("check")
def check_command(file: Path = typer.Argument(..., help="part spec file (TOML)")) -> None:
    """Validate a spec file; every problem is named, and the exit code is non-zero."""
    try:
        spec = read_part_file(file)
    except PartSpecError as exc:
        for p in exc.problems:
            err_console.print(f"[bold red]error:[/] {escape(str(p))}", highlight=False, markup=True)
        n = len(exc.problems)
        err_console.print(f"{file}: {n} problem{'s' if n != 1 else ''}", highlight=False)
        raise typer.Exit(1)
    out_console.print(f"{file}: ok — {spec.part_number}, {len(spec.holes)} holes, "
                      f"{len(spec.characteristics())} characteristics", highlight=False)


def register(app: typer.Typer) -> None:
    app.add_typer(parts_app, name="parts")
