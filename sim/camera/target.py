"""Chessboard calibration target seen by the endoscope in several poses.

Why: the calibration must be tested against a camera whose intrinsics and distortion
are known exactly.  Each sensor pixel asks which ideal pixel it sees (inverse Brown
distortion), back-projects it onto the board plane through the pose's homography, and
takes the chessboard value there; square edges are anti-aliased by the pixel's
footprint on the board (the coverage of a box pixel across a straight edge), then the
frame gets the same blur, vignetting and noise as the bore-wall frames.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from sim.camera.lens import BrownLens, ideal_pixel_grid


@dataclass(frozen=True)
class BoardView:
    image: np.ndarray
    rvec: np.ndarray
    tvec_mm: np.ndarray


def _square_wave(v: np.ndarray, footprint: np.ndarray) -> np.ndarray:
    """+1 on even squares, -1 on odd ones of ``v``, ramped across edges by the pixel footprint."""
    f = v - np.floor(v)
    dist = np.minimum(f, 1.0 - f)  # to the nearest edge, in squares
    cover = np.clip(0.5 + dist / np.maximum(footprint, 1e-6), 0.0, 1.0)
    even = (np.floor(v) % 2) == 0
    return np.where(even, 1.0, -1.0) * (2.0 * cover - 1.0)


def render_board(
    lens: BrownLens,
    rvec: np.ndarray,
    tvec_mm: np.ndarray,
    pattern_size: tuple[int, int] = (9, 7),
    square_mm: float = 0.5,
    size_px: tuple[int, int] = (1280, 1024),
    blur_sigma_px: float = 1.0,
    noise_dn: float = 2.0,
    seed: int = 0,
) -> np.ndarray:
    """One view of a chessboard with ``pattern_size`` inner corners (uint8)."""
    rng = np.random.default_rng(seed)
    w, h = size_px
    xu, yu = ideal_pixel_grid(lens, w, h)
    rot, _ = cv2.Rodrigues(np.asarray(rvec, float))
    hom = lens.camera_matrix @ np.column_stack([rot[:, 0], rot[:, 1], np.asarray(tvec_mm, float)])
    inv = np.linalg.inv(hom)
    den = inv[2, 0] * xu + inv[2, 1] * yu + inv[2, 2]
    bx = (inv[0, 0] * xu + inv[0, 1] * yu + inv[0, 2]) / den / square_mm  # in squares
    by = (inv[1, 0] * xu + inv[1, 1] * yu + inv[1, 2]) / den / square_mm
    # footprint of one pixel on the board, in squares, along each board axis
    fx = np.abs(np.gradient(bx, axis=1)) + np.abs(np.gradient(bx, axis=0))
    fy = np.abs(np.gradient(by, axis=1)) + np.abs(np.gradient(by, axis=0))
    # squares span [0, cols+1] x [0, rows+1]; inner corners at integers 1..cols, 1..rows
    chess = 0.5 + 0.5 * _square_wave(bx, fx) * _square_wave(by, fy)
    cols, rows = pattern_size
    on_board = (bx >= 0) & (bx <= cols + 1) & (by >= 0) & (by <= rows + 1)
    quiet = (bx >= -1) & (bx <= cols + 2) & (by >= -1) & (by <= rows + 2)  # white margin
    white_dn, black_dn, back_dn = 200.0, 40.0, 110.0
    radiance = np.where(on_board, black_dn + (white_dn - black_dn) * (1.0 - chess), np.where(quiet, white_dn, back_dn))
    radiance = cv2.GaussianBlur(radiance.astype(np.float32), (0, 0), blur_sigma_px)
    radiance += noise_dn * rng.standard_normal((h, w), dtype=np.float32)
    return np.clip(np.rint(radiance), 0, 255).astype(np.uint8)


def board_views(
    lens: BrownLens,
    n_views: int = 10,
    pattern_size: tuple[int, int] = (9, 7),
    square_mm: float = 0.5,
    distance_mm: float = 11.0,
    size_px: tuple[int, int] = (1280, 1024),
    seed: int = 0,
) -> list[BoardView]:
    """``n_views`` tilted poses that keep the whole board (with margin) in the frame."""
    rng = np.random.default_rng(seed)
    cols, rows = pattern_size
    w, h = size_px
    outline = np.array([[-1, -1, 0], [cols + 2, -1, 0], [cols + 2, rows + 2, 0], [-1, rows + 2, 0]], float) * square_mm
    views: list[BoardView] = []
    while len(views) < n_views:
        # tilts up to 30 deg about x and y: enough perspective to separate f from distance
        rvec = np.deg2rad([rng.uniform(-30, 30), rng.uniform(-30, 30), rng.uniform(-20, 20)])
        centre = np.array([(cols + 1) / 2, (rows + 1) / 2, 0.0]) * square_mm
        rot, _ = cv2.Rodrigues(rvec)
        shift = rng.uniform(-0.6, 0.6, 2)
        tvec = np.array([shift[0], shift[1], distance_mm * rng.uniform(0.9, 1.15)]) - rot @ centre
        img_pts, _ = cv2.projectPoints(outline, rvec, tvec, lens.camera_matrix, lens.dist_coeffs)
        p = img_pts.reshape(-1, 2)
        if p[:, 0].min() < 10 or p[:, 1].min() < 10 or p[:, 0].max() > w - 11 or p[:, 1].max() > h - 11:
            continue
        image = render_board(lens, rvec, tvec, pattern_size, square_mm, size_px, seed=int(rng.integers(2**31)))
        views.append(BoardView(image, rvec, tvec))
    return views
