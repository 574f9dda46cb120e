"""The operator panel's login: ``POST /api/v1/session`` with an API token opens a
browser session (cookie + CSRF token, see :mod:`api.sessions`), ``GET`` tells who is
logged in (and the CSRF token), ``DELETE`` logs out."""

from __future__ import annotations

import asyncio
import time
from datetime import datetime, timezone

from fastapi import APIRouter, HTTPException, Request, Response, status
from pydantic import BaseModel, ConfigDict, Field

from api import auth
from api.deps import ReaderDep, RuntimeDep
from api.routes.common import blocking
from api.runtime import StationRuntime
from api.schemas.session import Caller, LoggedOut, PanelSession
from api.sessions import ABSOLUTE_S, SESSION_COOKIE

router = APIRouter(prefix="/api/v1", tags=["panel session"])

#: a failed login waits this long: slows down a script trying tokens (they have 256
#: random bits anyway) without bothering an operator who mistyped
FAILED_LOGIN_DELAY_S = 0.5


class Login(BaseModel):
    model_config = ConfigDict(extra="forbid")
    token: str = Field(min_length=1, max_length=256, description="an API token (station token create)")


def _iso(epoch: float) -> str:
    return datetime.fromtimestamp(epoch, timezone.utc).isoformat()


def _origin_ok(request: Request) -> bool:
    """A login from another site's page is refused (login CSRF): a browser sends
    ``Origin`` with every POST; scripts without one are not browsers."""
    origin = request.headers.get("origin")
    if origin is None:
        return True
    return origin == f"{request.url.scheme}://{request.headers.get('host', '')}"


def _secure(rt: StationRuntime, request: Request) -> bool:
    """The cookie is ``Secure`` over https, and always when the settings say the
    station is served behind TLS (``cookie_secure``)."""
    return rt.settings.cookie_secure or request.url.scheme == "https"


def _session_json(who: auth.Principal, sess) -> dict:
    return {"name": who.name, "role": who.role, "token_id": who.token_id, "kind": "session",
            "csrf_token": sess.csrf_token, "expires_at": _iso(sess.expires_at)}


@router.post("/session", response_model=PanelSession,
             responses={401: {"description": "not a valid token"},
                        403: {"description": "a login from another site's page"}})
async def login(body: Login, request: Request, response: Response, rt: RuntimeDep) -> dict:
    """Log in to the panel with an API token: sets the session cookie (HttpOnly,
    SameSite=Strict, Secure over https or with the setting ``cookie_secure``) and
    returns the CSRF token to send as ``X-CSRF-Token`` with every write. The session
    ends no later than the token (``expires_at``); an expired token gets 401."""
    if not _origin_ok(request):
        raise HTTPException(status.HTTP_403_FORBIDDEN, "login from another site's page refused")
    who = await auth.verify_token(request, body.token.strip())
    if who is None:
        await asyncio.sleep(FAILED_LOGIN_DELAY_S)
        raise HTTPException(status.HTTP_401_UNAUTHORIZED, "this token is not valid (unknown, mistyped or revoked)")
    rt.sessions.drop(request.cookies.get(SESSION_COOKIE))  # a new login replaces the old session
    session_id, sess = rt.sessions.create(who)
    # the browser forgets the cookie when the session ends: a shift, or the token's end
    max_age = max(1, int(min(ABSOLUTE_S, sess.expires_at - time.time())))
    response.set_cookie(SESSION_COOKIE, session_id, max_age=max_age, path="/", httponly=True,
                        samesite="strict", secure=_secure(rt, request))
    response.headers["Cache-Control"] = "no-store"
    await blocking(rt.store.log_event, "audit", f"{who.who}: logged in to the panel")
    return _session_json(who, sess)


@router.get("/session", response_model=Caller, response_model_exclude_unset=True)
async def whoami(request: Request, response: Response, rt: RuntimeDep, who: ReaderDep) -> dict:
    """Who is calling; with a session cookie also its CSRF token and end."""
    response.headers["Cache-Control"] = "no-store"
    sess = None if "authorization" in request.headers else rt.sessions.get(
        request.cookies.get(SESSION_COOKIE))
    if sess is None:
        return {"name": who.name, "role": who.role, "token_id": who.token_id, "kind": "token"}
    return _session_json(who, sess)


@router.delete("/session", response_model=LoggedOut,
               responses={404: {"description": "no panel session (a Bearer token)"}})
async def logout(request: Request, response: Response, rt: RuntimeDep, who: ReaderDep) -> dict:
    """Log out: the session ends on the server and the cookie is cleared."""
    if "authorization" in request.headers or not rt.sessions.drop(request.cookies.get(SESSION_COOKIE)):
        raise HTTPException(status.HTTP_404_NOT_FOUND,
                            "no panel session to end (API tokens are revoked with `station token revoke`)")
    response.delete_cookie(SESSION_COOKIE, path="/", httponly=True, samesite="strict", secure=_secure(rt, request))
    await blocking(rt.store.log_event, "audit", f"{who.who}: logged out of the panel")
    return {"ended": True, "time": _iso(time.time())}
