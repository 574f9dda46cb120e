"""The FastAPI app: ``create_app(settings)``.

The lifespan opens the one station session (see :mod:`api.runtime`) before the first
request and closes it after the last. Errors come back as JSON ``{"detail": ...}``
with a status that says whose problem it is: 4xx the request's (401 no token, 403
wrong role, 404, 409 busy or wrong state, 413 too large, 422 invalid), 503 the
store's, 504 a device or the store too slow.
"""

from __future__ import annotations

import contextlib
import logging

from fastapi import FastAPI, Request
from fastapi.responses import JSONResponse

from api.routes import assets, inspections, live, ops, parts, reports, station
from api.runtime import StationRuntime
from api.settings import Settings
from station import __version__
from station.store import StoreError, StoreUnavailable

log = logging.getLogger("api")


def create_app(settings: Settings | None = None) -> FastAPI:
    settings = settings or Settings()

    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI):
        rt = StationRuntime(settings)
        await rt.open()
        try:
            assets.apply_active(rt)
        except BaseException:
            await rt.close()
            raise
        app.state.runtime = rt
        try:
            yield
        finally:
            await rt.close()

    app = FastAPI(title="Bore inspection station: MES API", version=__version__, lifespan=lifespan,
                  description="Job orders in, job responses (results, QIF) out; station state, "
                              "commands, part specs, models, calibrations, reports and live data.")

    @app.middleware("http")
    async def limit_body(request: Request, call_next):
        """Refuse a declared body above the upload limit before reading it."""
        length = request.headers.get("content-length")
        # multipart framing adds a little to the file itself
        if length is not None and length.isdigit() and int(length) > settings.max_upload_bytes + 64 * 1024:
            return JSONResponse({"detail": f"request body larger than {settings.max_upload_bytes} bytes"},
                                status_code=413)
        return await call_next(request)

    @app.exception_handler(StoreError)
    async def store_error(request: Request, exc: StoreError):
        log.error("store error: %s", exc)
        code = 503 if isinstance(exc, StoreUnavailable) else 500
        return JSONResponse({"detail": str(exc)}, status_code=code)

    for module in (inspections, station, parts, assets, reports, live, ops):
        app.include_router(module.router)
    return app
