"""The compiled kernels of the vision stage against facts worked out by hand."""

import numpy as np
import pytest

from station.vision.edges import _ray_peaks
from station.vision.fit import solve_small


def _rays(peaks, sigma=1.2, step=0.5, n_s=31, extra=None):
    """Gradient samples (rays, samples, 2) of Gaussian radial-derivative profiles peaking
    at ``peaks`` (in samples), along rays at angles 0, 90, 180 deg..."""
    s = np.arange(n_s) * step
    n = len(peaks)
    ang = np.arange(n) * np.pi / 2
    u = np.stack([np.cos(ang), np.sin(ang)], 1)
    g = np.exp(-0.5 * ((s[None, :] - np.asarray(peaks)[:, None] * step) / sigma) ** 2) * 40.0
    if extra is not None:
        g = g + extra
    g2 = np.stack([g * u[:, 0:1], g * u[:, 1:2]], axis=2).astype(np.float32)
    return g2, u


def test_the_log_parabola_finds_a_gaussian_peak_exactly_at_any_phase():
    peaks = [10.0, 10.3, 12.49, 14.75]  # sub-sample phases
    g2, u = _rays(peaks)
    k, ok, offset, sigma2, peak, win = _ray_peaks(g2, u, 4, 0.5)
    assert ok.all()
    # float32 samples: exact to their rounding
    np.testing.assert_allclose(k * 0.5 + offset, np.asarray(peaks) * 0.5, atol=2e-5)
    np.testing.assert_allclose(sigma2, 1.2**2, rtol=1e-4)
    assert win.shape == (4, 9) and np.all(peak > 0)


def test_the_innermost_strong_peak_is_the_rim_and_weak_or_cut_windows_are_refused():
    s = np.arange(31) * 0.5
    # ray 0: a stronger peak further out (a groove's far side) must not win
    outer = np.zeros((3, 31))
    outer[0] = 60.0 * np.exp(-0.5 * ((s - 12.0) / 1.0) ** 2)
    g2, u = _rays([8.0, 8.0, 1.0], extra=outer)  # ray 2 peaks too near the start for a window
    k, ok, offset, sigma2, peak, win = _ray_peaks(g2, u, 4, 0.5)
    assert ok[0] and k[0] * 0.5 + offset[0] == pytest.approx(4.0, abs=0.02)
    assert ok[1]
    assert not ok[2]
    # a window holding a value <= 0 cannot be fitted in the log
    g2, u = _rays([10.0], extra=np.where(np.arange(31) == 8, -100.0, 0.0)[None, :])
    assert not _ray_peaks(g2, u, 4, 0.5)[1][0]


def test_the_small_solver_matches_lapack_and_reports_singular_systems():
    rng = np.random.default_rng(0)
    for k in (3, 5, 6):
        a = rng.normal(size=(k, k))
        m = a @ a.T + k * np.eye(k)
        v = rng.normal(size=k)
        x, ok = solve_small(m, v)
        assert ok
        np.testing.assert_allclose(x, np.linalg.solve(m, v), rtol=1e-10, atol=1e-12)
    singular = np.array([[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 0.0, 0.0]])
    assert not solve_small(singular, np.ones(3))[1]
