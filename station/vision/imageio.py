"""Reading frames from files with errors a user can act on (no tracebacks, no None)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from drivers.interfaces.pixels import to_grey


class ImageReadError(ValueError):
    """A file that is missing, unreadable, or not an image OpenCV can decode."""


def to_8bit(image: np.ndarray) -> np.ndarray:
    """An 8-bit grey frame from one of 8 or 16 bits.

    A 16-bit container holds 10-, 12- or 14-bit data either at the top (MSB-aligned) or
    at the bottom (LSB-aligned) of its range, and the file does not say which.  So the
    frame is shifted right by the bits above 8 that its own maximum uses: 12-bit data at
    the bottom (max <= 4095) by 4, at the top by 8.  The measurement is scale-free (relative
    darkness and contrast, geometry), so a power-of-two scale loses nothing but the low
    bits; a fixed shift by 8 turned LSB-aligned 12-bit frames into 0-15 DN.
    """
    if image.dtype == np.uint8:
        return image
    if image.dtype == np.uint16:
        shift = max(int(image.max()).bit_length() - 8, 0)
        return (image >> shift).astype(np.uint8)
    raise ValueError(f"unsupported pixel type {image.dtype} (8- or 16-bit unsigned integers)")


def read_grey(path: str | Path) -> np.ndarray:
    """An 8-bit grey frame from ``path``; 16-bit frames are scaled to 8 bits (``to_8bit``)."""
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
    try:
        return to_8bit(to_grey(image))
    except ValueError as exc:
        raise ImageReadError(f"{p}: {exc}") from None
