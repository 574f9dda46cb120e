"""Live data for the panel: Server-Sent Events and the camera as MJPEG.

``GET /api/v1/events`` is ``text/event-stream``: first a ``state`` event with the
station's status, then every engine event (``state``, ``progress``, ``note``,
``retry``, ``fault``), ``job`` (started, finished) and ``result`` (the job response
of a finished inspection), each ``id:``/``event:``/``data: <JSON>``; a comment line
every few seconds keeps proxies from closing a quiet stream.

``GET /api/v1/camera.mjpg`` is ``multipart/x-mixed-replace`` of JPEG frames: while an
inspection runs, the sequencer's own frames (never a second grab that could delay
it); while idle, a grab at a low rate. Frames come from the station thread
(``LiveCamera`` in :mod:`api.runtime`): this loop never touches the camera itself.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import time

import cv2
from fastapi import APIRouter, HTTPException, Request, status
from fastapi.responses import StreamingResponse

from api.deps import ReaderDep, RuntimeDep

router = APIRouter(prefix="/api/v1", tags=["live"])

BOUNDARY = "frame"
#: JPEG quality for the live view: a preview, not evidence (crops are stored as PNG)
JPEG_QUALITY = 80
#: how long one camera grab may take before the stream gives up on it
GRAB_TIMEOUT_S = 5.0


@router.get("/events", response_class=StreamingResponse,
            responses={200: {"content": {"text/event-stream": {}}, "description": "Server-Sent Events"}})
async def events(request: Request, rt: RuntimeDep, who: ReaderDep) -> StreamingResponse:
    queue = rt.hub.subscribe()
    keepalive = rt.settings.sse_keepalive_s

    async def stream():
        try:
            first = json.dumps({"time": time.time(), **rt.station_status()}, default=str)
            yield f"event: state\ndata: {first}\n\n".encode()
            while not rt.hub.closed:
                try:
                    ev = await asyncio.wait_for(queue.get(), timeout=keepalive)
                except asyncio.TimeoutError:
                    if await request.is_disconnected():
                        return
                    yield b": keep-alive\n\n"
                    continue
                if ev is None:
                    return
                yield ev.sse()
        finally:
            rt.hub.unsubscribe(queue)

    return StreamingResponse(stream(), media_type="text/event-stream",
                             headers={"Cache-Control": "no-cache", "X-Accel-Buffering": "no"})


def _jpeg(image) -> bytes:
    ok, buf = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    if not ok:
        raise ValueError("JPEG encoding failed")
    return buf.tobytes()


@router.get("/camera.mjpg", response_class=StreamingResponse,
            responses={200: {"content": {f"multipart/x-mixed-replace; boundary={BOUNDARY}": {}},
                             "description": "the camera's frames as JPEG parts (MJPEG)"},
                       404: {"description": "the station has no camera"}})
async def camera(request: Request, rt: RuntimeDep, who: ReaderDep) -> StreamingResponse:
    cam = rt.camera
    if cam is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, "the station has no camera")
    period = 1.0 / max(rt.settings.idle_camera_hz, 0.1)

    async def stream():
        sent = None  # the sequence number of the last frame sent
        while not rt.hub.closed:
            frame = cam.last
            stale = frame is None or time.monotonic() - cam.last_at >= period
            if stale and not rt.busy:
                with contextlib.suppress(Exception):  # a failed grab: try again next period
                    frame = await asyncio.wait_for(cam.grab(), timeout=GRAB_TIMEOUT_S)
            if frame is not None and frame.sequence != sent:
                data = await asyncio.to_thread(_jpeg, frame.image)
                sent = frame.sequence
                yield (f"--{BOUNDARY}\r\nContent-Type: image/jpeg\r\nContent-Length: {len(data)}\r\n\r\n"
                       .encode() + data + b"\r\n")
            if await request.is_disconnected():
                return
            await asyncio.sleep(period if not rt.busy else min(period, 0.2))

    return StreamingResponse(stream(), media_type=f"multipart/x-mixed-replace; boundary={BOUNDARY}",
                             headers={"Cache-Control": "no-cache"})
