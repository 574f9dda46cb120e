"""The FastAPI app: ``create_app(settings)``.

The lifespan opens the one station session (see :mod:`api.runtime`) before the first
request and closes it after the last; the station runs on its own event loop in a
thread of this process (:mod:`api.station_thread`), apart from the requests' loop. Errors come back as JSON ``{"detail": ...}``
with a status that says whose problem it is: 4xx the request's (401 no token, 403
wrong role, 404, 409 busy or wrong state, 413 too large, 422 invalid), 503 the
store's, 504 a device or the store too slow.
"""

from __future__ import annotations

import contextlib
import logging
from pathlib import Path

from fastapi import FastAPI, HTTPException, Request, status
from fastapi.responses import JSONResponse, RedirectResponse
from fastapi.staticfiles import StaticFiles

from api import logsafe, openapi_links
from api.routes import assets, calibrate, inspections, live, monitor, ops, parts, reports, session, station, tokens
from api.runtime import StationRuntime
from api.settings import Settings
from station import __version__
from station.store import StoreError, StoreUnavailable

log = logging.getLogger("api")


def create_app(settings: Settings | None = None) -> FastAPI:
    settings = settings or Settings()

    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI):
        logsafe.install()  # after uvicorn set its logging up: no token in an access-log line
        rt = StationRuntime(settings)
        await rt.open()
        try:
            await assets.apply_active(rt)
        except BaseException:
            await rt.close()
            raise
        app.state.runtime = rt
        # the OPC UA face (api/opcua.py): after the station opens, stopped before it closes
        app.state.opcua = None
        if settings.opcua_endpoint:
            from api.opcua import OpcUaServer

            try:
                opcua = OpcUaServer(rt, settings.opcua_endpoint, cert=settings.opcua_cert, key=settings.opcua_key)
                await opcua.start()
            except BaseException:
                await rt.close()
                raise
            app.state.opcua = opcua
        try:
            yield
        finally:
            if app.state.opcua is not None:
                await app.state.opcua.stop()
            await rt.close()

    app = FastAPI(title="Bore inspection station: MES API", version=__version__, lifespan=lifespan,
                  description="Job orders in, job responses (results, QIF) out; station state, "
                              "commands, part specs, models, calibrations, reports and live data.")

    @app.exception_handler(StoreError)
    async def store_error(request: Request, exc: StoreError):
        log.error("store error: %s", exc)
        code = 503 if isinstance(exc, StoreUnavailable) else 500
        return JSONResponse({"detail": str(exc)}, status_code=code)

    # multipart framing adds a little to the file itself
    app.add_middleware(BodyLimit, limit=settings.max_upload_bytes + 64 * 1024,
                       message=f"request body larger than {settings.max_upload_bytes} bytes")

    app.add_middleware(SecurityHeaders)

    for module in (inspections, station, monitor, calibrate, parts, assets, reports, live, ops, session, tokens):
        app.include_router(module.router)

    @app.get("/", include_in_schema=False)
    async def root() -> RedirectResponse:
        return RedirectResponse("/panel/", status_code=303)

    app.mount("/panel", StaticFiles(directory=PANEL_DIR, html=True), name="panel")
    openapi_links.install(app)
    return app


class BodyLimit:
    """Refuse a request body above ``limit`` bytes with 413 (an ASGI middleware).

    A declared ``Content-Length`` above the limit is refused before a byte of the body
    is read. A body without one (``Transfer-Encoding: chunked``) is counted as it
    arrives and refused as soon as it passes the limit, so no request makes the server
    parse, buffer or spool more than ``limit`` bytes (multipart uploads are spooled
    by Starlette before the route sees them, JSON bodies read whole).
    """

    def __init__(self, app, limit: int, message: str):
        self.app, self.limit, self.message = app, limit, message

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        for name, value in scope.get("headers", ()):
            if name == b"content-length" and value.isdigit() and int(value) > self.limit:
                await JSONResponse({"detail": self.message}, status_code=413)(scope, receive, send)
                return
        received = 0

        async def limited_receive():
            nonlocal received
            message = await receive()
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > self.limit:
                    # raised inside the route's body read: FastAPI passes an
                    # HTTPException on, and the app answers it as usual (JSON 413)
                    raise HTTPException(status.HTTP_413_CONTENT_TOO_LARGE, self.message)
            return message

        await self.app(scope, limited_receive, send)


class SecurityHeaders:
    """The panel's pages may not be framed (clickjacking of its buttons) and run only
    their own scripts; no response is sniffed as another type (an ASGI middleware:
    it edits the response's start message, without Starlette's per-request task
    group and streams of ``@app.middleware``, which cost more than a small GET)."""

    NOSNIFF = (b"x-content-type-options", b"nosniff")
    PANEL = ((b"content-security-policy", None), (b"x-frame-options", b"DENY"),
             (b"referrer-policy", b"same-origin"), (b"cache-control", b"no-cache"))

    def __init__(self, app):
        self.app = app

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        panel = scope.get("path", "").startswith("/panel")

        async def with_headers(message):
            if message["type"] == "http.response.start":
                headers = list(message.get("headers", ()))
                names = {name.lower() for name, _ in headers}
                if self.NOSNIFF[0] not in names:
                    headers.append(self.NOSNIFF)
                if panel:
                    replace = {name for name, _ in self.PANEL}
                    headers = [(n, v) for n, v in headers if n.lower() not in replace]
                    headers += [(n, v if v is not None else PANEL_CSP.encode()) for n, v in self.PANEL]
                message = {**message, "headers": headers}
            await send(message)

        await self.app(scope, receive, with_headers)


#: the operator panel: static HTML, CSS and JS modules (no build step)
PANEL_DIR = Path(__file__).with_name("panel")
PANEL_CSP = ("default-src 'self'; img-src 'self' data: blob:; style-src 'self'; script-src 'self'; "
             "connect-src 'self'; frame-ancestors 'none'; base-uri 'none'; form-action 'self'")
