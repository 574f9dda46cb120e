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
"""

from __future__ import annotations

import asyncio
import hashlib
import time
from dataclasses import dataclass

from fastapi import Depends, HTTPException, Request, status
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from api.routes.common import in_api_thread
from api.sessions import CSRF_HEADER, RECHECK_S, SESSION_COOKIE, token_is_active

ROLES = ("mes", "operator", "engineer", "admin")

#: auto_error=False: a missing header is our 401 with a clear message, not FastAPI's 403
_bearer = HTTPBearer(auto_error=False, description="API token (`station token create --role ROLE`)")


@dataclass(frozen=True)
class Principal:
    """The caller: the token's name, role and id (for the audit log)."""

    name: str
    role: str
    token_id: int

    @property
    def who(self) -> str:
        return f"{self.name} (token {self.token_id}, {self.role})"


def _unauthorized(message: str) -> HTTPException:
    return HTTPException(status.HTTP_401_UNAUTHORIZED, message, headers={"WWW-Authenticate": "Bearer"})


#: methods that change nothing: no CSRF token needed with a session cookie
SAFE_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})


#: most tokens whose slow hash check is remembered (a handful in practice)
VERIFIED_MAX = 1000

#: a token's revocation is read from the database at most this often per token: a
#: `station token revoke` (another process) takes effect within this time, and fifty
#: clients polling with one token cost one read per second, not one per request
REVOCATION_CHECK_S = 1.0


async def verify_token(request: Request, token: str) -> Principal | None:
    """The principal of a valid API token, or None.

    The salted PBKDF2 check runs once per token and process; after it, the token's
    SHA-256 finds the record (256 random bits: a fast hash is enough to look it up,
    the stored hash stays slow), and only its revocation is read from the database,
    at most every REVOCATION_CHECK_S per token, so ``station token revoke`` takes
    effect within a second. Concurrent requests share that read (api/singleflight.py).
    """
    rt = request.app.state.runtime
    key = hashlib.sha256(token.encode()).hexdigest()
    known = rt.verified_tokens.get(key)
    if known is None:
        record = await asyncio.wait_for(in_api_thread(rt.tokens.verify, token), timeout=10.0)
        if record is None:
            return None
        if len(rt.verified_tokens) >= VERIFIED_MAX:
            rt.verified_tokens.clear()
        rt.verified_tokens[key] = record
        return Principal(record.name, record.role, record.id)
    now = time.monotonic()
    if now - rt.token_checked.get(known.id, -REVOCATION_CHECK_S) >= REVOCATION_CHECK_S:
        active = await rt.reads.run(("token", known.id), lambda: asyncio.wait_for(
            in_api_thread(token_is_active, rt.store, known.id), timeout=10.0))
        if not active:
            rt.verified_tokens.pop(key, None)
            rt.token_checked.pop(known.id, None)
            return None
        rt.token_checked[known.id] = now
    return Principal(known.name, known.role, known.id)


async def _from_session(request: Request, session_id: str) -> Principal:
    rt = request.app.state.runtime
    sess = rt.sessions.get(session_id)
    if sess is None:
        raise _unauthorized("the panel session has ended (expired, logged out or the server restarted): "
                            "log in again")
    now = time.monotonic()
    if now - sess.checked > RECHECK_S:  # a revoked token ends its sessions within RECHECK_S
        active = await asyncio.wait_for(in_api_thread(token_is_active, rt.store, sess.principal.token_id),
                                        timeout=10.0)
        if not active:
            rt.sessions.drop_token(sess.principal.token_id)
            raise _unauthorized("the token this session was opened with has been revoked")
        sess.checked = now
    if request.method not in SAFE_METHODS and not sess.csrf_ok(request.headers.get(CSRF_HEADER)):
        raise HTTPException(status.HTTP_403_FORBIDDEN,
                            f"a request with the panel's session cookie must carry its CSRF token in {CSRF_HEADER}")
    return sess.principal


async def authenticate(request: Request,
                       credentials: HTTPAuthorizationCredentials | None = Depends(_bearer)) -> Principal:
    """Any valid token, or a panel session (with its CSRF token for writes); 401 without."""
    if credentials is None or not credentials.credentials:
        session_id = request.cookies.get(SESSION_COOKIE)
        if session_id and "authorization" not in request.headers:
            return await _from_session(request, session_id)
        raise _unauthorized("an API token is required: send 'Authorization: Bearer <token>'")
    # the hash check and the database read block: off the event loop, bounded
    who = await verify_token(request, credentials.credentials)
    if who is None:
        raise _unauthorized("the API token is not valid (unknown, mistyped or revoked)")
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
