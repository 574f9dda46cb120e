"""Image crops on disk: PNG files under ``<data>/images/<inspection id>/``.

A crop is evidence for a result, so its file is written completely or not at all
(temporary file, fsync, rename) and its SHA-256 is recorded with it: whoever audits
a result later can tell the crop they look at is the one the station saw.
"""

from __future__ import annotations

import hashlib
import os
import re
import uuid
from pathlib import Path, PurePosixPath

import cv2
import numpy as np

IMAGES_DIR = "images"
#: a crop's name: one path component, no leading dot (no hidden files, no "..")
NAME_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,99}")


def crop_relpath(inspection_id: str, name: str) -> PurePosixPath:
    """``images/<inspection id>/<name>.png``; ValueError for a name or id that could
    leave that folder (separators, ``..``, absolute paths, hidden names)."""
    try:
        canonical = str(uuid.UUID(inspection_id))
    except (ValueError, AttributeError, TypeError):
        raise ValueError(f"not an inspection id: {inspection_id!r}") from None
    if canonical != inspection_id:
        raise ValueError(f"inspection id {inspection_id!r} is not in canonical form ({canonical})")
    stem = name[:-4] if name.lower().endswith(".png") else name
    if not NAME_PATTERN.fullmatch(stem) or ".." in stem:
        raise ValueError(f"image name {name!r} refused: use letters, digits, '.', '_', '-' "
                         "(no path separators, no '..', not starting with a dot)")
    return PurePosixPath(IMAGES_DIR, inspection_id, f"{stem}.png")


def encode_png(image: np.ndarray) -> bytes:
    """PNG bytes of a uint8 image (H x W grey, or H x W x 3/4 in OpenCV's BGR(A) order)."""
    if not isinstance(image, np.ndarray) or image.dtype != np.uint8:
        raise ValueError(f"an image crop must be a numpy uint8 array, not {getattr(image, 'dtype', type(image))}")
    if image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] not in (1, 3, 4)) or image.size == 0:
        raise ValueError(f"an image crop must be H x W or H x W x 1/3/4, not shape {image.shape}")
    ok, buf = cv2.imencode(".png", image)
    if not ok:
        raise ValueError(f"OpenCV could not encode a {image.shape} image as PNG")
    return buf.tobytes()


def sha256_hex(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def write_temp(final_path: Path, data: bytes) -> Path:
    """Write ``data`` beside ``final_path`` under a temporary name, flushed to disk.
    The caller renames it into place (:func:`publish`) once the record is ready."""
    final_path.parent.mkdir(parents=True, exist_ok=True)
    tmp = final_path.with_name(f".{final_path.name}.{uuid.uuid4().hex}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return tmp


def publish(tmp: Path, final_path: Path) -> None:
    """Rename into place (atomic on POSIX) and make the rename itself durable."""
    os.replace(tmp, final_path)
    dir_fd = os.open(final_path.parent, os.O_RDONLY)
    try:
        os.fsync(dir_fd)
    finally:
        os.close(dir_fd)
