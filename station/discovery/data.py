"""The recording as discovery sees it: residual, usable channels, groups, outliers.

Discovery works on the residual ``r = recording - model prediction``.  Before any
statistics, this module decides what the recording can support (is the time column
trustworthy? does the temperature vary?), groups repeated approaches (same target,
same direction, different runs) and removes gross outliers such as a blocked laser
beam, so that every later step sees the same clean arrays.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from station.axis_model import AxisModel
from station.effects import EvalContext
from station.recording import Recording

#: MAD -> standard deviation for normal data (1/Phi^-1(3/4)); Rousseeuw & Croux (1993)
MAD_TO_SIGMA = 1.4826
#: a point further than this many robust sigmas from its repeated approaches is an
#: outlier (blocked beam, dust on the optics); the brief asks for 6 sigma, which a
#: normal sample of 10^8 points would exceed about once (two-sided 2e-9)
OUTLIER_ROBUST_SIGMAS = 6.0
#: temperature range below which the column cannot separate a temperature effect
#: from a scale error: 0.1 K is the resolution of a typical material sensor
#: (ISO 230-3 asks for 0.1 K)
MIN_TEMPERATURE_RANGE_K = 0.1


@dataclass
class Prepared:
    """Arrays of the usable rows (outliers removed), in file order."""

    kind: str
    x: np.ndarray               # target, mm or deg
    direction: np.ndarray       # +1 / -1
    run: np.ndarray
    time_s: np.ndarray | None   # None when the column cannot be trusted
    temperature_c: np.ndarray | None
    residual: np.ndarray        # recording - model prediction, um or arcsec
    line: np.ndarray            # file line of every row
    group: np.ndarray           # index of the (target, direction) group of each row
    prev: np.ndarray            # index of the previous row of the same run, -1 at a run start
    outliers: list[dict] = field(default_factory=list)
    not_analysed: list[dict] = field(default_factory=list)
    #: further numeric columns of the recording (e.g. angle_arcsec), usable rows only
    channels: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def n(self) -> int:
        return int(self.x.size)

    def ctx(self, mask: np.ndarray | None = None) -> EvalContext:
        """Evaluation context for the effects (all rows, or a subset)."""
        sel = slice(None) if mask is None else mask
        return EvalContext.make(
            self.x[sel], self.kind, self.direction[sel],
            None if self.time_s is None else self.time_s[sel],
            None if self.temperature_c is None else self.temperature_c[sel],
            {k: v[sel] for k, v in self.channels.items()} or None,
        )

    def subset(self, mask: np.ndarray) -> "Prepared":
        idx = np.flatnonzero(mask)
        return Prepared(
            self.kind, self.x[idx], self.direction[idx], self.run[idx],
            None if self.time_s is None else self.time_s[idx],
            None if self.temperature_c is None else self.temperature_c[idx],
            self.residual[idx], self.line[idx], self.group[idx],
            previous_in_run(self.run[idx]), [], [],
            {k: v[idx] for k, v in self.channels.items()},
        )


def previous_in_run(run: np.ndarray) -> np.ndarray:
    """Index of the previous row of the same run in file (= time) order, -1 at a run's start.

    A recording's time is non-decreasing, so file order is time order; runs are
    treated as separate sequences for the correlated-noise model.
    """
    n = run.size
    prev = np.full(n, -1, dtype=int)
    order = np.lexsort((np.arange(n), run))          # by run, then file order
    same = run[order][1:] == run[order][:-1]
    prev[order[1:][same]] = order[:-1][same]
    return prev


def target_groups(x: np.ndarray, direction: np.ndarray, kind: str) -> np.ndarray:
    """Group index of every row: same nominal target (to 1e-6 of a unit) and direction."""
    xr = np.round(np.mod(x, 360.0) if kind == "rotary" else x, 6)
    keys = np.stack([xr, direction.astype(float)], axis=1)
    _, inverse = np.unique(keys, axis=0, return_inverse=True)
    return inverse.ravel()


def _loo_group_median(values: np.ndarray, group: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Median of the *other* members of each row's group (leave-one-out), and group sizes.

    Leaving the row out matters: with five repeats, one row in five *is* the
    median, and its zero distance would shrink the robust scale (MAD) by a fifth.
    """
    ng = int(group.max()) + 1 if group.size else 0
    counts = np.bincount(group, minlength=ng)
    out = np.zeros(values.size)
    order = np.argsort(group, kind="stable")
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    for g in np.flatnonzero(counts >= 2):
        rows = order[starts[g]: starts[g] + counts[g]]
        v = values[rows]
        others = np.broadcast_to(v, (v.size, v.size))[~np.eye(v.size, dtype=bool)].reshape(v.size, v.size - 1)
        out[rows] = np.median(others, axis=1)
    return out, counts[group]


def find_outliers(residual: np.ndarray, group: np.ndarray, run: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Rows whose residual is far from their repeated approaches (robust z > 6).

    Each row is compared with the median of its (target, direction) group, so every
    deterministic error of position and direction cancels; a per-run median of
    those differences is removed too, so a slow drift between runs does not
    widen the scale.  Rows without at least two other repeats are compared with
    the running median of their own run instead.  Returns (mask, robust_z, sigma).
    """
    med, counts = _loo_group_median(residual, group)
    dev = residual - med
    run_ids, run_idx = np.unique(run, return_inverse=True)
    run_med = np.array([np.median(dev[run_idx == k]) for k in range(run_ids.size)])
    dev = dev - run_med[run_idx]
    # rows with few repeats: compare with a running median (5 points) of the run
    few = counts < 3
    if np.any(few):
        for k in range(run_ids.size):
            rows = np.flatnonzero((run_idx == k) & few)
            all_rows = np.flatnonzero(run_idx == k)
            if rows.size == 0:
                continue
            pos = np.searchsorted(all_rows, rows)
            for r, p in zip(rows, pos):
                window = residual[all_rows[max(0, p - 2): p + 3]]
                dev[r] = residual[r] - np.median(window)
    usable = dev[~few] if np.count_nonzero(~few) >= 10 else dev
    sigma = MAD_TO_SIGMA * np.median(np.abs(usable - np.median(usable)))
    if sigma <= 0:
        sigma = np.std(usable) or 1.0
    z = dev / sigma
    return np.abs(z) > OUTLIER_ROBUST_SIGMAS, z, float(sigma)


def prepare(model: AxisModel, rec: Recording) -> Prepared:
    """Residual, trustworthy channels and outlier removal for one recording."""
    kind = model.kind
    not_analysed: list[dict] = []
    if rec.metadata.get("kind") and rec.kind != kind:
        not_analysed.append({"what": "axis kind", "why": f"recording says {rec.kind!r}, model says {kind!r}; the model's kind is used"})
    residual = rec.deviation - model.predict(rec)
    time_s: np.ndarray | None = rec.time_s
    if np.ptp(rec.time_s) <= 0 or np.unique(rec.time_s).size < max(3, rec.time_s.size // 10):
        time_s = None
        not_analysed.append({
            "what": "time", "signature": "time",
            "why": "the time_s column is constant or mostly repeated, so drift with time "
                   "(thermal_drift) cannot be analysed; rows are taken in file order",
        })
    temp = rec.temperature_c
    if temp is None:
        not_analysed.append({
            "what": "temperature", "signature": "temperature",
            "why": "the recording has no temperature_c column: thermal expansion cannot be "
                   "told from a scale error (log the material temperature to separate them)",
        })
    elif np.ptp(temp) < MIN_TEMPERATURE_RANGE_K:
        not_analysed.append({
            "what": "temperature", "signature": "temperature",
            "why": f"temperature_c varies by only {np.ptp(temp):.3f} K: thermal expansion is "
                   "indistinguishable from a scale error at constant temperature",
        })
    line = rec.line if rec.line is not None else np.arange(len(rec)) + 1
    group = target_groups(rec.target, rec.direction, kind)
    out_mask, z, _ = find_outliers(residual, group, rec.run)
    outliers = [
        {"line": int(line[i]), "run": int(rec.run[i]), "target": float(rec.target[i]),
         "direction": int(rec.direction[i]), "residual": float(residual[i]), "robust_z": float(z[i])}
        for i in np.flatnonzero(out_mask)
    ]
    keep = ~out_mask
    prep = Prepared(
        kind=kind,
        x=rec.target[keep].astype(float),
        direction=rec.direction[keep].astype(float),
        run=rec.run[keep],
        time_s=None if time_s is None else time_s[keep].astype(float),
        temperature_c=None if temp is None else temp[keep].astype(float),
        residual=residual[keep],
        line=line[keep],
        group=target_groups(rec.target[keep], rec.direction[keep], kind),
        prev=previous_in_run(rec.run[keep]),
        outliers=outliers,
        not_analysed=not_analysed,
        channels={k: v[keep] for k, v in rec.numeric_channels().items()},
    )
    return prep
