"""The whiteness test of the report's ``white`` flag.

``white`` is true when the residual, *whitened for the AR(1) noise the repeated
approaches show* (so correlated but structureless noise counts as white), passes
both of:

* the Ljung-Box portmanteau test (Ljung & Box 1978) on the whitened residual in
  time order, runs concatenated, at lag ``min(10, n/5)``
  (:func:`statsmodels.stats.diagnostic.acorr_ljungbox`): catches any remaining
  autocorrelation, i.e. smooth structure along the travel or in time;
* the Wald-Wolfowitz runs test on the signs of the whitened residual about its
  median: catches long stretches on one side, robust to outliers and to the
  shape of the noise distribution.

Each at ``WHITE_ALPHA``; the residual is white when both p-values exceed it.
"""

from __future__ import annotations

import numpy as np
from scipy import stats
from statsmodels.stats.diagnostic import acorr_ljungbox

#: significance of each whiteness test (1 %: a clean recording fails about 2 % of the time)
WHITE_ALPHA = 0.01


def runs_test(v: np.ndarray) -> float:
    """Two-sided p-value of the Wald-Wolfowitz runs test on the signs of ``v - median``."""
    s = v - np.median(v)
    s = s[s != 0] > 0
    n1, n2 = int(np.count_nonzero(s)), int(np.count_nonzero(~s))
    if n1 == 0 or n2 == 0:
        return 0.0
    runs = 1 + int(np.count_nonzero(s[1:] != s[:-1]))
    n = n1 + n2
    mean = 2.0 * n1 * n2 / n + 1
    var = 2.0 * n1 * n2 * (2.0 * n1 * n2 - n) / (n ** 2 * (n - 1))
    if var <= 0:
        return 1.0
    z = (runs - mean) / np.sqrt(var)
    return float(2 * stats.norm.sf(abs(z)))


def whiteness(rw: np.ndarray) -> dict:
    """Both tests on an already whitened residual (time order)."""
    n = rw.size
    if n < 10:
        return {"white": True, "ljung_box_p": None, "runs_p": None, "lags": 0}
    lags = int(max(1, min(10, n // 5)))
    lb = acorr_ljungbox(rw - rw.mean(), lags=[lags], return_df=True)
    p_lb = float(lb["lb_pvalue"].iloc[0])
    p_runs = runs_test(rw)
    return {"white": bool(p_lb > WHITE_ALPHA and p_runs > WHITE_ALPHA),
            "ljung_box_p": p_lb, "runs_p": p_runs, "lags": lags}
