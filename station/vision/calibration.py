"""Camera calibration: intrinsics and Brown distortion from chessboard images, and scale.

Why: an endoscope's lens has strong barrel distortion, which bends a hole's rim and
changes its apparent size across the frame.  We calibrate once from chessboard views
(OpenCV's findChessboardCorners / cornerSubPix / calibrateCamera), store the result as
JSON, and at measurement time undistort only the hole's edge points
(cv2.undistortPoints back into pixels of the same camera matrix), never whole images:
that is cheaper and does not resample the image the edges are measured on.

Scale at the bore wall: the wall lies at a known working distance Z from the
projection centre, so one ideal pixel spans Z / f mm there (pinhole model,
fronto-parallel wall at the optical axis); alternatively a feature of known size
(a reference hole on a setting master) gives mm per px directly.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

#: cornerSubPix: half-size of the search window (px) and stop criteria; 5 px is about a
#: tenth of a chessboard square at our scale, the usual OpenCV sample choice is (11, 11)
SUBPIX_HALF_WINDOW_PX = 5
SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)


@dataclass(frozen=True)
class CameraCalibration:
    camera_matrix: np.ndarray  # 3x3, px
    dist_coeffs: np.ndarray  # k1, k2, p1, p2 (OpenCV order)
    image_size: tuple[int, int]  # (width, height) px
    rms_px: float  # RMS reprojection error of the calibration
    mm_per_px: float | None = None  # scale at the bore wall, when known
    n_views: int = 0

    def undistort_px(self, pts_px: np.ndarray) -> np.ndarray:
        """Distorted image points (N, 2) -> ideal pixel coordinates of the same camera matrix."""
        src = np.ascontiguousarray(pts_px, dtype=np.float64).reshape(-1, 1, 2)
        out = cv2.undistortPoints(
            src,
            self.camera_matrix,
            self.dist_coeffs,
            P=self.camera_matrix,
            criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-9),
        )
        return out.reshape(-1, 2)

    def with_working_distance(self, distance_mm: float) -> "CameraCalibration":
        """Scale at the wall from the working distance: Z / sqrt(fx fy) mm per ideal px."""
        f_px = float(np.sqrt(self.camera_matrix[0, 0] * self.camera_matrix[1, 1]))
        return _replace(self, mm_per_px=distance_mm / f_px)

    def to_json(self) -> dict:
        return {
            "camera_matrix": self.camera_matrix.tolist(),
            "dist_coeffs": self.dist_coeffs.ravel().tolist(),
            "image_size": list(self.image_size),
            "rms_px": self.rms_px,
            "mm_per_px": self.mm_per_px,
            "n_views": self.n_views,
            "pixel_convention": "centre of pixel (0,0) at (0,0), x right, y down",
        }

    @classmethod
    def from_json(cls, d: dict) -> "CameraCalibration":
        k = np.asarray(d["camera_matrix"], dtype=np.float64)
        dist = np.asarray(d["dist_coeffs"], dtype=np.float64)
        if k.shape != (3, 3) or dist.ndim != 1 or dist.size < 4:
            raise ValueError("camera_matrix must be 3x3 and dist_coeffs hold at least k1, k2, p1, p2")
        return cls(k, dist, tuple(d["image_size"]), float(d.get("rms_px", float("nan"))), d.get("mm_per_px"),
                   int(d.get("n_views", 0)))

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_json(), indent=2) + "\n")

    @classmethod
    def load(cls, path: str | Path) -> "CameraCalibration":
        return cls.from_json(json.loads(Path(path).read_text()))


def _replace(c: CameraCalibration, **kw) -> CameraCalibration:
    from dataclasses import replace

    return replace(c, **kw)


def mm_per_px_from_feature(known_size_mm: float, measured_px: float) -> float:
    """Scale from a feature of known size, e.g. the reference hole of a setting master."""
    return known_size_mm / measured_px


def board_points_mm(pattern_size: tuple[int, int], square_mm: float) -> np.ndarray:
    """Inner-corner positions (N, 3) on the board plane, row by row, as OpenCV orders them."""
    cols, rows = pattern_size
    grid = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2).astype(np.float32)
    return np.hstack([grid * square_mm, np.zeros((cols * rows, 1), np.float32)])


def find_corners(image: np.ndarray, pattern_size: tuple[int, int]) -> np.ndarray | None:
    """Sub-pixel inner corners (N, 1, 2) of a chessboard view, or None if not found."""
    grey = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH + cv2.CALIB_CB_NORMALIZE_IMAGE
    found, corners = cv2.findChessboardCorners(grey, pattern_size, flags=flags)
    if not found:
        return None
    w = SUBPIX_HALF_WINDOW_PX
    return cv2.cornerSubPix(grey, corners, (w, w), (-1, -1), SUBPIX_CRITERIA)


def calibrate(
    images: list[np.ndarray],
    pattern_size: tuple[int, int],
    square_mm: float,
    working_distance_mm: float | None = None,
) -> CameraCalibration:
    """Intrinsics and (k1, k2, p1, p2) from chessboard views; k3 fixed at 0.

    k3 is fixed because a short endoscope lens is described by k1, k2 within our
    accuracy and a free k3 trades off against k1/k2 with few views.
    """
    if not images:
        raise ValueError("no calibration images")
    h, w = images[0].shape[:2]
    obj = board_points_mm(pattern_size, square_mm)
    obj_pts, img_pts = [], []
    for im in images:
        if im.shape[:2] != (h, w):
            raise ValueError("calibration images differ in size")
        c = find_corners(im, pattern_size)
        if c is not None:
            obj_pts.append(obj)
            img_pts.append(c.astype(np.float32))
    if len(img_pts) < 3:
        raise ValueError(f"chessboard {pattern_size[0]}x{pattern_size[1]} found in only {len(img_pts)} images; need 3")
    rms, k, dist, _, _ = cv2.calibrateCamera(obj_pts, img_pts, (w, h), None, None, flags=cv2.CALIB_FIX_K3)
    cal = CameraCalibration(k, np.asarray(dist, dtype=np.float64).ravel()[:4], (w, h), float(rms), None, len(img_pts))
    return cal.with_working_distance(working_distance_mm) if working_distance_mm else cal
