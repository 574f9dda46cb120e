"""The endoscope's CCD camera through OpenCV: V4L2 for devices, any backend for video files.

A device (an index like ``0`` or a path like ``/dev/video0``) is opened with
``cv2.CAP_V4L2`` so that resolution, exposure and gain go straight to the kernel driver;
a video file is opened with ``cv2.CAP_ANY`` (FFmpeg in opencv-python-headless) -- how the
tests and offline replays run.  Frames are returned grey (uint8) because the vision stage
measures edges, not colours, and a grey frame is a third of the bytes.

``VideoCapture.read`` blocks, so it runs in a worker thread with a timeout.
"""

from __future__ import annotations

import asyncio
import threading
import time
from pathlib import Path

import cv2
import numpy as np

from drivers.interfaces import Camera, CommunicationLost, DeviceTimeout, Frame
from drivers.interfaces.pixels import RESPONSE_GAMMA_RANGE, linearize, to_grey

#: V4L2 exposure: 1 = manual exposure (V4L2_EXPOSURE_MANUAL); OpenCV passes it through as is
_V4L2_MANUAL_EXPOSURE = 1


def _is_device(source: int | str) -> bool:
    """An index or anything under /dev/ (``/dev/video0``, a udev alias such as
    ``/dev/bore-camera``) is a V4L2 device; any other path is a video file."""
    return isinstance(source, int) or str(source).startswith("/dev/")


class OpenCVCamera(Camera):
    """A camera or a video file; ``loop`` rewinds a file at its end (a replay that never ends)."""

    def __init__(
        self,
        source: int | str,
        *,
        width: int | None = None,
        height: int | None = None,
        exposure: float | None = None,
        gain: float | None = None,
        fps: float | None = None,
        timeout_s: float = 1.0,
        loop: bool = False,
        name: str = "camera",
        response_gamma: float = 1.0,
    ):
        if not RESPONSE_GAMMA_RANGE[0] <= response_gamma <= RESPONSE_GAMMA_RANGE[1]:
            raise ValueError(f"response_gamma must be within {RESPONSE_GAMMA_RANGE}, not {response_gamma}")
        self.source = source
        #: the camera's encoding exponent (``pixels.linearize``): each frame is made linear
        #: in light before anything measures it; 1 for a camera whose gamma is off
        self.response_gamma = float(response_gamma)
        self.width, self.height = width, height
        self.exposure, self.gain, self.fps = exposure, gain, fps
        self.timeout_s = float(timeout_s)
        self.loop = loop
        self.name = name
        self._cap: cv2.VideoCapture | None = None
        self._lock = threading.Lock()
        self._sequence = 0

    @property
    def is_device(self) -> bool:
        return _is_device(self.source)

    def _open_sync(self) -> cv2.VideoCapture:
        if self._cap is not None:
            return self._cap
        if self.is_device:
            cap = cv2.VideoCapture(self.source, cv2.CAP_V4L2)
        else:
            if not Path(str(self.source)).exists():
                raise CommunicationLost(f"no such video file {self.source}", self.name)
            cap = cv2.VideoCapture(str(self.source), cv2.CAP_ANY)
        if not cap.isOpened():
            cap.release()
            raise CommunicationLost(f"cannot open {self.source}", self.name)
        self._apply_settings(cap)
        self._cap = cap
        return cap

    def _apply_settings(self, cap: cv2.VideoCapture) -> None:
        """Resolution, frame rate, exposure and gain; a file ignores them (OpenCV returns False)."""
        if self.width:
            cap.set(cv2.CAP_PROP_FRAME_WIDTH, self.width)
        if self.height:
            cap.set(cv2.CAP_PROP_FRAME_HEIGHT, self.height)
        if self.fps:
            cap.set(cv2.CAP_PROP_FPS, self.fps)
        if self.exposure is not None:
            cap.set(cv2.CAP_PROP_AUTO_EXPOSURE, _V4L2_MANUAL_EXPOSURE)
            cap.set(cv2.CAP_PROP_EXPOSURE, self.exposure)
        if self.gain is not None:
            cap.set(cv2.CAP_PROP_GAIN, self.gain)

    def _grab_sync(self) -> Frame:
        with self._lock:
            cap = self._open_sync()
            ok, image = cap.read()
            if not ok and self.loop and not self.is_device:
                cap.set(cv2.CAP_PROP_POS_FRAMES, 0)
                ok, image = cap.read()
            stamp = time.monotonic()
            if not ok or image is None:
                if self.is_device:
                    self._release_sync()  # reopen on the next grab: the device may come back
                    raise CommunicationLost("the camera delivered no frame", self.name)
                raise CommunicationLost("end of video file", self.name)
            if image.ndim == 3:
                # the grey the vision stage takes from a colour file, so a saved frame and
                # a live one measure alike
                image = to_grey(image)
            image = linearize(image, self.response_gamma)
            self._sequence += 1
            return Frame(np.ascontiguousarray(image), stamp, self._sequence)

    def _release_sync(self) -> None:
        if self._cap is not None:
            self._cap.release()
            self._cap = None

    async def connect(self) -> None:
        await asyncio.wait_for(asyncio.to_thread(self._locked_open), self.timeout_s * 5)

    def _locked_open(self) -> None:
        with self._lock:
            self._open_sync()

    async def grab(self) -> Frame:
        try:
            return await asyncio.wait_for(asyncio.to_thread(self._grab_sync), self.timeout_s)
        except asyncio.TimeoutError:
            raise DeviceTimeout(f"no frame within {self.timeout_s} s", self.name) from None

    async def close(self) -> None:
        def release():
            with self._lock:
                self._release_sync()

        await asyncio.to_thread(release)

    def resolution(self) -> tuple[int, int]:
        """(width, height) the capture reports (after open)."""
        cap = self._cap
        if cap is None:
            return (0, 0)
        return int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
