"""Scans and linear tests on the whitened residual.

All tests here work after the AR(1) whitening of :mod:`station.discovery.noise`,
so their reference distributions hold for correlated noise.  The periodic scan
is a least-squares sinusoid fit at every trial frequency (the generalised
Lomb-Scargle periodogram of Zechmeister & Kuerster 2009, with arbitrary nuisance
columns instead of only a floating mean), which handles the uneven target
spacing ISO 230-2 asks for.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

from station.discovery.noise import Whitener

#: frequencies evaluated per chunk of the scan (bounds memory at N x 256 floats)
_CHUNK = 256
#: oversampling of the frequency grid relative to 1/range (VanderPlas 2018 suggests 5-10)
OVERSAMPLING = 5
#: cap on the number of trial frequencies (speed on 10^4-point recordings)
MAX_FREQUENCIES = 1500


def project_out(W: Whitener, nuisance: np.ndarray | None, *arrays: np.ndarray):
    """Whiten the arrays and remove their projection on the whitened nuisance columns."""
    out = [W(a) for a in arrays]
    if nuisance is None or nuisance.shape[1] == 0:
        return out
    q, _ = np.linalg.qr(W(nuisance))
    return [a - q @ (q.T @ a) for a in out]


def linear_test(W: Whitener, r: np.ndarray, null_cols: np.ndarray | None, alt_cols: np.ndarray):
    """F-test of adding ``alt_cols`` to ``null_cols`` in a regression of ``r`` (whitened).

    Returns (p_value, coefficients of alt_cols, RSS reduction fraction).
    """
    n = r.size
    rw, aw = project_out(W, null_cols, r, alt_cols)
    coef, *_ = np.linalg.lstsq(aw, rw, rcond=None)
    rss0 = float(rw @ rw)
    rss1 = float(np.sum((rw - aw @ coef) ** 2))
    q = alt_cols.shape[1]
    k0 = 0 if null_cols is None else null_cols.shape[1]
    dof = n - k0 - q
    if dof <= 0 or rss1 <= 0:
        return 1.0, coef, 0.0
    f = ((rss0 - rss1) / q) / (rss1 / dof)
    return float(stats.f.sf(f, q, dof)), coef, (rss0 - rss1) / rss0 if rss0 > 0 else 0.0


@dataclass
class PeriodicScan:
    period: np.ndarray          # trial periods, position units
    power: np.ndarray           # fraction of the (whitened) residual variance explained
    best_period: float
    best_amplitude: float
    best_phase: float           # for amplitude * sin(2 pi x / period + phase)
    fap: float                  # false-alarm probability of the best peak
    n_independent: float


def _sin_cos_grid(x: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """sin and cos of 2 pi x f on an evenly spaced frequency chunk, by angle addition, shape (F, N).

    Two transcendental evaluations per row instead of one per (row, frequency):
    the scan of a 10^4-point recording is dominated by this.  Errors grow by about
    1e-16 per step, negligible over a chunk of 256.
    """
    s = np.empty((f.size, x.size))   # frequency-major: each step writes contiguous rows
    c = np.empty((f.size, x.size))
    a0 = 2 * np.pi * x * f[0]
    s[0], c[0] = np.sin(a0), np.cos(a0)
    if f.size > 1:
        d = 2 * np.pi * x * (f[1] - f[0])
        sd, cd = np.sin(d), np.cos(d)
        for j in range(1, f.size):
            np.multiply(s[j - 1], cd, out=s[j])
            s[j] += c[j - 1] * sd
            np.multiply(c[j - 1], cd, out=c[j])
            c[j] -= s[j - 1] * sd
    return s, c


_SCAN_CACHE: dict = {}
_SCAN_CACHE_SIZE = 8


def periodic_scan(x: np.ndarray, r: np.ndarray, W: Whitener, p_min: float, p_max: float,
                  nuisance: np.ndarray | None = None) -> PeriodicScan | None:
    """:func:`scan_periodic`, remembered for the last few arguments: the selection scans
    the same residual for the periodic candidate, the non-sinusoidal descriptor and
    the vocabulary alternative it is compared with."""
    key = (hash(x.tobytes()), hash(r.tobytes()), W.phi, hash(W.prev.tobytes()), p_min, p_max,
           None if nuisance is None else hash(nuisance.tobytes()))
    if key in _SCAN_CACHE:
        return _SCAN_CACHE[key]
    out = scan_periodic(x, r, W, p_min, p_max, nuisance)
    if len(_SCAN_CACHE) >= _SCAN_CACHE_SIZE:
        _SCAN_CACHE.pop(next(iter(_SCAN_CACHE)))
    _SCAN_CACHE[key] = out
    return out


def scan_periodic(x: np.ndarray, r: np.ndarray, W: Whitener, p_min: float, p_max: float,
                  nuisance: np.ndarray | None = None) -> PeriodicScan | None:
    """Least-squares sinusoid scan of ``r`` over periods [p_min, p_max].

    The false-alarm probability uses ``M`` independent frequencies in the band
    (about range x bandwidth, Horne & Baliunas 1986) and, per frequency, the exact
    F-distribution of a two-column regression: FAP = 1 - (1 - p_single)^M.
    """
    span = float(np.ptp(x))
    if p_min <= 0 or p_max <= p_min or span <= 0:
        return None
    f_lo, f_hi = 1.0 / p_max, 1.0 / p_min
    n_f = int(np.ceil((f_hi - f_lo) * span * OVERSAMPLING)) + 1
    n_f = int(np.clip(n_f, 16, MAX_FREQUENCIES))
    freqs = np.linspace(f_lo, f_hi, n_f)
    rw = project_out(W, nuisance, r)[0]
    if nuisance is not None and nuisance.shape[1]:
        q, _ = np.linalg.qr(W(nuisance))
    else:
        q = None
    rss0 = float(rw @ rw)
    red = np.empty(n_f)
    coef_s = np.empty(n_f)
    coef_c = np.empty(n_f)
    for i0 in range(0, n_f, _CHUNK):
        f = freqs[i0:i0 + _CHUNK]
        s, c = _sin_cos_grid(x, f)
        s, c = W.along_last(s), W.along_last(c)
        if q is not None:
            s = s - (s @ q) @ q.T
            c = c - (c @ q) @ q.T
        ss, cc, sc = np.einsum("fn,fn->f", s, s), np.einsum("fn,fn->f", c, c), np.einsum("fn,fn->f", s, c)
        sr, cr = s @ rw, c @ rw
        det = ss * cc - sc ** 2
        det = np.where(det > 1e-12 * ss * cc, det, np.inf)
        a = (cc * sr - sc * cr) / det
        b = (ss * cr - sc * sr) / det
        red[i0:i0 + _CHUNK] = a * sr + b * cr
        coef_s[i0:i0 + _CHUNK], coef_c[i0:i0 + _CHUNK] = a, b
    k = int(np.argmax(red))
    n = r.size
    k0 = 0 if q is None else q.shape[1]
    dof = max(n - k0 - 2, 1)
    rss1 = max(rss0 - red[k], 1e-300)
    fstat = ((rss0 - rss1) / 2) / (rss1 / dof)
    p_single = float(stats.f.sf(fstat, 2, dof))
    m = max(1.0, span * (f_hi - f_lo))
    fap = float(-np.expm1(m * np.log1p(-min(p_single, 1 - 1e-16))))
    a, b = coef_s[k], coef_c[k]   # a sin + b cos = A sin(. + phase)
    return PeriodicScan(period=1.0 / freqs, power=red / rss0 if rss0 > 0 else red,
                        best_period=float(1.0 / freqs[k]), best_amplitude=float(np.hypot(a, b)),
                        best_phase=float(np.arctan2(b, a)), fap=fap, n_independent=m)


_GRID_CACHE: dict = {}
_GRID_CACHE_SIZE = 2


def whitened_grid(key: tuple, make, W: Whitener, nuisance: np.ndarray | None) -> np.ndarray:
    """``make()``'s scan columns, whitened and with the nuisance projected out, remembered
    under ``key`` (plus the whitening): a scan grid does not change from one selection
    step to the next, only the residual does."""
    full = key + (W.phi, hash(W.prev.tobytes()), None if nuisance is None else hash(nuisance.tobytes()))
    if full not in _GRID_CACHE:
        if len(_GRID_CACHE) >= _GRID_CACHE_SIZE:
            _GRID_CACHE.pop(next(iter(_GRID_CACHE)))
        _GRID_CACHE[full] = project_out(W, nuisance, make())[0]
    return _GRID_CACHE[full]


def best_column(r: np.ndarray, cols: np.ndarray, W: Whitener, nuisance: np.ndarray | None = None,
                projected: bool = False):
    """Which single column (of a scan grid) explains ``r`` best; (index, coefficient, p_single).

    ``projected``: ``cols`` are already whitened with the nuisance projected out
    (:func:`whitened_grid`)."""
    if projected:
        rw, cw = project_out(W, nuisance, r)[0], cols
    else:
        rw, cw = project_out(W, nuisance, r, cols)
    cc = np.sum(cw * cw, 0)
    cc = np.where(cc > 0, cc, np.inf)
    cr = cw.T @ rw
    red = cr ** 2 / cc
    k = int(np.argmax(red))
    n = r.size
    k0 = 0 if nuisance is None else nuisance.shape[1]
    dof = max(n - k0 - 1, 1)
    rss0 = float(rw @ rw)
    rss1 = max(rss0 - red[k], 1e-300)
    p = float(stats.f.sf((rss0 - rss1) / (rss1 / dof), 1, dof))
    return k, float(cr[k] / cc[k]), p
