"""Pixels as the station takes them: one grey channel, whichever way a frame arrives.

It is part of ``drivers.interfaces`` because both sides of the camera need it: the
camera driver converts what the device delivers, and the vision stage converts frames
read from files or handed over in memory; a saved frame and a live one must measure
alike.
"""

from __future__ import annotations

from functools import lru_cache

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


#: the camera's response exponents accepted: an encoding gamma of a standard camera is
#: 0.45 (sRGB, Rec. 709) to 1 (linear); below 0.2 or above 3 it is a configuration error
RESPONSE_GAMMA_RANGE = (0.2, 3.0)


def linearize(image: np.ndarray, gamma: float) -> np.ndarray:
    """A frame whose pixels are proportional to the light again, from a camera that
    encodes them with a power law, pixel = full * (light / full) ** ``gamma`` (sRGB-like
    webcams and endoscope cameras 0.45, unless their gamma is switched off; 1: linear,
    the frame returned as it is). The photometric hole fit and the defects' relative
    darkness are models of light: an edge blurred in light and then encoded is no
    longer symmetric, and holes read 0.17 / 0.31 / 0.46 px small at a gamma of 0.8 / 0.6 /
    0.45 (vision bench frames 950000-950029, 41-43 holes; 0.000 linear), their u
    covering none of that. Integer frames keep their type (a look-up table over the
    type's full range: a 16-bit frame is taken as 0-65535, so 10-14-bit data at the
    bottom of the container, as V4L2's Y10 / Y12 formats deliver them, must be shifted up
    first; OpenCV's capture hands over 8-bit frames, and the files' ``read_grey`` makes
    8-bit frames before this); float frames are taken as 0-1."""
    if not RESPONSE_GAMMA_RANGE[0] <= gamma <= RESPONSE_GAMMA_RANGE[1]:
        raise ValueError(f"the camera's response gamma must be within {RESPONSE_GAMMA_RANGE}, not {gamma}")
    if gamma == 1.0:
        return image
    if np.issubdtype(image.dtype, np.integer):
        if image.dtype.itemsize > 2:
            raise ValueError(f"unsupported pixel type {image.dtype} for linearizing (8 or 16 bits)")
        return _linear_lut(image.dtype.str, float(gamma))[image]
    return np.clip(image, 0.0, 1.0) ** (1.0 / gamma)


@lru_cache(maxsize=8)
def _linear_lut(dtype: str, gamma: float) -> np.ndarray:
    """``linearize``'s look-up table for an integer type, made once per type and gamma
    (the camera driver linearizes every frame)."""
    dt = np.dtype(dtype)
    full = float(np.iinfo(dt).max)
    return np.round(full * (np.arange(int(full) + 1) / full) ** (1.0 / gamma)).astype(dt)
