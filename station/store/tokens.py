"""REST API tokens in the results database: created once, kept only as salted hashes.

A token reads ``st_<prefix>_<secret>``: the prefix (16 hex characters, public) finds
the row; the whole token is checked against its PBKDF2-SHA256 hash with a constant-
time comparison. The secret carries 256 random bits, so nobody guesses it; the salted
hash means a copy of the database (a backup, a support bundle) gives no usable token.
The iteration count is modest on purpose: a slow hash protects low-entropy passwords,
and every API request verifies a token, on a two-core station PC.

    tokens = TokenRepository(store)
    record, token = tokens.create("mes", name="plant MES")   # print `token` once
    tokens.verify(token) -> TokenRecord | None
"""

from __future__ import annotations

import hashlib
import hmac
import re
import secrets
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from sqlalchemy import select

from station.store.models import NAME_LEN, TOKEN_PREFIX_LEN, TOKEN_ROLES, ApiToken, utcnow

#: PBKDF2-HMAC-SHA256 iterations: about 6 ms per check here (see module docstring)
PBKDF2_ITERATIONS = 20_000
SALT_BYTES = 16
SECRET_BYTES = 32
_TOKEN = re.compile(r"^st_([0-9a-f]{%d})_([A-Za-z0-9_-]{20,128})$" % TOKEN_PREFIX_LEN)


@dataclass(frozen=True)
class TokenRecord:
    """A stored token without its secret."""

    id: int
    name: str
    role: str
    prefix: str
    created_at: datetime
    revoked_at: datetime | None

    def to_json(self) -> dict[str, Any]:
        return {"id": self.id, "name": self.name, "role": self.role, "prefix": self.prefix,
                "created_at": self.created_at.isoformat(),
                "revoked_at": None if self.revoked_at is None else self.revoked_at.isoformat()}


def _hash(token: str, salt: bytes) -> bytes:
    return hashlib.pbkdf2_hmac("sha256", token.encode(), salt, PBKDF2_ITERATIONS)


def _record(t: ApiToken) -> TokenRecord:
    return TokenRecord(t.id, t.name, t.role, t.prefix, t.created_at, t.revoked_at)


class TokenRepository:
    """Create, verify, list and revoke API tokens in a :class:`~station.store.Store`."""

    def __init__(self, store):
        self.store = store

    def create(self, role: str, name: str = "") -> tuple[TokenRecord, str]:
        """A new token of ``role``; returns the record and the token text, which is
        not stored anywhere and cannot be shown again."""
        if role not in TOKEN_ROLES:
            raise ValueError(f"role must be one of {', '.join(TOKEN_ROLES)}, not {role!r}")
        name = name or role
        if len(name) > NAME_LEN:
            raise ValueError(f"name must be at most {NAME_LEN} characters")
        prefix = secrets.token_hex(TOKEN_PREFIX_LEN // 2)
        token = f"st_{prefix}_{secrets.token_urlsafe(SECRET_BYTES)}"
        salt = secrets.token_bytes(SALT_BYTES)
        with self.store._transaction("create an API token") as s:
            row = ApiToken(name=name, role=role, prefix=prefix, salt=salt.hex(), token_hash=_hash(token, salt).hex(),
                           created_at=utcnow(), revoked_at=None)
            s.add(row)
            s.flush()
            return _record(row), token

    def verify(self, token: str) -> TokenRecord | None:
        """The token's record when ``token`` is a valid, unrevoked token; else None."""
        m = _TOKEN.match(token or "")
        if m is None:
            return None
        with self.store._transaction("check an API token", write=False) as s:
            row = s.scalar(select(ApiToken).where(ApiToken.prefix == m.group(1)))
            if row is None or row.revoked_at is not None:
                return None
            if not hmac.compare_digest(_hash(token, bytes.fromhex(row.salt)).hex(), row.token_hash):
                return None
            return _record(row)

    def list(self) -> list[TokenRecord]:
        with self.store._transaction("list API tokens", write=False) as s:
            return [_record(t) for t in s.scalars(select(ApiToken).order_by(ApiToken.id))]

    def revoke(self, token_id: int) -> TokenRecord:
        """Refuse the token from now on (KeyError when there is no such token)."""
        with self.store._transaction("revoke an API token") as s:
            row = s.get(ApiToken, token_id)
            if row is None:
                raise KeyError(f"no API token {token_id}")
            if row.revoked_at is None:
                row.revoked_at = utcnow()
            return _record(row)
