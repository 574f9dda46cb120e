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

import functools
import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from station.vision.imageio import to_8bit, to_grey

#: cornerSubPix: half-size of the search window (px) and stop criteria; 5 px is about a
#: tenth of a chessboard square at our scale, the usual OpenCV sample choice is (11, 11)
SUBPIX_HALF_WINDOW_PX = 5
SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)


#: grid step (px) of the stored map uncertainty; the map's uncertainty is smooth (it
#: comes from a few lens parameters), so a coarse grid interpolates it closely
MAP_U_STEP_PX = 64
#: the frame is split into COVERAGE_CELLS x COVERAGE_CELLS cells for the coverage figure
COVERAGE_CELLS = 8


@dataclass(frozen=True)
class CameraCalibration:
    camera_matrix: np.ndarray  # 3x3, px
    dist_coeffs: np.ndarray  # k1, k2, p1, p2 (OpenCV order)
    image_size: tuple[int, int]  # (width, height) px
    rms_px: float  # RMS reprojection error of the calibration
    mm_per_px: float | None = None  # scale at the bore wall, when known
    n_views: int = 0
    #: share of the frame's 8 x 8 cells in which the board's corners were seen
    coverage: float | None = None
    #: standard uncertainty (px) of the undistorted x and y on a grid of nodes
    #: ``map_u_nodes`` = (x nodes, y nodes): the jackknife over the views (``calibrate``)
    map_u_x_px: np.ndarray | None = None
    map_u_y_px: np.ndarray | None = None
    map_u_nodes: tuple[np.ndarray, np.ndarray] | None = None

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

    def distort_px(self, pts_px: np.ndarray) -> np.ndarray:
        """Ideal pixel coordinates (N, 2) of the camera matrix -> where the lens puts them
        in the image (``undistort_px``'s inverse)."""
        p = np.asarray(pts_px, dtype=np.float64).reshape(-1, 2)
        k = np.asarray(self.camera_matrix, np.float64)
        rays = np.column_stack([(p[:, 0] - k[0, 2]) / k[0, 0], (p[:, 1] - k[1, 2]) / k[1, 1], np.ones(len(p))])
        out, _ = cv2.projectPoints(rays.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), k,
                                   np.asarray(self.dist_coeffs, np.float64))
        return out.reshape(-1, 2)

    def undistort_u_px(self, pts_px: np.ndarray) -> np.ndarray | None:
        """Standard uncertainty (N, 2) of ``undistort_px`` at image points: how far the
        calibration's own map may be off there (bilinear in the stored grid), or None
        when the calibration holds none."""
        interpolators = self._map_u_interpolators
        if interpolators is None:
            return None
        xs, ys = self.map_u_nodes
        p = np.asarray(pts_px, dtype=np.float64).reshape(-1, 2)
        q = np.column_stack([np.clip(p[:, 1], ys[0], ys[-1]), np.clip(p[:, 0], xs[0], xs[-1])])
        return np.column_stack([f(q) for f in interpolators])

    @functools.cached_property
    def _map_u_interpolators(self):
        """Bilinear interpolators of the stored map uncertainty (x, y), built once per
        calibration (``undistort_u_px`` runs once per hole)."""
        if self.map_u_x_px is None or self.map_u_nodes is None:
            return None
        from scipy.interpolate import RegularGridInterpolator

        xs, ys = self.map_u_nodes
        return tuple(RegularGridInterpolator((ys, xs), g) for g in (self.map_u_x_px, self.map_u_y_px))

    def map_u_summary(self) -> dict | None:
        """The largest map uncertainty (px, the larger of x and y) over the central 80 %
        of the frame and over all of it; None without a stored map uncertainty."""
        if self.map_u_x_px is None or self.map_u_nodes is None:
            return None
        xs, ys = self.map_u_nodes
        w, h = self.image_size
        u = np.maximum(self.map_u_x_px, self.map_u_y_px)
        inner = u[np.ix_((ys >= 0.1 * h) & (ys <= 0.9 * h), (xs >= 0.1 * w) & (xs <= 0.9 * w))]
        return {"central_80_max_px": float(inner.max()) if inner.size else float("nan"), "frame_max_px": float(u.max())}

    def with_working_distance(self, distance_mm: float) -> "CameraCalibration":
        """Scale at the wall from the working distance: Z / sqrt(fx fy) mm per ideal px."""
        f_px = float(np.sqrt(self.camera_matrix[0, 0] * self.camera_matrix[1, 1]))
        return _replace(self, mm_per_px=distance_mm / f_px)

    def to_json(self) -> dict:
        d = {
            "camera_matrix": self.camera_matrix.tolist(),
            "dist_coeffs": self.dist_coeffs.ravel().tolist(),
            "image_size": list(self.image_size),
            "rms_px": self.rms_px,
            "mm_per_px": self.mm_per_px,
            "n_views": self.n_views,
            "pixel_convention": "centre of pixel (0,0) at (0,0), x right, y down",
        }
        if self.coverage is not None:
            d["coverage"] = self.coverage
        if self.map_u_x_px is not None and self.map_u_nodes is not None:
            d["map_uncertainty"] = {
                "method": "jackknife over the views, standard uncertainty (k = 1) of the undistorted point, px",
                "x_nodes_px": self.map_u_nodes[0].tolist(),
                "y_nodes_px": self.map_u_nodes[1].tolist(),
                "u_x_px": np.round(self.map_u_x_px, 5).tolist(),
                "u_y_px": np.round(self.map_u_y_px, 5).tolist(),
            }
        return d

    @classmethod
    def from_json(cls, d: dict) -> "CameraCalibration":
        k = np.asarray(d["camera_matrix"], dtype=np.float64)
        dist = np.asarray(d["dist_coeffs"], dtype=np.float64)
        if k.shape != (3, 3) or dist.ndim != 1 or dist.size < 4:
            raise ValueError("camera_matrix must be 3x3 and dist_coeffs hold at least k1, k2, p1, p2")
        ux = uy = nodes = None
        mu = d.get("map_uncertainty")  # absent from files written before it existed
        if mu is not None:
            nodes = (np.asarray(mu["x_nodes_px"], dtype=np.float64), np.asarray(mu["y_nodes_px"], dtype=np.float64))
            ux, uy = np.asarray(mu["u_x_px"], dtype=np.float64), np.asarray(mu["u_y_px"], dtype=np.float64)
            if ux.shape != (nodes[1].size, nodes[0].size) or uy.shape != ux.shape:
                raise ValueError("map_uncertainty: u_x_px and u_y_px must be len(y_nodes_px) x len(x_nodes_px)")
        cov = d.get("coverage")
        return cls(k, dist, tuple(d["image_size"]), float(d.get("rms_px", float("nan"))), d.get("mm_per_px"),
                   int(d.get("n_views", 0)), None if cov is None else float(cov), ux, uy, nodes)

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_json(), indent=2) + "\n")

    @classmethod
    def load(cls, path: str | Path) -> "CameraCalibration":
        return cls.from_json(json.loads(Path(path).read_text(encoding="utf-8-sig")))


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
    grey = to_8bit(to_grey(image))
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH + cv2.CALIB_CB_NORMALIZE_IMAGE
    found, corners = cv2.findChessboardCorners(grey, pattern_size, flags=flags)
    if not found:
        return None
    w = SUBPIX_HALF_WINDOW_PX
    return cv2.cornerSubPix(grey, corners, (w, w), (-1, -1), SUBPIX_CRITERIA)


def coverage_of(corners_px: np.ndarray, image_size: tuple[int, int], cells: int = COVERAGE_CELLS) -> float:
    """Share of the frame's ``cells`` x ``cells`` cells holding at least one corner."""
    w, h = image_size
    p = np.asarray(corners_px, dtype=np.float64).reshape(-1, 2)
    ix = np.clip((p[:, 0] + 0.5) * cells // w, 0, cells - 1).astype(int)
    iy = np.clip((p[:, 1] + 0.5) * cells // h, 0, cells - 1).astype(int)
    seen = np.zeros((cells, cells), dtype=bool)
    seen[iy, ix] = True
    return float(seen.mean())


def _solve(obj_pts, img_pts, image_size):
    rms, k, dist, _, _ = cv2.calibrateCamera(obj_pts, img_pts, image_size, None, None, flags=cv2.CALIB_FIX_K3)
    return float(rms), k, np.asarray(dist, dtype=np.float64).ravel()[:4]


def calibrate(
    images: list[np.ndarray],
    pattern_size: tuple[int, int],
    square_mm: float,
    working_distance_mm: float | None = None,
) -> CameraCalibration:
    """Intrinsics and (k1, k2, p1, p2) from chessboard views; k3 fixed at 0.

    k3 is fixed because a short endoscope lens is described by k1, k2 within our
    accuracy and a free k3 trades off against k1/k2 with few views.

    With 4 views or more the result also says how far its undistortion map can be
    trusted, point by point: the jackknife over the views (calibrate again without each
    view in turn; the spread of the maps, times (n - 1) / n, is their variance).  Where
    the board was never seen, the map is extrapolated from the lens model and its
    uncertainty grows: that is what the grid shows, with ``coverage`` as a summary.
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
    rms, k, dist = _solve(obj_pts, img_pts, (w, h))
    cov = coverage_of(np.concatenate([c.reshape(-1, 2) for c in img_pts]), (w, h))
    cal = CameraCalibration(k, dist, (w, h), rms, None, len(img_pts), cov)
    n = len(img_pts)
    if n >= 4:
        xs = np.linspace(0.0, w - 1.0, int(np.ceil((w - 1) / MAP_U_STEP_PX)) + 1)
        ys = np.linspace(0.0, h - 1.0, int(np.ceil((h - 1) / MAP_U_STEP_PX)) + 1)
        gx, gy = np.meshgrid(xs, ys)
        nodes = np.column_stack([gx.ravel(), gy.ravel()])
        maps = []
        for i in range(n):
            keep = [j for j in range(n) if j != i]
            _, ki, di = _solve([obj_pts[j] for j in keep], [img_pts[j] for j in keep], (w, h))
            maps.append(CameraCalibration(ki, di, (w, h), float("nan")).undistort_px(nodes))
        maps = np.asarray(maps)
        var = (n - 1) / n * ((maps - maps.mean(axis=0)) ** 2).sum(axis=0)
        u = np.sqrt(var).reshape(len(ys), len(xs), 2)
        cal = _replace(cal, map_u_x_px=u[..., 0], map_u_y_px=u[..., 1], map_u_nodes=(xs, ys))
    return cal.with_working_distance(working_distance_mm) if working_distance_mm else cal


#: above this the map's uncertainty somewhere in the frame (px, k = 1) is worth a warning:
#: it exceeds the hole measurement's own by more than an order of magnitude
MAP_U_WARN_PX = 0.5
#: below this share of the frame seen, the calibration extrapolates over most of it
COVERAGE_WARN = 0.5


def calibration_warnings(cal: CameraCalibration) -> list[str]:
    """What an operator should know before trusting a calibration everywhere."""
    out = []
    summary = cal.map_u_summary()
    if cal.coverage is not None and cal.coverage < COVERAGE_WARN:
        out.append(f"the board was seen in only {cal.coverage:.0%} of the frame; take views with it near the "
                   "corners and edges of the frame, where the distortion is largest")
    if summary is not None and summary["frame_max_px"] > MAP_U_WARN_PX:
        out.append(f"the undistortion map is uncertain by up to {summary['frame_max_px']:.2f} px where the board "
                   "was not seen; holes measured there carry it (HoleMeasurement.map_u_px)")
    if cal.map_u_x_px is None:
        out.append("fewer than 4 views: the map's uncertainty cannot be estimated")
    return out
