"""``station token create --expires``, ``token list`` (expiry, state, warnings) and
``token rotate`` / ``revoke`` by id or prefix, through typer's CliRunner on a data
folder's store (SQLite, or PostgreSQL with ``--db postgresql``)."""

from __future__ import annotations

import json
from datetime import timedelta

import pytest
from typer.testing import CliRunner

from station.cli import app
from station.store import Store
from station.store.models import utcnow
from station.store.tokens import TokenRepository

runner = CliRunner()


def _run(data, *args: str):
    return runner.invoke(app, ["token", *args, "--data", str(data)])


def _listed(data) -> dict[int, dict]:
    r = _run(data, "list", "--json")
    assert r.exit_code == 0, r.output
    return {t["id"]: t for t in json.loads(r.stdout)}


def _verify(data, token: str):
    with Store(data_dir=data) as store:
        return TokenRepository(store).verify(token)


def test_create_with_an_expiry_prints_the_token_once_and_says_when_it_ends(tmp_path):
    r = _run(tmp_path, "create", "--role", "mes", "--name", "plant MES", "--expires", "90d")
    assert r.exit_code == 0, r.output
    token = r.stdout.strip()
    assert token.startswith("st_") and "\n" not in token  # stdout is the token alone
    assert "expires 20" in r.stderr and "not shown again" in r.stderr
    record = _verify(tmp_path, token)
    assert abs((record.expires_at - (utcnow() + timedelta(days=90))).total_seconds()) < 60
    (listed,) = _listed(tmp_path).values()
    assert listed["expires_at"] == record.expires_at.isoformat() and listed["state"] == "active"


def test_create_without_expires_or_with_never_makes_a_token_that_does_not_end(tmp_path):
    for args in ([], ["--expires", "never"]):
        r = _run(tmp_path, "create", "--role", "operator", *args)
        assert r.exit_code == 0, r.output
        assert _verify(tmp_path, r.stdout.strip()).expires_at is None
        assert "expires never" in r.stderr


def test_create_with_an_iso_date(tmp_path):
    r = _run(tmp_path, "create", "--role", "engineer", "--expires", "2099-01-31")
    assert r.exit_code == 0, r.output
    assert _verify(tmp_path, r.stdout.strip()).expires_at.isoformat() == "2099-01-31T00:00:00+00:00"


@pytest.mark.parametrize("expires, says", [
    ("0d", "zero"), ("-5d", "negative"), ("90", "no unit"), ("soon", "cannot read"), ("2001-01-01", "not in the future"),
])
def test_create_refuses_a_zero_negative_past_or_unreadable_expiry(tmp_path, expires, says):
    r = _run(tmp_path, "create", "--role", "mes", "--expires", expires)
    assert r.exit_code == 2
    assert says in r.stderr and "--expires" in r.stderr
    assert "st_" not in r.stdout
    assert _listed(tmp_path) == {}  # nothing made


def test_list_shows_expiry_and_state_and_warns_of_tokens_ending_soon(tmp_path):
    with Store(data_dir=tmp_path) as store:
        repo = TokenRepository(store)
        forever, _ = repo.create("mes", "forever MES")
        soon, _ = repo.create("mes", "MES ending soon", expires_at=utcnow() + timedelta(days=5, hours=1))
        later, _ = repo.create("operator", "badge", expires_at=utcnow() + timedelta(days=60, hours=1))
        gone, _ = repo.create("engineer", "left the company")
        repo.revoke(gone.id)
        brief, _ = repo.create("admin", "brief", expires_at=utcnow() + timedelta(seconds=1))
    import time

    time.sleep(1.1)
    r = _run(tmp_path, "list")
    assert r.exit_code == 0, r.output
    lines = {int(line.split()[0]): line for line in r.stdout.splitlines() if line.strip()}
    assert lines[forever.id].endswith("expires never  active")
    assert lines[soon.id].endswith("expires in 5 d") and lines[later.id].endswith("expires in 60 d")
    assert lines[gone.id].endswith("revoked") and lines[brief.id].endswith("expired")
    assert f"st_{soon.prefix}_..." in lines[soon.id]
    # the warning: the one active token that ends within 14 days, and what to do
    warnings = [w for w in r.stderr.splitlines() if w.startswith("warning")]
    assert len(warnings) == 1 and f"token {soon.id} (MES ending soon, mes) expires in 5 d" in warnings[0]
    assert f"station token rotate {soon.id}" in warnings[0]
    states = {i: t["state"] for i, t in _listed(tmp_path).items()}
    assert states == {forever.id: "active", soon.id: "active", later.id: "active", gone.id: "revoked",
                      brief.id: "expired"}


def test_rotate_by_prefix_prints_the_new_token_and_keeps_the_old_one_through_the_grace(tmp_path):
    r = _run(tmp_path, "create", "--role", "mes", "--name", "plant MES", "--expires", "90d")
    old = r.stdout.strip()
    prefix = old.split("_")[1]
    r = _run(tmp_path, "rotate", f"st_{prefix[:8]}", "--grace", "1h")
    assert r.exit_code == 0, r.output
    new = r.stdout.strip()
    assert new.startswith("st_") and new != old
    assert "The old token works until" in r.stderr and "not shown again" in r.stderr
    old_rec, new_rec = _verify(tmp_path, old), _verify(tmp_path, new)
    assert old_rec is not None and new_rec is not None  # both work now
    assert (new_rec.role, new_rec.name) == ("mes", "plant MES")
    assert abs((old_rec.expires_at - (utcnow() + timedelta(hours=1))).total_seconds()) < 60
    # without --expires the new one lives as long as the old one was made to: 90 d from now
    assert abs((new_rec.expires_at - (utcnow() + timedelta(days=90))).total_seconds()) < 60
    listed = _listed(tmp_path)
    assert listed[old_rec.id]["state"] == "rotated" and listed[old_rec.id]["replaced_by"] == new_rec.id
    r = _run(tmp_path, "list")
    assert f"rotated (-> {new_rec.id}), ends in 59 min" in r.stdout
    # the rotated token cannot be rotated again, so its grace cannot be stretched
    r = _run(tmp_path, "rotate", str(old_rec.id), "--grace", "30d")
    assert r.exit_code == 2 and "already rotated" in r.stderr
    assert _verify(tmp_path, old).expires_at == old_rec.expires_at


def test_rotate_with_no_grace_and_a_new_expiry(tmp_path):
    old = _run(tmp_path, "create", "--role", "operator").stdout.strip()
    r = _run(tmp_path, "rotate", "1", "--grace", "0s", "--expires", "12w")
    assert r.exit_code == 0, r.output
    assert _verify(tmp_path, old) is None  # ended now
    new = _verify(tmp_path, r.stdout.strip())
    assert abs((new.expires_at - (utcnow() + timedelta(weeks=12))).total_seconds()) < 60


@pytest.mark.parametrize("args, says", [
    (["999"], "no API token 999"), (["nothex"], "neither a token id nor a token prefix"),
    (["1", "--grace", "-1h"], "negative"), (["1", "--grace", "soon"], "cannot read"),
    (["1", "--expires", "0d"], "zero"),
])
def test_rotate_refuses_unknown_tokens_and_bad_durations(tmp_path, args, says):
    assert _run(tmp_path, "create", "--role", "mes").exit_code == 0
    r = _run(tmp_path, "rotate", *args)
    assert r.exit_code == 2 and says in r.stderr, r.output
    assert len(_listed(tmp_path)) == 1  # nothing made


def test_revoke_by_prefix(tmp_path):
    token = _run(tmp_path, "create", "--role", "mes").stdout.strip()
    r = _run(tmp_path, "revoke", token.split("_")[1])
    assert r.exit_code == 0 and "revoked" in r.stdout
    assert _verify(tmp_path, token) is None
