"""Reading frames from files with errors a user can act on (no tracebacks, no None)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np


class ImageReadError(ValueError):
    """A file that is missing, unreadable, or not an image OpenCV can decode."""


def read_grey(path: str | Path) -> np.ndarray:
    """An 8-bit grey frame from ``path``; 16-bit frames are scaled to 8 bits."""
    p = Path(path)
    if not p.is_file():
        raise ImageReadError(f"{p}: no such file")
    try:
        data = np.fromfile(p, dtype=np.uint8)
    except OSError as exc:
        raise ImageReadError(f"{p}: cannot read ({exc.strerror})") from None
    image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    if image is None:
        raise ImageReadError(f"{p}: not an image (OpenCV cannot decode it)")
    if image.ndim == 3:
        image = cv2.cvtColor(image[..., :3], cv2.COLOR_BGR2GRAY)
    if image.dtype == np.uint16:
        image = (image >> 8).astype(np.uint8)
    elif image.dtype != np.uint8:
        raise ImageReadError(f"{p}: unsupported pixel type {image.dtype}")
    return image
