"""Who is calling: API tokens with roles, checked on every request but the probes.

Roles (a token has one): ``mes`` starts job orders, ``operator`` commands the station,
``engineer`` changes part specs, models and calibrations and runs reports, ``admin``
may do everything. Any valid token may read.

Today a token comes as ``Authorization: Bearer <token>``. The operator panel will log
in with a browser cookie later: :func:`authenticate` is the one place to add it (look
up a session cookie when there is no header), and every route keeps its dependency.
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass

from fastapi import Depends, HTTPException, Request, status
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

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


async def authenticate(request: Request,
                       credentials: HTTPAuthorizationCredentials | None = Depends(_bearer)) -> Principal:
    """Any valid token; 401 without one."""
    if credentials is None or not credentials.credentials:
        raise _unauthorized("an API token is required: send 'Authorization: Bearer <token>'")
    tokens = request.app.state.runtime.tokens
    # the hash check and the database read block: off the event loop, bounded
    record = await asyncio.wait_for(asyncio.to_thread(tokens.verify, credentials.credentials), timeout=10.0)
    if record is None:
        raise _unauthorized("the API token is not valid (unknown, mistyped or revoked)")
    return Principal(record.name, record.role, record.id)


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
operator = require("operator")
engineer = require("engineer")
