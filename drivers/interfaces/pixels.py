"""Pixels as the station takes them: one grey channel, whichever way a frame arrives.

It is part of ``drivers.interfaces`` because both sides of the camera need it: the
camera driver converts what the device delivers, and the vision stage converts frames
read from files or handed over in memory; a saved frame and a live one must measure
alike.
"""

from __future__ import annotations

import numpy as np


def to_grey(image: np.ndarray) -> np.ndarray:
    """One channel from a grey, grey + alpha, BGR or BGRA frame: for colour the mean of B, G
    and R, rounded, in the frame's own type. The same conversion for the camera driver's
    frames, files (``station.vision.imageio.read_grey``) and frames handed over in memory
    (``measure_holes``); under a white ring light the channels see the same geometry, and
    their mean carries less noise than luminance weights (1/3 of a channel's variance
    against 0.45)."""
    if image.ndim == 2:
        return image
    if image.ndim != 3 or image.shape[2] not in (1, 2, 3, 4):
        raise ValueError(f"a frame is grey, grey + alpha, BGR or BGRA, not of shape {image.shape}")
    if image.shape[2] <= 2:
        return image[..., 0]  # grey (+ alpha)
    colour = image[..., :3]
    if not np.issubdtype(image.dtype, np.integer):
        return colour.mean(axis=2).astype(image.dtype)
    # integer mean with rounding, without a float copy of the whole frame
    total = colour.sum(axis=2, dtype=np.uint32)
    n = colour.shape[2]
    return ((total + n // 2) // n).astype(image.dtype)
