"""The camera's flawed pixels: found from frames of a moving wall, mended before any
measurement.

Why: a sensor of a million pixels has some that do not answer the light as their
neighbours do (hot pixels with a dark signal of their own, dim ones, a CCD column short
of charge below a trap), and they are the same pixels in every frame. The vision stage
reads them as the scene: six such pixels on a hole's rim move its diameter by a median
of 2 of its own u, 10 u at worst (40 frames of the vision bench), and a column 5 mm long
is a "scratch" in every frame of a surface scan. A real station calibrates them once
and mends them in every frame, as it does its lens's distortion.

How they are found, without a lens cap or a flat light: from frames in which the wall
moves under the camera (a coverage scan, the table turning). The scene's features move
from frame to frame, the sensor's flaws stay, so a flaw is a pixel that stands out of
its neighbourhood the same way in most frames:

* **pixels**: each frame's residual against its 5 x 5 median, over the residual's local
  spread (a 33 px box of its absolute value); a pixel whose residual is beyond
  ``PIXEL_Z`` on one side in more than half the frames (its median beyond it) is hot or
  dim. On a wall whose features move, a sound pixel is that far out in a frame with a
  chance of a percent or less, so the majority of a dozen frames never is.
* **columns**: each pixel against the middle two of the four nearest pixels of its row
  (two each side, so that a flawed column does not pass as its neighbours' flaw),
  averaged over the frames, its running median along the column over ``COLUMN_ROWS``
  rows (a flawed pixel alone does not move it); a stretch of
  a column whose mean stands out by ``COLUMN_Z`` times that mean's spread over the
  frame (and by ``COLUMN_MIN_DN``) is a flawed column, its ends where it falls to half
  its level.

Mending (``PixelMap.repair``): a flawed column stretch takes the mean of the columns
beside it, a flawed pixel the mean of its sound neighbours (3 x 3, else 5 x 5). Both
measure the scene through the pixels' neighbours: a defect under a flawed pixel is read
from the pixels around it, which is what they see of it.
"""

from __future__ import annotations

import datetime as _dt
import json
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
from scipy.ndimage import median_filter

#: a pixel is flawed when its residual's median over the frames is beyond this many of
#: its neighbourhood's spreads
PIXEL_Z = 3.5
#: frames needed: fewer leave a sound pixel's majority to chance near the scene's edges
MIN_FRAMES = 12
#: a column's mean residual is averaged over this many rows before it is judged
COLUMN_ROWS = 32
#: and judged flawed beyond this many of the averaged means' robust spread ...
COLUMN_Z = 6.0
#: ... and by at least this much (DN of an 8-bit frame; quantisation's own scale)
COLUMN_MIN_DN = 1.0
#: the map file's format name (``PixelMap.save`` / ``load``)
FORMAT = "station pixel map 1"


@dataclass
class PixelMap:
    """The flawed pixels of one camera: ``pixels`` (row, col, "hot" | "dim") and column
    stretches ``columns`` (col, first row, last row, the mean offset in DN), for frames
    of ``width`` x ``height``, found from ``frames`` frames."""

    width: int
    height: int
    pixels: list[tuple[int, int, str]] = field(default_factory=list)
    columns: list[tuple[int, int, int, float]] = field(default_factory=list)
    frames: int = 0
    created: str = ""
    source: str = ""

    @property
    def shape(self) -> tuple[int, int]:
        return (self.height, self.width)

    def repair(self, image: np.ndarray) -> np.ndarray:
        """``image`` with its flawed pixels mended (a copy, the same type; grey frames of
        the map's size only: a frame of another size is from another camera or mode)."""
        if image.shape[:2] != self.shape:
            raise ValueError(f"the pixel map is for {self.width} x {self.height} frames, this frame is "
                             f"{image.shape[1]} x {image.shape[0]}: another camera or another mode")
        if image.ndim != 2:
            raise ValueError(f"the pixel map mends grey frames, not of shape {image.shape}")
        if not self.pixels and not self.columns:
            return image
        out = image.astype(np.float32)
        h, w = self.shape
        for c, r0, r1, _ in self.columns:
            side = [k for k in (c - 1, c + 1) if 0 <= k < w]
            out[r0:r1 + 1, c] = out[r0:r1 + 1, side].mean(axis=1)
        if self.pixels:
            rc = np.array([(r, c) for r, c, _ in self.pixels], dtype=np.intp)
            bad = np.zeros(self.shape, bool)
            bad[rc[:, 0], rc[:, 1]] = True
            for half in (1, 2):
                d = np.arange(-half, half + 1)
                dr, dc = np.meshgrid(d, d, indexing="ij")
                rr = np.clip(rc[:, :1] + dr.ravel(), 0, h - 1)
                cc = np.clip(rc[:, 1:] + dc.ravel(), 0, w - 1)
                good = ~bad[rr, cc]
                n = good.sum(axis=1)
                ok = n > 0
                vals = np.where(good, out[rr, cc], 0.0).sum(axis=1)
                todo = ok & bad[rc[:, 0], rc[:, 1]]
                out[rc[todo, 0], rc[todo, 1]] = vals[todo] / n[todo]
                bad[rc[todo, 0], rc[todo, 1]] = False
                if not bad.any():
                    break
        if np.issubdtype(image.dtype, np.integer):
            info = np.iinfo(image.dtype)
            return np.clip(np.rint(out), info.min, info.max).astype(image.dtype)
        return out.astype(image.dtype)

    # ------------------------------------------------------------------ files
    def to_json(self) -> dict:
        return {"format": FORMAT, "width": self.width, "height": self.height, "frames": self.frames,
                "created": self.created, "source": self.source,
                "pixels": [[int(r), int(c), k] for r, c, k in self.pixels],
                "columns": [[int(c), int(r0), int(r1), round(float(o), 3)] for c, r0, r1, o in self.columns]}

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_json(), indent=1) + "\n")

    @classmethod
    def from_json(cls, d: dict, where: str = "pixel map") -> PixelMap:
        if not isinstance(d, dict) or d.get("format") != FORMAT:
            raise ValueError(f"{where}: not a pixel map (its 'format' must be {FORMAT!r})")

        def size(name: str) -> int:
            v = d.get(name)
            if not isinstance(v, int) or isinstance(v, bool) or v <= 0:
                raise ValueError(f"{where}: '{name}' must be a whole number of pixels > 0, not {v!r}")
            return v

        w, h = size("width"), size("height")
        pixels = []
        for i, p in enumerate(d.get("pixels", [])):
            if (not isinstance(p, list) or len(p) != 3 or not all(isinstance(v, int) for v in p[:2])
                    or p[2] not in ("hot", "dim")):
                raise ValueError(f"{where}: pixels[{i}] must be [row, col, 'hot' | 'dim'], not {p!r}")
            if not (0 <= p[0] < h and 0 <= p[1] < w):
                raise ValueError(f"{where}: pixels[{i}] {p[:2]} lies outside the {w} x {h} frame")
            pixels.append((p[0], p[1], p[2]))
        columns = []
        for i, c in enumerate(d.get("columns", [])):
            if (not isinstance(c, list) or len(c) != 4 or not all(isinstance(v, int) for v in c[:3])
                    or not isinstance(c[3], (int, float))):
                raise ValueError(f"{where}: columns[{i}] must be [col, first row, last row, offset DN], not {c!r}")
            if not (0 <= c[0] < w and 0 <= c[1] <= c[2] < h):
                raise ValueError(f"{where}: columns[{i}] {c[:3]} lies outside the {w} x {h} frame")
            columns.append((c[0], c[1], c[2], float(c[3])))
        return cls(w, h, pixels, columns, frames=int(d.get("frames", 0)), created=str(d.get("created", "")),
                   source=str(d.get("source", "")))

    @classmethod
    def load(cls, path: str | Path) -> PixelMap:
        path = Path(path)
        try:
            d = json.loads(path.read_text())
        except json.JSONDecodeError as exc:
            raise ValueError(f"{path}: line {exc.lineno}: not JSON ({exc.msg})") from None
        return cls.from_json(d, str(path))


class PixelMapBuilder:
    """Frames of a moving wall in, one at a time (``add``); ``result()`` the map."""

    def __init__(self, pixel_z: float = PIXEL_Z):
        self.pixel_z = float(pixel_z)
        self.frames = 0
        self._shape: tuple[int, int] | None = None
        self._hi = self._lo = None
        self._col = None

    def add(self, image: np.ndarray) -> None:
        if image.ndim != 2:
            raise ValueError(f"a pixel map is read from grey frames, not of shape {image.shape}")
        if self._shape is None:
            self._shape = image.shape
            self._hi = np.zeros(image.shape, np.uint16)
            self._lo = np.zeros(image.shape, np.uint16)
            self._col = np.zeros(image.shape, np.float64)
            self._sum = np.zeros(image.shape, np.float64)
        elif image.shape != self._shape:
            raise ValueError(f"frame {self.frames + 1} is {image.shape[1]} x {image.shape[0]} px, the first was "
                             f"{self._shape[1]} x {self._shape[0]}: one camera, one mode")
        f = image.astype(np.float32)
        r = f - cv2.medianBlur(f, 5)
        # the residual's local spread: its mean absolute value over 33 px (x 1.25: a normal
        # law's standard deviation), floored at an 8-bit frame's quantisation
        scale = np.maximum(1.25 * cv2.blur(np.abs(r), (33, 33), borderType=cv2.BORDER_REFLECT), 0.5)
        z = r / scale
        self._hi += z > self.pixel_z
        self._lo += z < -self.pixel_z
        # the column's residual against the middle two of its row's four nearest pixels
        p = np.pad(f, ((0, 0), (2, 2)), mode="reflect")
        nb = np.stack([p[:, 0:-4], p[:, 1:-3], p[:, 3:-1], p[:, 4:]])
        mid = (nb.sum(axis=0) - nb.max(axis=0) - nb.min(axis=0)) / 2.0
        self._col += f - mid
        self._sum += f
        self.frames += 1

    def result(self, source: str = "") -> PixelMap:
        if self.frames < MIN_FRAMES:
            raise ValueError(f"a pixel map needs at least {MIN_FRAMES} frames of a moving wall, got {self.frames}")
        h, w = self._shape
        half = self.frames / 2.0
        hot = self._hi > half
        dim = self._lo > half
        columns = _columns(self._col / self.frames, self._sum / self.frames)
        in_col = np.zeros((h, w), bool)
        for c, r0, r1, _ in columns:
            in_col[r0:r1 + 1, c] = True
        pixels = [(int(r), int(c), "hot") for r, c in zip(*np.nonzero(hot & ~in_col))]
        pixels += [(int(r), int(c), "dim") for r, c in zip(*np.nonzero(dim & ~in_col))]
        pixels.sort()
        created = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
        return PixelMap(w, h, pixels, columns, frames=self.frames, created=created, source=source)


def _columns(mean: np.ndarray, image: np.ndarray) -> list[tuple[int, int, int, float]]:
    """Flawed column stretches from the frames' mean column residual ``mean`` and their
    mean ``image`` (rows x cols)."""
    h, w = mean.shape
    rows = min(COLUMN_ROWS, h)
    # a running median along the column: a hot or dim pixel alone does not move it
    smooth = median_filter(mean.astype(np.float32), size=(rows, 1), mode="reflect")
    med = float(np.median(smooth))
    spread = 1.4826 * float(np.median(np.abs(smooth - med)))
    bar = max(COLUMN_Z * spread, COLUMN_MIN_DN)
    flagged = np.abs(smooth - med) > bar
    out = []
    for c in np.nonzero(flagged.sum(axis=0) >= rows // 2)[0]:
        col = smooth[:, c] - med
        for r0, r1 in _runs(flagged[:, c]):
            if r1 - r0 + 1 < rows // 2:
                continue
            level = float(np.median(col[r0:r1 + 1]))
            keep = (np.sign(col) == np.sign(level)) & (np.abs(col) > abs(level) / 2.0)
            a, b = r0, r1
            while a > 0 and keep[a - 1]:
                a -= 1
            while b < h - 1 and keep[b + 1]:
                b += 1
            # the smoothing's half-level crossing is within a row or two of the stretch's
            # end: mend two rows more each side (sound pixels mended cost nothing)
            a, b = max(a - 2, 0), min(b + 2, h - 1)
            level = float(np.median(mean[a:b + 1, c]))
            if out and out[-1][0] == c and a <= out[-1][2] + 1:
                out[-1] = (c, out[-1][1], b, (out[-1][3] + level) / 2.0)
            else:
                out.append((int(c), int(a), int(b), level))
    # the middle two of four neighbours still lean away from a flawed column beside them
    # (by about a tenth of its offset): each stretch is judged again on the frames' mean
    # image against the nearest columns that are not candidates themselves
    cand = {c for c, *_ in out}
    kept = []
    for c, a, b, _ in out:
        left = next((k for k in range(c - 1, -1, -1) if k not in cand), None)
        right = next((k for k in range(c + 1, w) if k not in cand), None)
        refs = [k for k in (left, right) if k is not None]
        ref = image[a:b + 1, refs].mean(axis=1)
        level = float(np.median(image[a:b + 1, c] - ref))
        if abs(level) > bar:
            kept.append((int(c), int(a), int(b), level))
    return kept


def _runs(flags: np.ndarray) -> list[tuple[int, int]]:
    """(first, last) of each run of True in a 1-D array."""
    d = np.diff(np.concatenate([[0], flags.astype(np.int8), [0]]))
    starts, ends = np.nonzero(d == 1)[0], np.nonzero(d == -1)[0] - 1
    return list(zip(starts.tolist(), ends.tolist()))


def find_pixel_map(frames, source: str = "") -> PixelMap:
    """The map from an iterable of grey frames of a moving wall (``PixelMapBuilder``)."""
    b = PixelMapBuilder()
    for f in frames:
        b.add(f)
    return b.result(source)
