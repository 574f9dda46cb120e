"""REST API tokens in the results database: created once, kept only as salted hashes.

A token reads ``st_<prefix>_<secret>``: the prefix (16 hex characters, public) finds
the row; the whole token is checked against its PBKDF2-SHA256 hash with a constant-
time comparison. The secret carries 256 random bits, so nobody guesses it; the salted
hash means a copy of the database (a backup, a support bundle) gives no usable token.
The iteration count is modest on purpose: a slow hash protects low-entropy passwords,
and every API request verifies a token, on a two-core station PC.

A token may have an end (``expires_at``; None: never, the default, see docs/security.md,
Tokens) and is replaced without downtime by a rotation: a new token of the same role
and name, while the old one keeps working for a grace period and then ends. Creation,
rotation and revocation are written to the store's event log (kind ``audit``; the
token's id, name, role and public prefix, never its secret).

    tokens = TokenRepository(store)
    record, token = tokens.create("mes", name="plant MES", expires_at=in_90_days)  # print `token` once
    tokens.verify(token) -> TokenRecord | None          # active tokens only
    tokens.lookup(token) -> TokenRecord | None          # any genuine token: say why it is refused
    old, new, token = tokens.rotate(old.id, grace_s=86400.0)
"""

from __future__ import annotations

import hashlib
import hmac
import math
import re
import secrets
from dataclasses import dataclass
from datetime import date, datetime, timedelta, timezone
from typing import Any

from sqlalchemy import select

from station.store.models import NAME_LEN, TOKEN_PREFIX_LEN, TOKEN_ROLES, ApiToken, utcnow

#: PBKDF2-HMAC-SHA256 iterations: about 6 ms per check here (see module docstring)
PBKDF2_ITERATIONS = 20_000
SALT_BYTES = 16
SECRET_BYTES = 32
_TOKEN = re.compile(r"^st_([0-9a-f]{%d})_([A-Za-z0-9_-]{20,128})$" % TOKEN_PREFIX_LEN)

#: `station token list` warns of active tokens that end within this many days: time to
#: rotate before an MES stops on a 401
EXPIRY_WARNING_DAYS = 14
#: the old token's grace after a rotation when none is given: a day, so a client that
#: reloads its configuration once a shift has switched before the old one ends
DEFAULT_GRACE_S = 24 * 3600.0
#: the longest a token may live or a grace last (about 100 years): beyond this the
#: datetime arithmetic overflows, and nobody means it
MAX_LIFETIME_S = 100 * 365.25 * 86400.0


class TokenStateError(ValueError):
    """A token cannot be rotated (revoked, expired, already rotated)."""


@dataclass(frozen=True)
class TokenRecord:
    """A stored token without its secret."""

    id: int
    name: str
    role: str
    prefix: str
    created_at: datetime
    revoked_at: datetime | None
    expires_at: datetime | None = None
    replaced_by: int | None = None

    def expired(self, now: datetime | None = None) -> bool:
        return self.expires_at is not None and (now or utcnow()) >= self.expires_at

    def active(self, now: datetime | None = None) -> bool:
        """Neither revoked nor expired (a rotated token is active until its grace ends)."""
        return self.revoked_at is None and not self.expired(now)

    def state(self, now: datetime | None = None) -> str:
        """``revoked``, ``expired``, ``rotated`` (superseded, in its grace) or ``active``."""
        if self.revoked_at is not None:
            return "revoked"
        if self.expired(now):
            return "expired"
        return "rotated" if self.replaced_by is not None else "active"

    def to_json(self, now: datetime | None = None) -> dict[str, Any]:
        return {"id": self.id, "name": self.name, "role": self.role, "prefix": self.prefix,
                "created_at": self.created_at.isoformat(),
                "revoked_at": None if self.revoked_at is None else self.revoked_at.isoformat(),
                "expires_at": None if self.expires_at is None else self.expires_at.isoformat(),
                "replaced_by": self.replaced_by, "state": self.state(now)}


def _hash(token: str, salt: bytes) -> bytes:
    return hashlib.pbkdf2_hmac("sha256", token.encode(), salt, PBKDF2_ITERATIONS)


def _record(t: ApiToken) -> TokenRecord:
    return TokenRecord(t.id, t.name, t.role, t.prefix, t.created_at, t.revoked_at, t.expires_at, t.replaced_by)


def _describe(r: TokenRecord) -> str:
    """How the audit log names a token: id, name, role and public prefix (no secret)."""
    return f"token {r.id} ({r.name}, role {r.role}, st_{r.prefix}_...)"


def _iso(t: datetime | None) -> str:
    return "never" if t is None else t.isoformat(timespec="seconds")


# ------------------------------------------------------------------ durations and dates
_UNITS_S = {"s": 1.0, "m": 60.0, "h": 3600.0, "d": 86400.0, "w": 7 * 86400.0}
_PART = re.compile(r"(\d+(?:\.\d+)?)([smhdw])")


def parse_duration(text: str, *, allow_zero: bool = False) -> float:
    """Seconds of a duration such as ``90d``, ``24h``, ``1d12h``, ``30m``, ``45s``,
    ``2w`` (s, m, h, d, w; parts add up). A bare number, a negative, zero (unless
    ``allow_zero``) or anything else is refused with a ValueError that says why."""
    s = (text or "").strip().lower().replace(" ", "")
    if not s:
        raise ValueError("a duration is empty: write e.g. 90d, 24h, 30m (s, m, h, d, w)")
    if allow_zero and re.fullmatch(r"0+(\.0*)?", s):
        return 0.0
    if s.startswith("-"):
        raise ValueError(f"duration {text!r} is negative: it must be positive")
    if re.fullmatch(r"\d+(\.\d+)?", s):
        raise ValueError(f"duration {text!r} has no unit: write e.g. {s}d or {s}h (s, m, h, d, w)")
    parts = _PART.findall(s)
    if not parts or "".join(n + u for n, u in parts) != s:
        raise ValueError(f"cannot read {text!r} as a duration: write e.g. 90d, 24h, 1d12h (s, m, h, d, w)")
    seconds = sum(float(n) * _UNITS_S[u] for n, u in parts)
    if seconds <= 0 and not allow_zero:
        raise ValueError(f"duration {text!r} is zero: it must be positive")
    if seconds > MAX_LIFETIME_S:
        raise ValueError(f"duration {text!r} is longer than 100 years")
    return seconds


def parse_expiry(text: str, now: datetime | None = None) -> datetime | None:
    """When a token given ``--expires text`` ends: ``never`` (None), a duration from
    ``now`` (``90d``, see :func:`parse_duration`), or an ISO 8601 date or date and time
    (a date means 00:00 UTC of that day; a time without an offset is UTC). A time not
    in the future is refused (ValueError)."""
    now = now or utcnow()
    s = (text or "").strip()
    if s.lower() in ("never", "none"):
        return None
    if re.fullmatch(r"\d{4}-\d{2}-\d{2}.*", s):
        try:
            when = (datetime.combine(date.fromisoformat(s), datetime.min.time()) if len(s) == 10
                    else datetime.fromisoformat(s))
        except ValueError:
            raise ValueError(f"cannot read {text!r} as an ISO date or date and time "
                             "(e.g. 2027-01-31 or 2027-01-31T18:00+01:00)") from None
        if when.tzinfo is None or when.utcoffset() is None:
            when = when.replace(tzinfo=timezone.utc)
        when = when.astimezone(timezone.utc)
        if when <= now:
            raise ValueError(f"expiry {when.isoformat(timespec='seconds')} is not in the future")
        return when
    try:
        return now + timedelta(seconds=parse_duration(s))
    except ValueError as exc:
        raise ValueError(f"{exc}; or an ISO date (2027-01-31), or 'never'") from None


def _later(seconds: float | None, now: datetime, what: str) -> datetime | None:
    if seconds is None:
        return None
    if not (math.isfinite(seconds) and 0 < seconds <= MAX_LIFETIME_S):
        raise ValueError(f"{what} must be a positive number of seconds up to 100 years, not {seconds!r}")
    return now + timedelta(seconds=seconds)


# ------------------------------------------------------------------------- repository
class TokenRepository:
    """Create, verify, list, rotate and revoke API tokens in a :class:`~station.store.Store`."""

    def __init__(self, store):
        self.store = store

    def _audit(self, message: str) -> None:
        # after the token's own transaction (the store's log_event stamps the station);
        # a failure here must not hide the token that was made: the caller prints it
        try:
            self.store.log_event("audit", message)
        except Exception:  # noqa: BLE001 - the token is made; the audit is best effort
            import logging

            logging.getLogger("station.store").exception("cannot write the audit event %r", message)

    @staticmethod
    def _new_row(role: str, name: str, expires_at: datetime | None, now: datetime) -> tuple[ApiToken, str]:
        prefix = secrets.token_hex(TOKEN_PREFIX_LEN // 2)
        token = f"st_{prefix}_{secrets.token_urlsafe(SECRET_BYTES)}"
        salt = secrets.token_bytes(SALT_BYTES)
        return ApiToken(name=name, role=role, prefix=prefix, salt=salt.hex(), token_hash=_hash(token, salt).hex(),
                        created_at=now, revoked_at=None, expires_at=expires_at, replaced_by=None), token

    def create(self, role: str, name: str = "", *, expires_at: datetime | None = None,
               by: str | None = None) -> tuple[TokenRecord, str]:
        """A new token of ``role`` ending at ``expires_at`` (None: never); returns the
        record and the token text, which is not stored anywhere and cannot be shown again."""
        if role not in TOKEN_ROLES:
            raise ValueError(f"role must be one of {', '.join(TOKEN_ROLES)}, not {role!r}")
        name = name or role
        if len(name) > NAME_LEN:
            raise ValueError(f"name must be at most {NAME_LEN} characters")
        now = utcnow()
        if expires_at is not None:
            if expires_at.tzinfo is None or expires_at.utcoffset() is None:
                raise ValueError("expires_at must be an aware datetime")
            if expires_at <= now:
                raise ValueError(f"expiry {_iso(expires_at)} is not in the future")
        with self.store.transaction("create an API token") as s:
            row, token = self._new_row(role, name, expires_at, now)
            s.add(row)
            s.flush()
            record = _record(row)
        self._audit(f"{_describe(record)} created{f' by {by}' if by else ''}; expires {_iso(record.expires_at)}")
        return record, token

    def lookup(self, token: str) -> TokenRecord | None:
        """The record of a genuine token (its hash matches), whatever its state; None
        for anything else. Callers say why a genuine one is refused (expired, revoked)."""
        m = _TOKEN.match(token or "")
        if m is None:
            return None
        with self.store.transaction("check an API token", write=False) as s:
            row = s.scalar(select(ApiToken).where(ApiToken.prefix == m.group(1)))
            if row is None:
                return None
            if not hmac.compare_digest(_hash(token, bytes.fromhex(row.salt)).hex(), row.token_hash):
                return None
            return _record(row)

    def verify(self, token: str) -> TokenRecord | None:
        """The token's record when ``token`` is a valid, unrevoked, unexpired token; else None."""
        record = self.lookup(token)
        return record if record is not None and record.active() else None

    def get(self, token_id: int) -> TokenRecord | None:
        with self.store.transaction("read an API token", write=False) as s:
            row = s.get(ApiToken, token_id)
            return None if row is None else _record(row)

    def find(self, id_or_prefix: str | int) -> TokenRecord:
        """A token by its id (``12``) or its public prefix (``st_0123...``, or at least
        the first 6 of its hex digits, as `station token list` shows it); KeyError when
        none or more than one matches."""
        text = str(id_or_prefix).strip()
        prefix = text.removeprefix("st_").split("_", 1)[0].rstrip(".").lower()
        is_prefix = bool(re.fullmatch(r"[0-9a-f]{6,%d}" % TOKEN_PREFIX_LEN, prefix))
        # a prefix is hex: "005875" reads as an id too; both are looked up, and a text
        # that names two different tokens is refused rather than guessed
        by_id = self.get(int(text)) if text.isdigit() else None
        if not is_prefix:
            if by_id is not None:
                return by_id
            if text.isdigit():
                raise KeyError(f"no API token {text}")
            raise KeyError(f"{text!r} is neither a token id nor a token prefix (st_ and at least 6 hex digits)")
        with self.store.transaction("find an API token", write=False) as s:
            rows = list(s.scalars(select(ApiToken).where(ApiToken.prefix.startswith(prefix)).limit(2)))
        if len(rows) > 1:
            raise KeyError(f"more than one API token has the prefix {prefix}: give more of it, or the id")
        if rows and by_id is not None and rows[0].id != by_id.id:
            raise KeyError(f"{text} is token {by_id.id}'s id and token {rows[0].id}'s prefix: "
                           f"write the prefix as st_{prefix}")
        if rows:
            return _record(rows[0])
        if by_id is not None:
            return by_id
        raise KeyError(f"no API token with prefix {prefix}" if not text.isdigit() else f"no API token {text}")

    def list(self) -> list[TokenRecord]:
        with self.store.transaction("list API tokens", write=False) as s:
            return [_record(t) for t in s.scalars(select(ApiToken).order_by(ApiToken.id))]

    def rotate(self, token_id: int, *, grace_s: float = DEFAULT_GRACE_S, expires_in_s: float | None = None,
               keep_expiry: bool = False, self_service: bool = False,
               by: str | None = None) -> tuple[TokenRecord, TokenRecord, str]:
        """Replace token ``token_id`` by a new one of the same role and name; returns
        (old record, new record, new token text). The old token keeps working for
        ``grace_s`` more seconds (0: it ends now) and never longer than it would have:
        its ``expires_at`` becomes ``min(expires_at, now + grace_s)``.

        The new token ends ``expires_in_s`` from now (None: never), or, with
        ``keep_expiry``, lives as long as the old one was made to live (its
        ``expires_at - created_at``; never when the old one had no end).
        ``self_service`` (a client rotating its own token over the API) may not get a
        longer life than that: a token that expires cannot make itself one that does
        not, or one that lives longer (ValueError).

        KeyError for an unknown token; TokenStateError for a revoked, expired or
        already rotated one (a rotated token cannot be rotated again: its grace stays
        what the first rotation set).
        """
        if not (math.isfinite(grace_s) and 0 <= grace_s <= MAX_LIFETIME_S):
            raise ValueError(f"grace must be 0 to 100 years in seconds, not {grace_s!r}")
        now = utcnow()
        new_expires = _later(expires_in_s, now, "the new token's lifetime")
        with self.store.transaction("rotate an API token") as s:
            old = s.get(ApiToken, token_id, with_for_update=True)
            if old is None:
                raise KeyError(f"no API token {token_id}")
            current = _record(old)
            if current.state(now) != "active":
                detail = {"revoked": f"was revoked at {_iso(old.revoked_at)}",
                          "expired": f"expired at {_iso(old.expires_at)}",
                          "rotated": f"was already rotated (replaced by token {old.replaced_by}; "
                                     f"it ends at {_iso(old.expires_at)})"}[current.state(now)]
                raise TokenStateError(f"token {old.id} cannot be rotated: it {detail}")
            lifetime = None if old.expires_at is None else old.expires_at - old.created_at
            if keep_expiry and expires_in_s is None and lifetime is not None:
                new_expires = now + lifetime
            if self_service and lifetime is not None:
                if new_expires is None or new_expires - now > lifetime + timedelta(seconds=1):
                    raise ValueError(f"this token was made to live {_span(lifetime)}: it cannot make itself a "
                                     "token that lives longer (an administrator can: station token rotate)")
            new_row, token = self._new_row(old.role, old.name, new_expires, now)
            s.add(new_row)
            s.flush()
            end = now + timedelta(seconds=grace_s)
            old.expires_at = end if old.expires_at is None else min(old.expires_at, end)
            old.replaced_by = new_row.id
            s.flush()
            old_record, new_record = _record(old), _record(new_row)
        self._audit(f"{_describe(old_record)} rotated{f' by {by}' if by else ''}: replaced by {_describe(new_record)}, "
                    f"which expires {_iso(new_record.expires_at)}; the old one ends {_iso(old_record.expires_at)}")
        return old_record, new_record, token

    def revoke(self, token_id: int, *, by: str | None = None) -> TokenRecord:
        """Refuse the token from now on (KeyError when there is no such token)."""
        with self.store.transaction("revoke an API token") as s:
            row = s.get(ApiToken, token_id, with_for_update=True)
            if row is None:
                raise KeyError(f"no API token {token_id}")
            changed = row.revoked_at is None
            if changed:
                row.revoked_at = utcnow()
            record = _record(row)
        if changed:
            self._audit(f"{_describe(record)} revoked{f' by {by}' if by else ''}")
        return record


def _span(t: timedelta) -> str:
    s = t.total_seconds()
    for unit, n in (("d", 86400.0), ("h", 3600.0), ("m", 60.0)):
        if s >= n:
            return f"{s / n:.4g} {unit}"
    return f"{s:.0f} s"
