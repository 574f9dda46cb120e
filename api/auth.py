"""Who is calling: API tokens with roles, checked on every request but the probes.

Roles (a token has one): ``mes`` starts job orders, ``operator`` commands the station,
``engineer`` changes part specs, models and calibrations and runs reports, ``admin``
may do everything. Any valid token may read.

A caller proves who it is in one of two ways, both checked by :func:`authenticate`
(the one dependency every route uses):

* ``Authorization: Bearer <token>`` (the MES, scripts): the header wins when present;
* the operator panel's session cookie (:mod:`api.sessions`, made by ``POST
  /api/v1/session`` with a token): a request that changes something (any method but
  GET, HEAD, OPTIONS) must also carry the session's CSRF token in ``X-CSRF-Token``,
  or it is refused with 403. A browser sends the cookie by itself; it cannot be made
  to send the header by another site (SameSite=Strict is the second line).

A token past its ``expires_at`` is refused with 401 and a message that says when it
expired, on every route, and so is a panel session opened with it. Writes are limited
per token (:mod:`api.ratelimit`): over the limit, 429 with ``Retry-After``.
"""

from __future__ import annotations

import asyncio
import dataclasses
import hashlib
import time
from dataclasses import dataclass
from datetime import datetime

from fastapi import Depends, HTTPException, Request, status
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from api.ratelimit import retry_after_s
from api.routes.common import in_api_thread
from api.sessions import CSRF_HEADER, RECHECK_S, SESSION_COOKIE, read_token
from station.store.models import utcnow

ROLES = ("mes", "operator", "engineer", "admin")

#: auto_error=False: a missing header is our 401 with a clear message, not FastAPI's 403
_bearer = HTTPBearer(auto_error=False, description="API token (`station token create --role ROLE`)")


@dataclass(frozen=True)
class Principal:
    """The caller: the token's name, role and id (for the audit log), and when the
    token ends (None: never)."""

    name: str
    role: str
    token_id: int
    expires_at: datetime | None = None

    @property
    def who(self) -> str:
        return f"{self.name} (token {self.token_id}, {self.role})"


def _unauthorized(message: str) -> HTTPException:
    return HTTPException(status.HTTP_401_UNAUTHORIZED, message, headers={"WWW-Authenticate": "Bearer"})


def _when(t: datetime) -> str:
    return t.isoformat(timespec="seconds")


def expired(what: str, expires_at: datetime) -> HTTPException:
    """401 for a token (or a session of one) past its end: says so, and when."""
    return HTTPException(status.HTTP_401_UNAUTHORIZED,
                         f"{what} expired at {_when(expires_at)}: ask an administrator for a new token "
                         "(station token create or station token rotate)",
                         headers={"WWW-Authenticate": 'Bearer error="invalid_token", '
                                                      'error_description="the token expired"'})


def _principal(record) -> Principal:
    return Principal(record.name, record.role, record.id, record.expires_at)


#: methods that change nothing: no CSRF token needed with a session cookie
SAFE_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})


#: most tokens whose slow hash check is remembered (a handful in practice)
VERIFIED_MAX = 1000

#: a token's revocation is read from the database at most this often per token: a
#: `station token revoke` (another process) takes effect within this time, and fifty
#: clients polling with one token cost one read per second, not one per request
REVOCATION_CHECK_S = 1.0


async def verify_token(request: Request, token: str) -> Principal | None:
    """The principal of a valid API token, or None; an expired one raises 401 saying so.
    (:func:`known_token` does the checking.)"""
    known = await known_token(request.app.state.runtime, token)
    if known is None:
        return None
    if known.expired(utcnow()):
        raise expired("the API token", known.expires_at)
    return _principal(known)


async def known_token(rt, token: str):
    """The record of an API token that exists and is not revoked (expired or not: the
    caller compares the expiry with its clock), or None. For REST and OPC UA alike.

    The salted PBKDF2 check runs once per token and process; after it, the token's
    SHA-256 finds the record (256 random bits: a fast hash is enough to look it up,
    the stored hash stays slow), and only its revocation and expiry are read from the
    database, at most every REVOCATION_CHECK_S per token, so ``station token revoke``
    and a rotation's shortened grace take effect within a second. Concurrent requests
    share that read (api/singleflight.py). The expiry itself is compared with the
    clock on every request.
    """
    key = hashlib.sha256(token.encode()).hexdigest()
    known = rt.verified_tokens.get(key)
    if known is None:
        record = await asyncio.wait_for(in_api_thread(rt.tokens.lookup, token), timeout=10.0)
        if record is None or record.revoked_at is not None:
            return None
        if len(rt.verified_tokens) >= VERIFIED_MAX:
            rt.verified_tokens.clear()
        rt.verified_tokens[key] = known = record  # an expired one too: refused again without the slow hash
    else:
        now = time.monotonic()
        if now - rt.token_checked.get(known.id, -REVOCATION_CHECK_S) >= REVOCATION_CHECK_S:
            stored = await rt.reads.run(("token", known.id), lambda: asyncio.wait_for(
                in_api_thread(read_token, rt.store, known.id), timeout=10.0))
            if stored is None or stored.revoked_at is not None:
                rt.verified_tokens.pop(key, None)
                rt.token_checked.pop(known.id, None)
                return None
            if (stored.expires_at, stored.replaced_by) != (known.expires_at, known.replaced_by):
                known = dataclasses.replace(known, expires_at=stored.expires_at, replaced_by=stored.replaced_by)
                rt.verified_tokens[key] = known
            rt.token_checked[known.id] = now
    return known


async def _from_session(request: Request, session_id: str) -> Principal:
    rt = request.app.state.runtime
    sess = rt.sessions.get(session_id)
    if sess is None:
        raise _unauthorized("the panel session has ended (expired, logged out or the server restarted): "
                            "log in again")
    now = time.monotonic()
    if now - sess.checked > RECHECK_S:  # a revoked token ends its sessions within RECHECK_S
        stored = await asyncio.wait_for(in_api_thread(read_token, rt.store, sess.principal.token_id),
                                        timeout=10.0)
        if stored is None or stored.revoked_at is not None:
            rt.sessions.drop_token(sess.principal.token_id)
            raise _unauthorized("the token this session was opened with has been revoked")
        if stored.expires_at != sess.principal.expires_at:  # a rotation brought its end forward
            sess.principal = dataclasses.replace(sess.principal, expires_at=stored.expires_at)
        sess.checked = now
    if sess.token_expired():  # the session ends with its token, to the second
        rt.sessions.drop(session_id)
        raise expired("the panel session's token", sess.principal.expires_at)
    if request.method not in SAFE_METHODS and not sess.csrf_ok(request.headers.get(CSRF_HEADER)):
        raise HTTPException(status.HTTP_403_FORBIDDEN,
                            f"a request with the panel's session cookie must carry its CSRF token in {CSRF_HEADER}")
    return sess.principal


def _count_write(request: Request, who: Principal) -> None:
    """A write takes one unit of its token's bucket (api/ratelimit.py): 429 when empty."""
    limiter = request.app.state.runtime.write_limiter
    wait_s = limiter.take(who.token_id)
    if wait_s > 0:
        retry = retry_after_s(wait_s)
        raise HTTPException(status.HTTP_429_TOO_MANY_REQUESTS,
                            f"too many writes with this token: the limit is {limiter.describe()}; "
                            f"retry after {retry} s", headers={"Retry-After": str(retry)})


async def authenticate(request: Request,
                       credentials: HTTPAuthorizationCredentials | None = Depends(_bearer)) -> Principal:
    """Any valid token, or a panel session (with its CSRF token for writes); 401
    without, or with an expired one. A write is then counted against the token's
    limit (429 over it); reads are not limited."""
    if credentials is None or not credentials.credentials:
        session_id = request.cookies.get(SESSION_COOKIE)
        if session_id and "authorization" not in request.headers:
            who = await _from_session(request, session_id)
        else:
            raise _unauthorized("an API token is required: send 'Authorization: Bearer <token>'")
    else:
        # the hash check and the database read block: off the event loop, bounded
        who = await verify_token(request, credentials.credentials)
        if who is None:
            raise _unauthorized("the API token is not valid (unknown, mistyped or revoked)")
    if request.method not in SAFE_METHODS:
        _count_write(request, who)
    return who


def require(*roles: str):
    """A dependency that admits tokens of ``roles`` (and admin); 403 for other roles."""
    allowed = set(roles) | {"admin"}

    async def check(principal: Principal = Depends(authenticate)) -> Principal:
        if principal.role not in allowed:
            raise HTTPException(status.HTTP_403_FORBIDDEN,
                                f"role {principal.role!r} may not do this; it needs one of: "
                                + ", ".join(sorted(allowed)))
        return principal

    return check


#: shorthands used by the routes
reader = authenticate
mes = require("mes")
#: job orders: the MES, and the operator at the panel's Start button
job_orders = require("mes", "operator")
operator = require("operator")
engineer = require("engineer")
