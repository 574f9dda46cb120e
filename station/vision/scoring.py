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

    def add(self, other: "Score") -> None:
        self.centre_err_px += other.centre_err_px
        self.diameter_err_px += other.diameter_err_px
        self.misses += other.misses
        self.phantoms += other.phantoms
        self.partial_found += other.partial_found
        self.partial_flag_errors += other.partial_flag_errors

    def summary(self) -> dict:
        c = np.asarray(self.centre_err_px)
        d = np.abs(np.asarray(self.diameter_err_px))
        return {
            "holes_measured": int(c.size),
            "median_centre_err_px": float(np.median(c)) if c.size else None,
            "worst_centre_err_px": float(c.max()) if c.size else None,
            "median_diameter_err_px": float(np.median(d)) if d.size else None,
            "worst_diameter_err_px": float(d.max()) if d.size else None,
            "mean_diameter_err_px": float(np.mean(self.diameter_err_px)) if d.size else None,
            "misses": self.misses,
            "phantoms": self.phantoms,
            "partial_found": self.partial_found,
            "partial_flag_errors": self.partial_flag_errors,
        }


def score_frame(truths: list[tuple], detections: list[tuple], check_partial: bool = True) -> Score:
    """Greedy nearest matching within a quarter diameter (at least 3 px) of a true centre."""
    s = Score()
    used: set[int] = set()
    det = np.asarray([d[:2] for d in detections], float).reshape(-1, 2)
    for tx, ty, td, tpartial in truths:
        if det.size:
            dist = np.hypot(det[:, 0] - tx, det[:, 1] - ty)
            dist[list(used)] = np.inf
            j = int(np.argmin(dist))
        if not det.size or dist[j] > max(3.0, 0.25 * td):
            s.misses += 0 if tpartial else 1
            continue
        used.add(j)
        dpartial = bool(detections[j][3])
        if check_partial and dpartial != bool(tpartial):
            s.partial_flag_errors += 1
        if tpartial:
            s.partial_found += 1
            continue
        s.centre_err_px.append(float(dist[j]))
        s.diameter_err_px.append(float(detections[j][2] - td))
    s.phantoms = len(detections) - len(used)
    return s
