"""``station token``: API tokens for the REST API (create prints the token once)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from station.cli.common import fail, out_console, print_json

token_app = typer.Typer(help="API tokens of the REST API (stored hashed in the results database).",
                        no_args_is_help=True)

DataOpt = typer.Option(Path("var"), "--data", help="data folder of the station (its database)")
DbOpt = typer.Option(None, "--db", help="database URL (default: SQLite in the data folder)")


def _repo(data: Path, db: Optional[str]):
    from station.store import Store
    from station.store.tokens import TokenRepository

    store = Store(db, data_dir=data)  # a reader: no owner lock, the server may be running
    return store, TokenRepository(store)


@token_app.command("create")
def create(role: str = typer.Option(..., "--role", help="mes, operator, engineer or admin"),
           name: str = typer.Option("", "--name", help="who or what uses it (default: the role)"),
           data: Path = DataOpt, db: Optional[str] = DbOpt) -> None:
    """Create a token and print it; it is stored hashed and cannot be shown again."""
    from station.store import StoreError

    try:
        store, repo = _repo(data, db)
    except StoreError as exc:
        fail(str(exc))
    try:
        record, token = repo.create(role, name)
    except (ValueError, StoreError) as exc:
        fail(str(exc))
    finally:
        store.close()
    typer.echo(token)
    typer.echo(f"token {record.id} ({record.name}, role {record.role}) created; keep it, it is not shown again",
               err=True)


@token_app.command("list")
def list_tokens(data: Path = DataOpt, db: Optional[str] = DbOpt,
                json: bool = typer.Option(False, "--json", help="JSON on stdout")) -> None:
    """The tokens (never their secrets)."""
    store, repo = _repo(data, db)
    try:
        tokens = repo.list()
    finally:
        store.close()
    if json:
        print_json([t.to_json() for t in tokens])
        return
    for t in tokens:
        out_console.print(f"{t.id:4d}  {t.role:8s}  {t.name}  st_{t.prefix}_...  "
                          + ("revoked" if t.revoked_at else "active"), highlight=False)


@token_app.command("revoke")
def revoke(token_id: int = typer.Argument(..., help="the token's id (station token list)"),
           data: Path = DataOpt, db: Optional[str] = DbOpt) -> None:
    """Refuse a token from now on."""
    store, repo = _repo(data, db)
    try:
        record = repo.revoke(token_id)
    except KeyError as exc:
        fail(str(exc.args[0]))
    finally:
        store.close()
    typer.echo(f"token {record.id} ({record.name}) revoked")


def register(app: typer.Typer) -> None:
    app.add_typer(token_app, name="token")
