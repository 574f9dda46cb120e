"""Scoring measured holes against ground truth: errors, misses, phantoms, partial flags.

Used by the vision benchmark and the tests alike, so both judge by the same rules.
Truth and detections are plain (x_px, y_px, diameter_px, partial) tuples; station does
not know where the truth came from (the renderer lives in ``sim``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Score:
    centre_err_px: list[float] = field(default_factory=list)  # whole holes only
    diameter_err_px: list[float] = field(default_factory=list)  # signed, measured - true
    misses: int = 0  # whole holes not found
    phantoms: int = 0  # detections matching no hole at all
    partial_found: int = 0  # cut holes found
    partial_flag_errors: int = 0  # matched holes whose partial flag is wrong
    #: errors over the method's own standard uncertainty, for whole holes that come with
    #: one: (measured - true) / u of the diameter, and of the centre's x and y (both listed)
    diameter_z: list[float] = field(default_factory=list)
    centre_z: list[float] = field(default_factory=list)

    def add(self, other: "Score") -> None:
        self.centre_err_px += other.centre_err_px
        self.diameter_err_px += other.diameter_err_px
        self.diameter_z += other.diameter_z
        self.centre_z += other.centre_z
        self.misses += other.misses
        self.phantoms += other.phantoms
        self.partial_found += other.partial_found
        self.partial_flag_errors += other.partial_flag_errors

    def summary(self) -> dict:
        c = np.asarray(self.centre_err_px)
        d = np.abs(np.asarray(self.diameter_err_px))
        out = {}
        if self.diameter_z or self.centre_z:
            # how often the stated uncertainty (k = 2) holds the error: about 95 % if it is right
            zd, zc = np.abs(self.diameter_z), np.abs(self.centre_z)
            out = {"diameter_within_2u": float(np.mean(zd <= 2)) if zd.size else None,
                   "centre_within_2u": float(np.mean(zc <= 2)) if zc.size else None,
                   "holes_with_u": int(zd.size)}
        return out | {
            "holes_measured": int(c.size),
            "median_centre_err_px": float(np.median(c)) if c.size else None,
            "worst_centre_err_px": float(c.max()) if c.size else None,
            "p90_centre_err_px": float(np.percentile(c, 90)) if c.size else None,
            "rms_centre_err_px": float(np.sqrt(np.mean(c**2))) if c.size else None,
            "median_diameter_err_px": float(np.median(d)) if d.size else None,
            "worst_diameter_err_px": float(d.max()) if d.size else None,
            "p90_diameter_err_px": float(np.percentile(d, 90)) if d.size else None,
            "rms_diameter_err_px": float(np.sqrt(np.mean(d**2))) if d.size else None,
            "mean_diameter_err_px": float(np.mean(self.diameter_err_px)) if d.size else None,
            "misses": self.misses,
            "phantoms": self.phantoms,
            "partial_found": self.partial_found,
            "partial_flag_errors": self.partial_flag_errors,
        }


def ratio_of_medians_ci(
    baseline: list[list[float]], ours: list[list[float]], draws: int = 2000, level: float = 0.95, seed: int = 0
) -> tuple[float, float]:
    """Confidence interval of median(|baseline|) / median(|ours|) by the bootstrap over frames.

    ``baseline`` and ``ours`` hold one list of errors per frame (the same frames, in the
    same order): frames are resampled as units, because the holes of one frame share its
    blur, contrast and texture.  Percentile interval at ``level``.  A 40-frame bench has
    only ~60 holes: its diameter ratio ranged 3.3x-7.8x over five seeds, and one run's
    interval was 2.45-6.11x; this says how far one run's ratio can be trusted.
    """
    if len(baseline) != len(ours):
        raise ValueError(f"{len(baseline)} baseline frames but {len(ours)} of ours: the same frames are needed")
    n = len(ours)
    if n == 0:
        raise ValueError("no frames")
    rng = np.random.default_rng(seed)
    # concatenate once; a draw is a multiset of frames, i.e. a count per frame, and a
    # frame's errors enter a draw as often as the frame was drawn
    b_err, b_frame = _flatten(baseline)
    o_err, o_frame = _flatten(ours)
    ratios = np.empty(draws)
    for k in range(draws):
        counts = np.bincount(rng.integers(0, n, n), minlength=n)
        b = np.repeat(b_err, counts[b_frame])
        o = np.repeat(o_err, counts[o_frame])
        ratios[k] = np.median(b) / np.median(o) if b.size and o.size else np.nan
    ratios = ratios[np.isfinite(ratios)]
    if not ratios.size:
        raise ValueError("no draw had errors of both methods")
    tail = 100 * (1 - level) / 2
    return float(np.percentile(ratios, tail)), float(np.percentile(ratios, 100 - tail))


def _flatten(per_frame: list[list[float]]) -> tuple[np.ndarray, np.ndarray]:
    err = np.abs(np.concatenate([np.asarray(e, float) for e in per_frame])) if per_frame else np.zeros(0)
    frame = np.repeat(np.arange(len(per_frame)), [len(e) for e in per_frame])
    return err, frame


def _match(truths: list[tuple], detections: list[tuple]) -> list[int | None]:
    """The detection matched to each true hole (its index, or None), in the truths'
    order: greedy nearest within a quarter diameter (at least 3 px) of a true centre, each
    detection taken once."""
    used: set[int] = set()
    det = np.asarray([d[:2] for d in detections], float).reshape(-1, 2)
    out: list[int | None] = []
    for tx, ty, td, _ in truths:
        j = None
        if det.size:
            dist = np.hypot(det[:, 0] - tx, det[:, 1] - ty)
            dist[list(used)] = np.inf
            k = int(np.argmin(dist))
            if dist[k] <= max(3.0, 0.25 * td):
                j = k
                used.add(k)
        out.append(j)
    return out


def score_frame(truths: list[tuple], detections: list[tuple], check_partial: bool = True) -> Score:
    """Greedy nearest matching within a quarter diameter (at least 3 px) of a true centre.

    A detection is (x, y, diameter, partial), optionally followed by the standard
    uncertainties (u_diameter, u_x, u_y) of a whole hole (None where there are none)."""
    s = Score()
    matched = _match(truths, detections)
    for (tx, ty, td, tpartial), j in zip(truths, matched):
        if j is None:
            s.misses += 0 if tpartial else 1
            continue
        dpartial = bool(detections[j][3])
        if check_partial and dpartial != bool(tpartial):
            s.partial_flag_errors += 1
        if tpartial:
            s.partial_found += 1
            continue
        s.centre_err_px.append(float(np.hypot(detections[j][0] - tx, detections[j][1] - ty)))
        s.diameter_err_px.append(float(detections[j][2] - td))
        u = tuple(detections[j][4:7])
        if len(u) == 3 and all(v is not None and v > 0 for v in u):
            s.diameter_z.append(float((detections[j][2] - td) / u[0]))
            s.centre_z += [float((detections[j][0] - tx) / u[1]), float((detections[j][1] - ty) / u[2])]
    s.phantoms = len(detections) - sum(j is not None for j in matched)
    return s


def match_whole_holes(truths: list[tuple], detections: list[tuple]) -> list[int | None]:
    """The detection matched to each whole true hole (its index, or None for a miss), by
    ``score_frame``'s rule (the cut holes take their detections too)."""
    return [j for t, j in zip(truths, _match(truths, detections)) if not t[3]]
