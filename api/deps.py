"""Typed dependencies of the routes (in the manner of the FastAPI full-stack
template's ``SessionDep`` and ``CurrentUser``): a route names what it needs by its
parameter's type, and FastAPI supplies it.

* ``RuntimeDep``: the one station runtime the app's lifespan opened (:mod:`api.runtime`).
* ``ReaderDep``, ``JobOrdersDep``, ``OperatorDep``, ``EngineerDep``: the caller
  (:class:`api.auth.Principal`), admitted by the role the route needs (:mod:`api.auth`);
  a route that changes something names the narrowest one, a read ``ReaderDep``.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Request

from api import auth
from api.runtime import StationRuntime


def get_runtime(request: Request) -> StationRuntime:
    """The station runtime, kept on the app's state by the lifespan (:func:`api.app.create_app`)."""
    return request.app.state.runtime


RuntimeDep = Annotated[StationRuntime, Depends(get_runtime)]

#: any valid token or panel session
ReaderDep = Annotated[auth.Principal, Depends(auth.reader)]
#: the MES, and the operator at the panel's Start button
JobOrdersDep = Annotated[auth.Principal, Depends(auth.job_orders)]
#: station commands
OperatorDep = Annotated[auth.Principal, Depends(auth.operator)]
#: part specs, models, calibrations, reports, decisions on model proposals
EngineerDep = Annotated[auth.Principal, Depends(auth.engineer)]
