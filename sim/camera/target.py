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


#: where the views put the board, as a share of the room it has to move in each
#: direction: the centre, the four corners and the four edge middles of the frame, in turn
_PLACES = [(0, 0), (-1, -1), (1, 1), (1, -1), (-1, 1), (0, -1), (0, 1), (-1, 0), (1, 0)]


def board_views(
    lens: BrownLens,
    n_views: int = 10,
    pattern_size: tuple[int, int] = (9, 7),
    square_mm: float = 0.5,
    distance_mm: float = 11.0,
    size_px: tuple[int, int] = (1280, 1024),
    seed: int = 0,
    spread: float = 1.0,
) -> list[BoardView]:
    """``n_views`` tilted poses that keep the whole board (with margin) in the frame.

    As a careful operator does, the views take the board round the frame: the centre,
    then the corners, then the middles of the edges (``spread`` = 1 pushes it as far out
    as the frame allows, 0 keeps every view near the centre).  Distortion grows with
    the distance from the centre, so views that never reach the corners leave k2 to
    extrapolation there: with the board kept within ~0.6 mm of the centre, three seeds'
    undistortion maps erred by 0.4-5 px at the frame's corners.
    """
    rng = np.random.default_rng(seed)
    cols, rows = pattern_size
    w, h = size_px
    margin = 11
    outline = np.array([[-1, -1, 0], [cols + 2, -1, 0], [cols + 2, rows + 2, 0], [-1, rows + 2, 0]], float) * square_mm
    centre = np.array([(cols + 1) / 2, (rows + 1) / 2, 0.0]) * square_mm
    fx, fy = lens.camera_matrix[0, 0], lens.camera_matrix[1, 1]
    views: list[BoardView] = []
    attempts = 0
    while len(views) < n_views:
        attempts += 1
        if attempts > 1000 * n_views:
            raise RuntimeError("no board pose fits the frame: board too large for the lens at this distance")
        # tilts up to 30 deg about x and y: enough perspective to separate f from distance
        rvec = np.deg2rad([rng.uniform(-30, 30), rng.uniform(-30, 30), rng.uniform(-20, 20)])
        rot, _ = cv2.Rodrigues(rvec)
        z = distance_mm * rng.uniform(0.9, 1.15)
        tvec = np.array([0.0, 0.0, z]) - rot @ centre
        # the board's extent at the frame's centre (pinhole), hence the room it has
        p = cv2.projectPoints(outline, rvec, tvec, lens.camera_matrix, np.zeros(5))[0].reshape(-1, 2)
        room_x = max((w - (p[:, 0].max() - p[:, 0].min())) / 2 - margin, 0.0)
        room_y = max((h - (p[:, 1].max() - p[:, 1].min())) / 2 - margin, 0.0)
        px, py = _PLACES[len(views) % len(_PLACES)]
        jitter = rng.normal(0.0, 8.0, 2)

        def placed(share: float) -> np.ndarray | None:
            shift_px = np.array([px * room_x, py * room_y]) * share + jitter
            t = tvec + np.array([shift_px[0] * z / fx, shift_px[1] * z / fy, 0.0])
            q = cv2.projectPoints(outline, rvec, t, lens.camera_matrix, lens.dist_coeffs)[0].reshape(-1, 2)
            inside = q[:, 0].min() >= margin - 1 and q[:, 1].min() >= margin - 1 and \
                q[:, 0].max() <= w - margin and q[:, 1].max() <= h - margin
            return t if inside else None

        # the room was judged without the lens; barrel distortion pulls the board's far
        # side inwards, so push it out further while it stays in the frame
        best = None
        for share in [0.0] if spread == 0 else np.arange(0.8, 2.0, 0.1) * spread:
            t = placed(float(share))
            if t is None:
                break
            best = t
        if best is None:
            continue
        tvec = best
        image = render_board(lens, rvec, tvec, pattern_size, square_mm, size_px, seed=int(rng.integers(2**31)))
        views.append(BoardView(image, rvec, tvec))
    return views


def calibrate_lens(lens: BrownLens, n_views: int = 12, seed: int = 0, size_px: tuple[int, int] = (1280, 1024),
                   pattern_size: tuple[int, int] = (9, 7), square_mm: float = 0.5):
    """The station's calibration of a twin's camera, as a plant makes it of a real one:
    chessboard views round the frame (:func:`board_views`) through the station's own
    ``station.vision.calibration.calibrate`` (OpenCV). The station never sees ``lens``
    itself, only what the calibration makes of these images."""
    from station.vision.calibration import calibrate

    views = board_views(lens, n_views=n_views, pattern_size=pattern_size, square_mm=square_mm, size_px=size_px,
                        seed=seed)
    return calibrate([v.image for v in views], pattern_size, square_mm)
