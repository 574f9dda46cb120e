"""What the master checks say, read as a whole: a step, a drift, or not yet known.

One master check tells how far the holes read from their certificate now. Several,
in time order, tell what kind of change it is, which is what names the physics
(docs/monitor.md, The loop):

* a **step**: the errors were steady, jumped between two checks and stayed (a knock, a
  collision moved the part's datum: ISO 230-1's location error EZ0 of the workholding);
* a **drift**: the errors change steadily with time (the part, the frame or the grating
  warming or cooling: the station has no thermometer, so it sees a thermal drift as the
  rate at which its checks move);
* **not yet known**: two checks cannot tell a step from a fast drift; the next one does.

Each check's errors are kept in the frame of the model the station started with (the
changes approved since then are taken off), so checks under different models are
comparable. Time is the station's machine clock (seconds; on hardware the host's
clock, in simulation the drives' scaled clock, the one the world's physics runs on).

Along with the kind: the present value of the error per hole (from the fit, less noisy
than the last check alone), the drift rate with its standard uncertainty, and the
scale the holes show against their distance from the datum face (a part expanding
from its face reads long in proportion: the session proposes it as the part's
expansion, ``part.scale_ppm``, the master of the parts' material standing in for a
thermometer, and covers it in the stated uncertainty until then).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

#: at most this many of the latest checks are read (older ones may be another regime)
WINDOW = 8
#: chi-square difference that tells two explanations apart (Kass and Raftery's "strong")
DECISIVE = 6.0
#: a drift whose rate is this many standard uncertainties from zero is a drift
SIGNIFICANT = 3.0
#: a drift's value now and its rate come from the latest this many checks: a thermal
#: drift slows as the bodies settle (a first-order lag), and a line through a long
#: window would miss where it is now
RECENT = 4


@dataclass(frozen=True)
class MasterRecord:
    """One master check: when (machine clock s, inspections so far), and per hole its
    axial place (mm), its error against the certificate in the starting model's frame
    (um) and that error's combined standard uncertainty (station and certificate, um)."""

    time_s: float
    index: int
    position_mm: dict[str, float]
    error_um: dict[str, float]
    u_um: dict[str, float]
    #: per hole the table's nominal angle for it (deg; the part family's drawing)
    angle_deg: dict[str, float] = field(default_factory=dict)

    def mean(self) -> tuple[float, float]:
        """The mean error over the holes and its standard uncertainty (um)."""
        e = np.array(list(self.error_um.values()))
        u = np.array([self.u_um[h] for h in self.error_um])
        return float(e.mean()), float(math.sqrt(np.sum(u**2)) / len(u))


@dataclass
class Explanation:
    """What the checks say (see the module's docstring)."""

    kind: str  # "step" | "drift" | "unknown" | "steady"
    #: per hole: the error now (starting model's frame, um)
    now_um: dict[str, float]
    description: str
    checks: int
    rate_um_per_h: float | None = None
    rate_u_um_per_h: float | None = None
    #: between which checks (machine clock s) a step fell
    step_between_s: tuple[float, float] | None = None
    #: the holes' error per mm of distance from the datum face (um/mm = 1000 ppm) and its u
    scale_ppm: float | None = None
    scale_u_ppm: float | None = None
    chi2: dict[str, float] = field(default_factory=dict)

    def to_json(self) -> dict:
        return asdict(self)

    @property
    def drifting(self) -> bool:
        return self.kind == "drift" and self.rate_um_per_h is not None


def _wls(X: np.ndarray, y: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Weighted least squares: coefficients, their covariance, chi-square."""
    w = 1.0 / u
    A = X * w[:, None]
    coef, *_ = np.linalg.lstsq(A, y * w, rcond=None)
    cov = np.linalg.pinv(A.T @ A)
    r = (y - X @ coef) * w
    return coef, cov, float(r @ r)


def scale_of(records: list[MasterRecord]) -> tuple[float, float] | None:
    """The holes' error against their axial place, pooled over the checks (each check's
    own offset taken out): ppm and its standard uncertainty; None with one hole."""
    xs, ys, us, groups = [], [], [], []
    for k, r in enumerate(records):
        for h, e in r.error_um.items():
            xs.append(r.position_mm[h])
            ys.append(e)
            us.append(r.u_um[h])
            groups.append(k)
    if len(set(xs)) < 2:
        return None
    n_g = len(records)
    X = np.zeros((len(xs), n_g + 1))
    for i, g in enumerate(groups):
        X[i, g] = 1.0
    X[:, -1] = np.asarray(xs) - np.mean(xs)
    coef, cov, _ = _wls(X, np.asarray(ys), np.asarray(us))
    return float(coef[-1] * 1e3), float(math.sqrt(cov[-1, -1]) * 1e3)


def explain(records: list[MasterRecord]) -> Explanation:
    """Read the latest checks (``WINDOW`` at most, oldest first) as a step, a drift,
    steady, or not yet known."""
    if not records:
        raise ValueError("no master checks to explain")
    recs = records[-WINDOW:]
    holes = list(recs[-1].error_um)
    t = np.array([r.time_s for r in recs])
    m = np.array([r.mean()[0] for r in recs])
    u = np.array([r.mean()[1] for r in recs])
    sc = scale_of(recs)
    scale = {} if sc is None else {"scale_ppm": sc[0], "scale_u_ppm": sc[1]}
    last = recs[-1]
    ones = np.ones_like(t)
    if len(recs) == 1:
        return Explanation("unknown", dict(last.error_um), "one check: the error now, its kind not yet known",
                           1, **scale)
    _, _, chi_const = _wls(ones[:, None], m, u)
    # drift: a straight line in time, its value now at the last check
    span_h = max((t[-1] - t[0]) / 3600.0, 1e-9)
    coef, cov, chi_lin = _wls(np.column_stack([ones, (t - t[-1]) / 3600.0]), m, u)
    rate, rate_u = float(coef[1]), float(math.sqrt(cov[1, 1]))
    # step: steady before and after one jump, the best place for it
    best = None
    for j in range(1, len(recs)):
        X = np.column_stack([ones, (np.arange(len(recs)) >= j).astype(float)])
        c, _, chi = _wls(X, m, u)
        if best is None or chi < best[0]:
            best = (chi, j, c)
    chi_step, j, c_step = best
    chi2 = {"steady": chi_const, "drift": chi_lin, "step": chi_step}

    def per_hole(shift_now: float) -> dict[str, float]:
        # each hole's own errors where the explanation holds, moved to the value now
        return {h: float(last.error_um[h] - m[-1] + shift_now) for h in holes}

    if len(recs) == 2:
        return Explanation("unknown", dict(last.error_um),
                           f"two checks {(t[1] - t[0]) / 60.0:.1f} min apart moved {m[1] - m[0]:+.2f} um: a step "
                           f"or a drift, the next check tells", 2, rate, rate_u, chi2=chi2, **scale)
    dof = len(recs) - 2
    if chi_const <= dof + 1 + 2.0 * math.sqrt(2.0 * (dof + 1)) and chi_const <= min(chi_lin, chi_step) + DECISIVE:
        mean_now = float(np.average(m, weights=1.0 / u**2))
        return Explanation("steady", per_hole(mean_now), f"{len(recs)} checks steady at {mean_now:+.2f} um on average",
                           len(recs), rate, rate_u, chi2=chi2, **scale)
    if chi_lin + DECISIVE <= chi_step and abs(rate) >= SIGNIFICANT * rate_u:
        k = min(RECENT, len(recs))
        coef, cov, _ = _wls(np.column_stack([ones[-k:], (t[-k:] - t[-1]) / 3600.0]), m[-k:], u[-k:])
        rate, rate_u = float(coef[1]), float(math.sqrt(cov[1, 1]))
        return Explanation("drift", per_hole(float(coef[0])),
                           f"{len(recs)} checks over {span_h * 60.0:.0f} min drift, lately at {rate:+.1f} +/- "
                           f"{rate_u:.1f} um/h: the part, the frame or the grating warming or cooling",
                           len(recs), rate, rate_u, chi2=chi2, **scale)
    if chi_step + DECISIVE <= chi_lin:
        after = float(c_step[0] + c_step[1])
        return Explanation("step", per_hole(after),
                           f"steady at {c_step[0]:+.2f} um, then {after:+.2f} um from the check at "
                           f"{t[j] / 60.0:.1f} min on: the datum moved between two checks (a knock, a collision)",
                           len(recs), rate, rate_u, (float(t[j - 1]), float(t[j])), chi2=chi2, **scale)
    return Explanation("unknown", dict(last.error_um),
                       f"{len(recs)} checks fit a step and a drift alike (chi-square {chi_step:.1f} and "
                       f"{chi_lin:.1f}): the next check tells", len(recs), rate, rate_u, chi2=chi2, **scale)
