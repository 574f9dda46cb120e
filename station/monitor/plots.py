"""The proposal as a picture: the master checks' errors before and after the change.

Matplotlib's Agg backend (no display on the station PC). Left: each master check's
position error per hole (measured − certified, in the present model's frame) against
the machine clock, with each point's ±2u bar and the station's stated U as a band;
right: the same with the proposal's expected change applied, what the checks would have
shown under the proposed model.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from station.discovery.plots import PLOT_LOCK  # noqa: E402


def write_proposal_plot(p, path: Path) -> Path | None:
    """``p``: a ``Proposal`` whose explanation holds ``points`` (time_s, hole,
    error_um, u_um); None when it has none to show. After a step, the checks before it
    were another state of the machine: the right-hand side shows the change on the
    checks since the step (the earlier ones in grey, as they were)."""
    if (p.explanation or {}).get("kind") == "calibration":
        # a self-calibration's proposal: its curves before and after (it takes the lock)
        from station.calibration.proposal import write_calibration_plot

        return write_calibration_plot(p, path)
    pts = (p.explanation or {}).get("points") or []
    if not pts:
        return None
    with PLOT_LOCK:
        return _draw(p, pts, path)


def _draw(p, pts: list[dict], path: Path) -> Path:
    step = (p.explanation or {}).get("step_between_s") if (p.explanation or {}).get("kind") == "step" else None
    since = step[1] if step else -np.inf
    holes = sorted({q["hole"] for q in pts})
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    t0 = min(q["time_s"] for q in pts)
    span_min = max((max(q["time_s"] for q in pts) - t0) / 60.0, 1.0)
    for ax, stage in zip(axes, ("before", "after")):
        shown = []
        for k, h in enumerate(holes):
            q = [x for x in pts if x["hole"] == h]
            t = np.array([(x["time_s"] - t0) / 60.0 for x in q]) + 0.01 * span_min * k
            e = np.array([x["error_um"] for x in q])
            u = np.array([2.0 * x["u_um"] for x in q])
            now = np.array([x["time_s"] >= since for x in q])
            if stage == "after":
                if (~now).any():
                    ax.errorbar(t[~now], e[~now], yerr=u[~now], fmt="o", ms=3, color="0.7", capsize=2)
                t, e, u = t[now], e[now] + float(p.expected_change_um.get(h, 0.0)), u[now]
            ax.errorbar(t, e, yerr=u, fmt="o-", ms=4, lw=0.8, capsize=2, label=h)
            shown.extend(e)
        rms = float(np.sqrt(np.mean(np.square(shown)))) if shown else float("nan")
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_title(f"{stage} the change (rms {rms:.2f} um)" + (" since the step" if step and stage == "after" else ""))
        ax.set_xlabel("machine clock since the first check shown [min]")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("master: measured - certified [um] (bars: 2u)")
    axes[0].legend(loc="best", fontsize=8)
    kind = (p.explanation or {}).get("kind", "")
    fig.suptitle(f"proposal {p.id}: {', '.join(c.term for c in p.changes)}" + (f" ({kind})" if kind else ""),
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path
