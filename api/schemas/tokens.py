"""A rotated API token (``POST /tokens/rotate``)."""

from __future__ import annotations

from datetime import datetime

from pydantic import BaseModel, Field


class OldToken(BaseModel):
    id: int
    prefix: str = Field(description="the old token's public prefix")
    expires_at: datetime = Field(description="when the old token stops working (end of the grace)")


class RotatedToken(BaseModel):
    token: str = Field(description="the new token: shown once, stored only as a hash")
    id: int
    prefix: str = Field(description="the new token's public prefix (st_<prefix>_...)")
    name: str
    role: str
    expires_at: datetime | None = Field(description="when the new token expires (null: never)")
    old: OldToken
