"""``station results list / show / qif``: what the results store holds.

These commands only read: they open the store without taking the station's owner
lock and without recovering interrupted inspections (that is the running station's
job), and a data folder without a database stays without one.
"""

from __future__ import annotations

import sys
from datetime import datetime, timezone
from pathlib import Path
from typing import Optional

import typer
from rich.markup import escape
from rich.table import Table

from station import __version__
from station.cli.common import err_console, fail, out_console, print_json
from station.exports.qif import finished_qif_bytes
from station.store import DEFAULT_DATA_DIR, InspectionNotFound, InspectionStateError, Store, StoreError
from station.store.engine import default_url, sqlite_file

results_app = typer.Typer(help="Inspection results: list, show, QIF.", no_args_is_help=True)

_DATA_HELP = "data folder holding station.db and images/"
_DB_HELP = "database URL (default: sqlite in the data folder; postgresql+psycopg://... for a server)"


def _open(data: Path, db: Optional[str]) -> Store | None:
    """The store, or None when the default SQLite file does not exist yet."""
    url = db or default_url(data)
    f = sqlite_file(url)
    if f is not None and not f.exists():
        return None
    try:
        return Store(url, data_dir=data)
    except StoreError as exc:
        fail(escape(str(exc)))


def _when(t: datetime | None) -> str:
    return "–" if t is None else t.astimezone(timezone.utc).strftime("%Y-%m-%d %H:%M:%S")


def _num(v: float | None) -> str:
    return "–" if v is None else f"{v:.4f}".rstrip("0").rstrip(".")


def _parse_time(name: str, text: Optional[str]) -> datetime | None:
    if text is None:
        return None
    try:
        t = datetime.fromisoformat(text)
    except ValueError:
        fail(f"{name}: not an ISO 8601 time: {text!r} (e.g. 2025-03-01T08:00:00+00:00)")
    return t if t.tzinfo is not None else t.replace(tzinfo=timezone.utc)  # plain times are read as UTC


@results_app.command("list")
def list_command(
    part: Optional[str] = typer.Option(None, "--part", help="part number"),
    serial: Optional[str] = typer.Option(None, "--serial", help="serial number"),
    result: Optional[str] = typer.Option(None, "--result", help="pass or fail"),
    state: Optional[str] = typer.Option(None, "--state", help="running, complete, aborted, faulted, interrupted"),
    station: Optional[str] = typer.Option(None, "--station", help="one station's id (several stations may "
                                          "share a database: docs/plant.md)"),
    since: Optional[str] = typer.Option(None, "--since", help="started at or after (ISO 8601; UTC if no offset)"),
    until: Optional[str] = typer.Option(None, "--until", help="started before (ISO 8601; UTC if no offset)"),
    limit: int = typer.Option(50, "--limit", min=1, max=1000, help="at most this many"),
    offset: int = typer.Option(0, "--offset", min=0, help="skip this many (paging)"),
    as_json: bool = typer.Option(False, "--json", help="print exactly one JSON array on stdout"),
    data: Path = typer.Option(DEFAULT_DATA_DIR, "--data", help=_DATA_HELP),
    db: Optional[str] = typer.Option(None, "--db", envvar="STATION_DB_URL", help=_DB_HELP),
) -> None:
    """Inspections, newest first."""
    if result is not None and result not in ("pass", "fail"):
        fail(f"--result must be pass or fail, not {result!r}")
    t_since, t_until = _parse_time("--since", since), _parse_time("--until", until)
    store = _open(data, db)
    if store is None:
        if as_json:
            print_json([])
        else:
            err_console.print(f"no results store in {data} yet (no inspection has run)", highlight=False)
        return
    with store:
        try:
            rows = store.list_inspections(since=t_since, until=t_until, part_number=part, serial=serial,
                                          result=result, state=state, station=station, limit=limit,
                                          offset=offset)
            total = store.count_inspections(since=t_since, until=t_until, part_number=part, serial=serial,
                                            result=result, state=state, station=station)
        except (StoreError, ValueError) as exc:
            fail(escape(str(exc)))
    if as_json:
        print_json([r.to_json() for r in rows])
        return
    table = Table(title=f"Inspections {offset + 1 if rows else 0}–{offset + len(rows)} of {total}",
                  title_justify="left")
    for name in ("id", "station", "started (UTC)", "part", "serial", "state", "result"):
        table.add_column(name)
    for r in rows:
        table.add_row(r.id, r.station_id or "–", _when(r.started_at), r.part_number, r.serial or "–", r.state,
                      r.result or "–")
    out_console.print(table)


@results_app.command("show")
def show_command(
    inspection_id: str = typer.Argument(..., help="inspection id"),
    as_json: bool = typer.Option(False, "--json", help="print exactly one JSON object on stdout"),
    data: Path = typer.Option(DEFAULT_DATA_DIR, "--data", help=_DATA_HELP),
    db: Optional[str] = typer.Option(None, "--db", envvar="STATION_DB_URL", help=_DB_HELP),
) -> None:
    """One inspection: header, characteristics with limits, image crops, events."""
    store = _open(data, db)
    if store is None:
        fail(f"no inspection {inspection_id!r}: no results store in {data} yet")
    with store:
        try:
            rec = store.get(inspection_id)
            events = store.events(inspection_id, limit=1000)
        except InspectionNotFound as exc:
            fail(escape(str(exc)))
        except StoreError as exc:
            fail(escape(str(exc)))
    if as_json:
        print_json({**rec.to_json(), "events": [e.to_json() for e in events]})
        return
    out_console.print(
        f"inspection {rec.id}\n  part {rec.part_number}, serial {rec.serial or '–'}, order {rec.order_id or '–'}\n"
        f"  {rec.state}" + (f", {rec.result.upper()}" if rec.result else "")
        + (f" — {rec.reason}" if rec.reason else "")
        + f"\n  started {_when(rec.started_at)} UTC, finished {_when(rec.finished_at)}",
        highlight=False, markup=False)
    table = Table(title="Characteristics", title_justify="left")
    for name, justify in (("characteristic", "left"), ("unit", "left"), ("nominal", "right"), ("lower", "right"),
                          ("upper", "right"), ("measured", "right"), ("U (k=2)", "right"), ("", "left")):
        table.add_column(name, justify=justify)
    for c in rec.characteristics:
        verdict = "[green]pass[/]" if c.passed else "[bold red]FAIL[/]"
        table.add_row(c.characteristic_id, c.unit, _num(c.nominal), _num(c.lower_limit), _num(c.upper_limit),
                      _num(c.measured), _num(c.uncertainty_k2), verdict)
    out_console.print(table)
    for i in rec.images:
        out_console.print(f"image {i.subject}: {i.path} (sha256 {i.sha256[:16]}…)", highlight=False, markup=False)
    for e in events:
        out_console.print(f"{_when(e.at)}  {e.kind}: {e.message}", highlight=False, markup=False)


@results_app.command("qif")
def qif_command(
    inspection_id: str = typer.Argument(..., help="inspection id"),
    out: Optional[Path] = typer.Option(None, "--out", help="write the document to this file (default: stdout)"),
    data: Path = typer.Option(DEFAULT_DATA_DIR, "--data", help=_DATA_HELP),
    db: Optional[str] = typer.Option(None, "--db", envvar="STATION_DB_URL", help=_DB_HELP),
) -> None:
    """A finished inspection as a QIF 3.0 results document (the same bytes as the REST
    API's GET /api/v1/inspections/ID/qif); a running one has no results yet."""
    store = _open(data, db)
    if store is None:
        fail(f"no inspection {inspection_id!r}: no results store in {data} yet")
    with store:
        try:
            rec = store.get(inspection_id)
        except StoreError as exc:  # InspectionNotFound among them
            fail(escape(str(exc)))
    try:
        body = finished_qif_bytes(rec, software_version=__version__)
    except InspectionStateError as exc:
        fail(escape(str(exc)))
    if out is None:
        sys.stdout.buffer.write(body)
        sys.stdout.flush()
        return
    try:
        out.write_bytes(body)
    except OSError as exc:
        fail(escape(f"cannot write {out}: {exc}"))
    err_console.print(f"QIF of inspection {rec.id} written to {out}", highlight=False, markup=False)


def register(app: typer.Typer) -> None:
    app.add_typer(results_app, name="results")
