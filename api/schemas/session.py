"""The operator panel's session: who is calling."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from api.schemas.common import ClosedModel, IsoTime


class Caller(ClosedModel):
    """Who is calling: the token's name, role and id; with a session cookie also the
    session's CSRF token and end (absent for a Bearer caller)."""

    name: str
    role: str = Field(description="mes, operator, engineer or admin")
    token_id: int
    kind: Literal["token", "session"] = Field(description="a Bearer token, or a panel session")
    csrf_token: str | None = Field(default=None, description="send as X-CSRF-Token with every write (sessions only)")
    expires_at: IsoTime | None = Field(default=None, description="when the session ends (sessions only)")


class PanelSession(Caller):
    """A panel session just opened."""

    csrf_token: str = Field(description="send as X-CSRF-Token with every write")
    expires_at: IsoTime = Field(description="when the session ends: a shift, or the token's end")


class LoggedOut(ClosedModel):
    ended: bool
    time: IsoTime
