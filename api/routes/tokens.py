"""A client rotates its own API token: ``POST /api/v1/tokens/rotate``.

Rotation without downtime: the caller gets a new token of the same role and name,
once, in the answer; the token it called with keeps working for a grace period (a
day unless it asks for less), so it can switch over between two requests and no
request fails. The old token's end is only ever brought forward, never pushed back,
and a rotated token cannot be rotated again. The new token lives as long as the old
one was made to live (``expires_at - created_at``; no end if the old one had none)
and never longer: a token cannot make itself a longer-lived one (an administrator
can, with ``station token rotate``). Audited in the store's event log (no secret).

Only a Bearer caller can rotate: a panel session has no token of its own to swap
(its operator's badge token is rotated by an administrator), so a cookie caller gets
400.
"""

from __future__ import annotations

import dataclasses

from fastapi import APIRouter, Body, HTTPException, Request, Response, status
from pydantic import BaseModel, ConfigDict, Field

from api.deps import ReaderDep, RuntimeDep
from api.routes.common import blocking
from api.schemas.tokens import OldToken, RotatedToken
from station.store.tokens import DEFAULT_GRACE_S, MAX_LIFETIME_S, TokenStateError

router = APIRouter(prefix="/api/v1", tags=["tokens"])

#: longest grace a client may give its old token (a week): enough to roll a new token
#: out to every instance of a client; an old token that lives on for longer is no rotation
MAX_SELF_GRACE_S = 7 * 86400.0


class RotateRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")
    grace_s: float = Field(DEFAULT_GRACE_S, ge=0, le=MAX_SELF_GRACE_S,
                           description="seconds the old token keeps working (0: it ends now; default a day); "
                                       "never beyond its own expiry")
    expires_in_s: float | None = Field(None, gt=0, le=MAX_LIFETIME_S,
                                       description="the new token's lifetime in seconds (default: the old "
                                                   "token's lifetime; not longer than it)")


@router.post("/tokens/rotate", response_model=RotatedToken,
             responses={400: {"description": "a panel session: no token to rotate"},
                        409: {"description": "the token was already rotated"},
                        422: {"description": "a longer life than the token's own, or a bad body"}})
async def rotate_own_token(request: Request, response: Response, rt: RuntimeDep, who: ReaderDep,
                           body: RotateRequest | None = Body(None)) -> RotatedToken:
    """Swap the calling token for a new one; the old one keeps working for ``grace_s``."""
    if "authorization" not in request.headers:
        raise HTTPException(status.HTTP_400_BAD_REQUEST,
                            "a panel session has no token of its own to rotate: call with "
                            "'Authorization: Bearer <token>', or ask an administrator (station token rotate)")
    body = body or RotateRequest()
    try:
        old, new, token = await blocking(rt.tokens.rotate, who.token_id, grace_s=body.grace_s,
                                         expires_in_s=body.expires_in_s, keep_expiry=True, self_service=True,
                                         by=f"{who.who} over the API")
    except TokenStateError as exc:
        raise HTTPException(status.HTTP_409_CONFLICT, str(exc)) from None
    except ValueError as exc:
        raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, str(exc)) from None
    except KeyError as exc:
        raise HTTPException(status.HTTP_404_NOT_FOUND, str(exc.args[0])) from None
    # this process knows the old token's new end at once (others read it within a second)
    for key, known in list(rt.verified_tokens.items()):
        if known.id == old.id:
            rt.verified_tokens[key] = dataclasses.replace(known, expires_at=old.expires_at,
                                                          replaced_by=old.replaced_by)
    rt.write_limiter.transfer(old.id, new.id)  # a rotation buys no fresh burst of writes
    response.headers["Cache-Control"] = "no-store"
    return RotatedToken(token=token, id=new.id, prefix=new.prefix, name=new.name, role=new.role,
                        expires_at=new.expires_at, old=OldToken(id=old.id, prefix=old.prefix,
                                                                expires_at=old.expires_at))
