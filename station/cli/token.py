"""``station token``: API tokens for the REST API (create and rotate print the token once)."""

from __future__ import annotations

from datetime import datetime
from pathlib import Path
from typing import Optional

import typer

from station.cli.common import err_console, fail, out_console, print_json

token_app = typer.Typer(help="API tokens of the REST API (stored hashed in the results database).",
                        no_args_is_help=True)

DataOpt = typer.Option(Path("var"), "--data", help="data folder of the station (its database)")
DbOpt = typer.Option(None, "--db", envvar="STATION_DB_URL",
                     help="database URL (default: SQLite in the data folder; also $STATION_DB_URL)")
ExpiresHelp = ("when the token stops working: a duration (90d, 12w, 24h, 30m; s m h d w), an ISO date or "
               "date and time (2027-01-31, 2027-01-31T18:00+01:00; UTC without an offset), or 'never'")


def _repo(data: Path, db: Optional[str]):
    from station.store import Store
    from station.store.tokens import TokenRepository

    store = Store(db, data_dir=data)  # a reader: no owner lock, the server may be running
    return store, TokenRepository(store)


def _when(t: datetime | None) -> str:
    return "never" if t is None else t.isoformat(timespec="seconds")


def _in(seconds: float) -> str:
    """A time span as a person reads it: 83 d, 5 h, 12 min, 40 s."""
    for unit, n in (("d", 86400.0), ("h", 3600.0), ("min", 60.0)):
        if seconds >= n:
            return f"{int(seconds // n)} {unit}"
    return f"{max(0, int(seconds))} s"


def state_text(record, now: datetime) -> str:
    """active / expires in N d / rotated (-> id), ends in N h / expired / revoked."""
    state = record.state(now)
    if state in ("revoked", "expired"):
        return state
    if state == "rotated":
        return f"rotated (-> {record.replaced_by}), ends in {_in((record.expires_at - now).total_seconds())}"
    if record.expires_at is None:
        return "active"
    return f"expires in {_in((record.expires_at - now).total_seconds())}"


@token_app.command("create")
def create(role: str = typer.Option(..., "--role", help="mes, operator, engineer or admin"),
           name: str = typer.Option("", "--name", help="who or what uses it (default: the role)"),
           expires: str = typer.Option("never", "--expires", help=ExpiresHelp + " (default: never)"),
           data: Path = DataOpt, db: Optional[str] = DbOpt) -> None:
    """Create a token and print it; it is stored hashed and cannot be shown again."""
    from station.store import StoreError
    from station.store.tokens import parse_expiry

    try:
        expires_at = parse_expiry(expires)
    except ValueError as exc:
        fail(f"--expires: {exc}")
    try:
        store, repo = _repo(data, db)
    except StoreError as exc:
        fail(str(exc))
    try:
        record, token = repo.create(role, name, expires_at=expires_at, by="station token create")
    except (ValueError, StoreError) as exc:
        fail(str(exc))
    finally:
        store.close()
    typer.echo(token)
    typer.echo(f"token {record.id} ({record.name}, role {record.role}, st_{record.prefix}_...) created; "
               f"expires {_when(record.expires_at)}; keep it, it is not shown again", err=True)


@token_app.command("list")
def list_tokens(data: Path = DataOpt, db: Optional[str] = DbOpt,
                json: bool = typer.Option(False, "--json", help="JSON on stdout")) -> None:
    """The tokens (never their secrets), with their expiry and state; warns of tokens
    that expire within 14 days."""
    from station.store.models import utcnow
    from station.store.tokens import EXPIRY_WARNING_DAYS

    store, repo = _repo(data, db)
    try:
        tokens = repo.list()
    finally:
        store.close()
    now = utcnow()
    if json:
        print_json([t.to_json(now) for t in tokens])
    else:
        for t in tokens:
            out_console.print(f"{t.id:4d}  {t.role:8s}  {t.name}  st_{t.prefix}_...  expires {_when(t.expires_at)}  "
                              + state_text(t, now), highlight=False, markup=False)
    for t in tokens:
        if (t.state(now) == "active" and t.expires_at is not None
                and (t.expires_at - now).total_seconds() < EXPIRY_WARNING_DAYS * 86400.0):
            err_console.print(f"warning: token {t.id} ({t.name}, {t.role}) expires in "
                              f"{_in((t.expires_at - now).total_seconds())} ({_when(t.expires_at)}): rotate it "
                              f"before then (station token rotate {t.id})", highlight=False, markup=False)


@token_app.command("rotate")
def rotate(token: str = typer.Argument(..., metavar="ID_OR_PREFIX",
                                       help="the token's id or its prefix (st_0123abcd..., station token list)"),
           grace: str = typer.Option("24h", "--grace", help="how long the old token keeps working (0 s: it ends "
                                                            "now); never past its own expiry"),
           expires: Optional[str] = typer.Option(None, "--expires", help=ExpiresHelp + " (default: as long as "
                                                 "the old token was made to live; never if it had no end)"),
           data: Path = DataOpt, db: Optional[str] = DbOpt) -> None:
    """Replace a token by a new one of the same role and name, printed once; the old
    one keeps working until the grace ends, so its client can switch without downtime."""
    from station.store import StoreError
    from station.store.models import utcnow
    from station.store.tokens import parse_duration, parse_expiry

    try:
        grace_s = parse_duration(grace, allow_zero=True)
    except ValueError as exc:
        fail(f"--grace: {exc}")
    expires_in_s = None
    if expires is not None:
        try:
            now = utcnow()
            end = parse_expiry(expires, now)
        except ValueError as exc:
            fail(f"--expires: {exc}")
        expires_in_s = None if end is None else (end - now).total_seconds()
    store, repo = _repo(data, db)
    try:
        old = repo.find(token)
        old, new, text = repo.rotate(old.id, grace_s=grace_s, expires_in_s=expires_in_s,
                                     keep_expiry=expires is None, by="station token rotate")
    except KeyError as exc:
        fail(str(exc.args[0]))
    except (ValueError, StoreError) as exc:  # a refused rotation (TokenStateError) says why
        fail(str(exc))
    finally:
        store.close()
    typer.echo(text)
    typer.echo(f"token {new.id} ({new.name}, role {new.role}, st_{new.prefix}_...) replaces token {old.id}; "
               f"it expires {_when(new.expires_at)}; keep it, it is not shown again. The old token works until "
               f"{_when(old.expires_at)}.", err=True)


@token_app.command("revoke")
def revoke(token: str = typer.Argument(..., metavar="ID_OR_PREFIX",
                                       help="the token's id or its prefix (station token list)"),
           data: Path = DataOpt, db: Optional[str] = DbOpt) -> None:
    """Refuse a token from now on."""
    store, repo = _repo(data, db)
    try:
        record = repo.revoke(repo.find(token).id, by="station token revoke")
    except KeyError as exc:
        fail(str(exc.args[0]))
    finally:
        store.close()
    typer.echo(f"token {record.id} ({record.name}) revoked")


def register(app: typer.Typer) -> None:
    app.add_typer(token_app, name="token")
