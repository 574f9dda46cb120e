"""API tokens that expire and are rotated (station/store/tokens.py): the durations and
dates ``--expires`` and ``--grace`` take, and the repository's rules, on the store
under test (SQLite, or PostgreSQL with ``--db postgresql``) with a clock of the test's
own: a token ends at its ``expires_at``; a rotation gives the old token a grace that
only ever brings its end forward; a rotated token cannot be rotated again; a client
rotating its own token cannot give the new one a longer life; every step is audited
without the secret."""

from __future__ import annotations

from datetime import datetime, timedelta, timezone

import pytest

from station.store import Store
from station.store import tokens as tokens_mod
from station.store.tokens import (
    DEFAULT_GRACE_S,
    TokenRepository,
    TokenStateError,
    parse_duration,
    parse_expiry,
)

T0 = datetime(2027, 3, 1, 6, 0, tzinfo=timezone.utc)


# ------------------------------------------------------------------ durations and dates
@pytest.mark.parametrize("text, seconds", [
    ("90d", 90 * 86400.0), ("24h", 86400.0), ("30m", 1800.0), ("45s", 45.0), ("2w", 14 * 86400.0),
    ("1d12h", 1.5 * 86400.0), ("1.5h", 5400.0), (" 7D ", 7 * 86400.0), ("1h 30m", 5400.0),
])
def test_durations_are_read_with_their_units(text, seconds):
    assert parse_duration(text) == seconds


@pytest.mark.parametrize("text, says", [
    ("0d", "zero"), ("0s", "zero"), ("-5d", "negative"), ("-1h", "negative"), ("90", "no unit"),
    ("", "empty"), ("soon", "cannot read"), ("5x", "cannot read"), ("5d3", "cannot read"), ("d", "cannot read"),
    ("200000w", "100 years"),
])
def test_zero_negative_and_unreadable_durations_are_refused_saying_why(text, says):
    with pytest.raises(ValueError, match=says):
        parse_duration(text)


def test_a_grace_may_be_zero():
    assert parse_duration("0", allow_zero=True) == 0.0
    assert parse_duration("0s", allow_zero=True) == 0.0
    with pytest.raises(ValueError, match="negative"):
        parse_duration("-1s", allow_zero=True)


def test_expiry_is_a_duration_a_date_a_time_or_never():
    assert parse_expiry("90d", T0) == T0 + timedelta(days=90)
    assert parse_expiry("never", T0) is None
    assert parse_expiry("NEVER", T0) is None
    # a date is 00:00 UTC of that day; a time without an offset is UTC; an offset is honoured
    assert parse_expiry("2027-06-30", T0) == datetime(2027, 6, 30, tzinfo=timezone.utc)
    assert parse_expiry("2027-06-30T18:00", T0) == datetime(2027, 6, 30, 18, tzinfo=timezone.utc)
    assert parse_expiry("2027-06-30T18:00+02:00", T0) == datetime(2027, 6, 30, 16, tzinfo=timezone.utc)
    assert parse_expiry("2027-06-30T18:00+02:00", T0).tzinfo == timezone.utc


@pytest.mark.parametrize("text, says", [
    ("2027-02-28", "not in the future"), ("2027-03-01T06:00:00Z", "not in the future"),
    ("2027-13-01", "ISO date"), ("0d", "zero"), ("-90d", "negative"), ("tomorrow", "cannot read"),
])
def test_an_expiry_in_the_past_or_unreadable_is_refused(text, says):
    with pytest.raises(ValueError, match=says):
        parse_expiry(text, T0)


# --------------------------------------------------------------------------- repository
class Clock:
    """The repository's ``utcnow``, moved by the test."""

    def __init__(self, t: datetime):
        self.t = t

    def __call__(self) -> datetime:
        return self.t

    def advance(self, **kw) -> None:
        self.t += timedelta(**kw)


@pytest.fixture
def clock(monkeypatch) -> Clock:
    c = Clock(T0)
    monkeypatch.setattr(tokens_mod, "utcnow", c)
    return c


@pytest.fixture
def repo(tmp_path):
    with Store(data_dir=tmp_path) as store:
        yield TokenRepository(store)


def test_a_token_ends_at_its_expiry(repo, clock):
    record, token = repo.create("mes", "plant MES", expires_at=T0 + timedelta(days=90))
    assert record.expires_at == T0 + timedelta(days=90)
    assert repo.verify(token) == record and record.state(T0) == "active"
    clock.advance(days=90)  # exactly at the end: over
    assert repo.verify(token) is None
    assert repo.lookup(token) == record and record.state(clock.t) == "expired"  # genuine, but expired
    assert repo.lookup(token[:-1] + ("A" if token[-1] != "A" else "B")) is None


def test_a_token_without_expiry_never_ends(repo, clock):
    record, token = repo.create("operator")
    assert record.expires_at is None
    clock.advance(days=3650)
    assert repo.verify(token) == record


def test_a_token_cannot_be_made_already_expired(repo, clock):
    with pytest.raises(ValueError, match="not in the future"):
        repo.create("mes", expires_at=T0)
    with pytest.raises(ValueError, match="aware"):
        repo.create("mes", expires_at=datetime(2030, 1, 1))


def test_rotation_keeps_the_old_token_through_its_grace(repo, clock):
    old, old_token = repo.create("mes", "plant MES")
    was, new, new_token = repo.rotate(old.id, grace_s=3600.0)
    assert (new.role, new.name) == ("mes", "plant MES") and new.id != old.id and new_token != old_token
    assert was.expires_at == T0 + timedelta(hours=1) and was.replaced_by == new.id
    assert new.expires_at is None  # the old one had no end: neither has the new one
    clock.advance(minutes=59)
    assert repo.verify(old_token) is not None and repo.verify(new_token) is not None
    clock.advance(minutes=1)
    assert repo.verify(old_token) is None and repo.verify(new_token) is not None


def test_the_default_grace_is_a_day(repo, clock):
    old, _ = repo.create("mes")
    was, _new, _ = repo.rotate(old.id)
    assert was.expires_at == T0 + timedelta(seconds=DEFAULT_GRACE_S) == T0 + timedelta(days=1)


def test_a_grace_never_extends_the_old_token(repo, clock):
    old, old_token = repo.create("mes", expires_at=T0 + timedelta(hours=2))
    was, _new, _ = repo.rotate(old.id, grace_s=7 * 86400.0)
    assert was.expires_at == T0 + timedelta(hours=2)  # not T0 + 7 d
    clock.advance(hours=2)
    assert repo.verify(old_token) is None


def test_a_rotated_token_cannot_be_rotated_again(repo, clock):
    old, _ = repo.create("mes")
    was, new, _ = repo.rotate(old.id, grace_s=3600.0)
    with pytest.raises(TokenStateError, match="already rotated"):
        repo.rotate(old.id, grace_s=7 * 86400.0)
    assert repo.get(old.id).expires_at == was.expires_at  # its grace stays what it was
    repo.rotate(new.id, grace_s=60.0)  # the successor can, in turn


def test_expired_and_revoked_tokens_cannot_be_rotated(repo, clock):
    short, _ = repo.create("mes", expires_at=T0 + timedelta(minutes=5))
    gone, _ = repo.create("mes")
    repo.revoke(gone.id)
    clock.advance(minutes=5)
    with pytest.raises(TokenStateError, match="expired"):
        repo.rotate(short.id)
    with pytest.raises(TokenStateError, match="revoked"):
        repo.rotate(gone.id)
    with pytest.raises(KeyError):
        repo.rotate(999_999)


def test_the_new_tokens_life_and_the_self_service_cap(repo, clock):
    old, _ = repo.create("mes", expires_at=T0 + timedelta(days=90))
    clock.advance(days=80)
    # keep_expiry: the new token lives as long as the old one was made to (90 d from now)
    _was, new, _ = repo.rotate(old.id, keep_expiry=True, self_service=True)
    assert new.expires_at == clock.t + timedelta(days=90)
    # a client may ask for a shorter life, not a longer one, nor none
    with pytest.raises(ValueError, match="lives longer"):
        repo.rotate(new.id, expires_in_s=91 * 86400.0, self_service=True)
    with pytest.raises(ValueError, match="lives longer"):
        repo.rotate(new.id, expires_in_s=None, self_service=True)
    assert repo.get(new.id).replaced_by is None  # a refused rotation changed nothing
    _was, shorter, _ = repo.rotate(new.id, expires_in_s=30 * 86400.0, self_service=True)
    assert shorter.expires_at == clock.t + timedelta(days=30)
    # an administrator (the CLI) may give any life, or none
    _was, forever, _ = repo.rotate(shorter.id, expires_in_s=None)
    assert forever.expires_at is None


def test_tokens_are_found_by_id_or_prefix(repo, clock):
    a, token = repo.create("mes")
    assert repo.find(str(a.id)) == a
    assert repo.find(a.prefix) == a and repo.find(f"st_{a.prefix}_...") == a and repo.find(a.prefix[:6]) == a
    assert repo.find(token) == a  # the whole token works too (its secret is not used)
    with pytest.raises(KeyError, match="no API token"):
        repo.find("999999")
    with pytest.raises(KeyError, match="neither"):
        repo.find("abc")  # too short to be a prefix


def test_create_rotate_and_revoke_are_audited_without_the_secret(repo, clock):
    old, old_token = repo.create("mes", "plant MES", expires_at=T0 + timedelta(days=90), by="station token create")
    _was, new, new_token = repo.rotate(old.id, grace_s=600.0, by="station token rotate")
    repo.revoke(new.id, by="station token revoke")
    repo.revoke(new.id)  # a second revocation changes nothing and is not logged again
    messages = [e.message for e in repo.store.events(kind="audit", limit=100)]
    text = "\n".join(messages)
    assert len(messages) == 3, messages
    assert f"token {old.id} (plant MES, role mes, st_{old.prefix}_...) created by station token create" in text
    assert f"token {old.id} (plant MES, role mes, st_{old.prefix}_...) rotated by station token rotate" in text
    assert f"token {new.id} (plant MES, role mes, st_{new.prefix}_...) revoked by station token revoke" in text
    for token in (old_token, new_token):
        assert token not in text and token[len("st_") + 16 + 1:] not in text


def test_a_prefix_of_decimal_digits_is_found_as_a_prefix(repo):
    """Hex prefixes are made of decimal digits alone about 6 % of the time at 6 digits:
    such a text is looked up as an id and as a prefix; one match is the token, two
    different ones are refused (never a guess)."""
    a, _ = repo.create("mes")
    b, _ = repo.create("mes")
    digits = "0123456789abcdef"
    with repo.store.transaction("give a token a decimal prefix") as s:
        from station.store.models import ApiToken

        s.get(ApiToken, b.id).prefix = "9876543210" + digits[:6]
    assert repo.find("987654").id == b.id  # six decimal digits, no such id: the prefix
    assert repo.find(str(a.id)).id == a.id  # a short id is an id
    with repo.store.transaction("give a token a prefix that is another's id") as s:
        s.get(ApiToken, b.id).prefix = f"{a.id:06d}" + "abcdefabcd"
    with pytest.raises(KeyError, match="id and token"):
        repo.find(f"{a.id:06d}")
    assert repo.find(f"st_{a.id:06d}abc").id == b.id
