"""Probes: the process answers, the store and the station are reachable."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from api.schemas.common import ClosedModel


class Health(ClosedModel):
    status: Literal["ok"]


class Readiness(ClosedModel):
    """Whether the station can take work (200), or what is not reachable (503)."""

    ready: bool
    checks: dict[str, str] = Field(description="`store` and `station`: `ok`, or the error that says why not")
