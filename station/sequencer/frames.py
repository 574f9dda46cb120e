"""Frames that carry no measurement: black (no signal) and frozen (the previous image again).

A camera can go on delivering frames that mean nothing: a lamp or a sensor that failed
gives black frames, a hung sensor or capture pipeline repeats its last image under new
sequence numbers. The vision stage would find no hole in the first and measure a stale
view in the second -- a false "not found" or a wrong position. :class:`FrameCheck`
recognises both before anything is measured, and the engine treats them as a camera
fault (retried as a transient, then the inspection is faulted).

* **black**: the 99th percentile of the (subsampled) grey values is at or below
  ``black_level``; a lit bore wall is far brighter almost everywhere;
* **frozen**: the image content is byte for byte the one of the previous frame. A real
  sensor never delivers two identical frames (its noise alone differs), so equality
  means the same buffer again, whatever the sequence number says.
"""

from __future__ import annotations

import hashlib

import numpy as np

from drivers.interfaces import BadFrame


class FrameCheck:
    def __init__(self, black_level: int = 12, step: int = 4):
        self.black_level = int(black_level)
        self.step = int(step)
        self._last_digest: bytes | None = None
        self._last_sequence: int | None = None

    def check(self, frame, device: str = "camera") -> None:
        """Raise :class:`BadFrame` for a black or a frozen frame."""
        image = np.asarray(frame.image)
        if image.size == 0:
            raise BadFrame("empty frame (no pixels)", device)
        sample = image[:: self.step, :: self.step]
        p99 = float(np.percentile(sample, 99))
        if p99 <= self.black_level:
            raise BadFrame(f"black frame {frame.sequence} (no signal: 99th percentile {p99:.0f} of 255)", device)
        digest = hashlib.blake2b(np.ascontiguousarray(image).tobytes(), digest_size=16).digest()
        previous, prev_seq = self._last_digest, self._last_sequence
        self._last_digest, self._last_sequence = digest, frame.sequence
        if digest == previous:
            raise BadFrame(f"frozen frame {frame.sequence} (the same image as frame {prev_seq})", device)
