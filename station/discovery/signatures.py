"""Where the residual is structured: the report's ``findings``.

Each signature is a linear (or scanned) test on the whitened residual, with the
family of tests Bonferroni-corrected at ``FINDING_ALPHA``.  They describe the
mismatch in the metrologist's terms -- direction, position, time, temperature,
periodic, angle, local -- independently of which effects are later chosen, so a
reader can see the evidence behind the effects and, when the verdict is
``partly-explained``, where structure remains.
"""

from __future__ import annotations

import numpy as np

from station.discovery.data import Prepared
from station.discovery.library import MAX_STEP_POSITIONS, distinct_targets, local_defect_columns, \
    local_defect_grid, period_limits, step_columns, step_gaps
from station.discovery.noise import Whitener
from station.discovery.scans import PeriodicScan, best_column, linear_test, periodic_scan

#: family-wise significance of the findings of one residual
FINDING_ALPHA = 0.01


def _norm(v: np.ndarray) -> np.ndarray:
    s = np.ptp(v)
    return (v - v.mean()) / (s if s > 0 else 1.0)


def _unit(kind: str) -> tuple[str, str]:
    return ("um", "mm") if kind == "linear" else ("arcsec", "deg")


def find_signatures(prep: Prepared, r: np.ndarray, W: Whitener) -> tuple[list[dict], PeriodicScan | None]:
    """Findings of residual ``r`` (same rows as ``prep``) and the periodic scan behind them."""
    du, pu = _unit(prep.kind)
    n = prep.n
    whole = [float(prep.x.min()), float(prep.x.max())]
    ones = np.ones((n, 1))
    xn = _norm(prep.x)
    tests: list[tuple[str, float, dict]] = []   # (signature, p, finding)

    if np.unique(prep.direction).size == 2:
        p, coef, _ = linear_test(W, r, ones, prep.direction[:, None])
        tests.append(("direction", p, {
            "range": whole, "direction": "both",
            "description": f"mean residual differs by {2 * coef[0]:.3g} {du} between approach "
                           f"directions (+1 minus -1)"}))

    p, coef, _ = linear_test(W, r, None, np.column_stack([ones, xn, xn ** 2 - np.mean(xn ** 2)]))
    tests.append(("position", p, {
        "range": whole, "direction": "both",
        "description": f"residual varies along the travel: mean {coef[0]:.3g} {du}, "
                       f"{coef[1]:.3g} {du} from start to end, curvature {coef[2]:.3g} {du}"}))

    if prep.time_s is not None:
        tn = _norm(prep.time_s)
        p, coef, _ = linear_test(W, r, np.column_stack([ones, xn]), np.column_stack([tn, tn ** 2]))
        run_ids = np.unique(prep.run)
        means = np.array([r[prep.run == k].mean() for k in run_ids])
        tests.append(("time", p, {
            "range": whole, "direction": "both",
            "description": f"residual changes with time: {coef[0]:.3g} {du} over the campaign "
                           f"(linear part); run means span {np.ptp(means):.3g} {du}"}))

    if prep.temperature_c is not None and np.ptp(prep.temperature_c) > 0:
        tc = prep.temperature_c - prep.temperature_c.mean()
        p, coef, _ = linear_test(W, r, np.column_stack([ones, xn]), np.column_stack([tc, prep.x * tc]))
        tests.append(("temperature", p, {
            "range": whole, "direction": "both",
            "description": f"residual follows temperature ({np.ptp(prep.temperature_c):.2f} K range): "
                           f"{coef[1]:.3g} {du}/({pu} K) with position, {coef[0]:.3g} {du}/K overall"}))

    if prep.kind == "rotary" and np.ptp(prep.x) >= 180.0:
        rad = np.radians(prep.x)
        p, coef, _ = linear_test(W, r, ones, np.column_stack([np.sin(rad), np.cos(rad)]))
        tests.append(("angle", p, {
            "range": whole, "direction": "both",
            "description": f"once-per-revolution sine of amplitude {np.hypot(*coef):.3g} {du} "
                           f"(phase {np.degrees(np.arctan2(coef[1], coef[0])):.0f} deg)"}))

    p_min, p_max = period_limits(prep)
    scan = periodic_scan(prep.x, r, W, p_min, p_max, nuisance=np.column_stack([ones, prep.x]))
    if scan is not None:
        tests.append(("periodic", scan.fap, {
            "range": whole, "direction": "both", "period": scan.best_period,
            "false_alarm_probability": scan.fap,
            "description": f"periodic in position: period {scan.best_period:.4g} {pu}, amplitude "
                           f"{scan.best_amplitude:.3g} {du} (false-alarm probability {scan.fap:.2g}, "
                           f"{scan.n_independent:.0f} independent frequencies scanned)"}))

    if distinct_targets(prep).size >= 8:
        centres, widths = local_defect_grid(prep)
        cols = local_defect_columns(prep, centres, widths)
        k, coef, p1 = best_column(r, cols, W, np.column_stack([ones, xn, xn ** 2]))
        c, w = float(centres[k]), float(widths[k])
        p = min(1.0, p1 * centres.size)
        tests.append(("local", p, {
            "range": [max(whole[0], c - 2 * w), min(whole[1], c + 2 * w)], "direction": "both",
            "description": f"a local {'bump' if coef > 0 else 'dip'} of {abs(coef):.3g} {du} around "
                           f"{c:.4g} {pu} (width {w:.3g} {pu})"}))

    left, right = step_gaps(prep)
    if left.size:
        # a jump that stays (a joint between scale segments), beyond a straight line;
        # every gap is a hypothesis (Bonferroni)
        every = int(np.ceil(left.size / MAX_STEP_POSITIONS))     # thinned on dense recordings
        left, right = left[::every], right[::every]
        mids = (left + right) / 2.0
        k, coef, p1 = best_column(r, step_columns(prep, mids), W, np.column_stack([ones, xn]))
        p = min(1.0, p1 * mids.size * every)
        tests.append(("position", p, {
            "range": [float(left[k]), float(right[k])], "direction": "both", "step_at": float(mids[k]),
            "description": f"a step of {coef:+.3g} {du} between {left[k]:.4g} and {right[k]:.4g} {pu}: the "
                           f"residual jumps there and stays (beyond a straight line)"}))

    m = max(len(tests), 1)
    findings = []
    for sig, p, f in tests:
        if p < FINDING_ALPHA / m:
            findings.append({"signature": sig, **f, "p_value": float(p)})
    return findings, scan
