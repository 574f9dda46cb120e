"""PNG plots of the residual before and after, and of the periodic spectrum.

Matplotlib's Agg backend (no display needed on the station PC).  One file per
view so a report viewer can show the one it needs.
"""

from __future__ import annotations

import threading
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

_COLOURS = {1: "tab:red", -1: "tab:blue"}

#: pyplot keeps global state (the current figure): one picture at a time in a process,
#: whichever thread draws it (the API draws off its loop, the station's session too)
PLOT_LOCK = threading.RLock()


def _units(kind: str) -> tuple[str, str]:
    return ("um", "mm") if kind == "linear" else ("arcsec", "deg")


def write_plots(d, out: Path) -> list[Path]:
    with PLOT_LOCK:
        return _write_plots(d, out)


def _write_plots(d, out: Path) -> list[Path]:
    prep = d.prep
    du, pu = _units(prep.kind)
    paths: list[Path] = []
    pairs = (("before", d.before_residual), ("after", d.after_residual))

    def scatter_against(v, label, fname):
        fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
        for ax, (stage, r) in zip(axes, pairs):
            for s, c in _COLOURS.items():
                m = prep.direction == s
                ax.plot(v[m], r[m], ".", color=c, ms=3, label=f"direction {s:+d}")
            ax.axhline(0, color="k", lw=0.5)
            ax.set_title(f"residual {stage} (rms {np.sqrt(np.mean(r ** 2)):.3g} {du})")
            ax.set_xlabel(label)
        axes[0].set_ylabel(f"recording - model [{du}]")
        axes[0].legend(loc="best", fontsize=8)
        fig.tight_layout()
        p = out / fname
        fig.savefig(p, dpi=100)
        plt.close(fig)
        paths.append(p)

    scatter_against(prep.x, f"target [{pu}]", "residual_position.png")
    if prep.time_s is not None:
        scatter_against(prep.time_s, "time [s]", "residual_time.png")
    else:
        scatter_against(np.arange(prep.n, dtype=float), "row (no trustworthy time)", "residual_time.png")

    fig, axes = plt.subplots(1, 2, figsize=(8, 4), sharey=True)
    for ax, (stage, r) in zip(axes, pairs):
        data = [r[prep.direction == s] for s in (1, -1)]
        ax.boxplot(data)
        ax.set_xticks([1, 2], ["+1", "-1"])
        ax.set_title(f"residual {stage} by direction")
        ax.set_xlabel("approach direction")
    axes[0].set_ylabel(f"[{du}]")
    fig.tight_layout()
    p = out / "residual_direction.png"
    fig.savefig(p, dpi=100)
    plt.close(fig)
    paths.append(p)

    if d.scan is not None:
        fig, ax = plt.subplots(figsize=(8, 4))
        ax.semilogx(d.scan.period, d.scan.power, lw=0.8)
        found = [e for e in d.report["effects"] if e["name"] == "periodic"]
        for e in found:
            ax.axvline(e["parameters"]["period"], color="tab:red", ls="--",
                       label=f"found period {e['parameters']['period']:.4g} {pu}")
        ax.axvline(d.scan.best_period, color="tab:grey", ls=":",
                   label=f"highest peak (FAP {d.scan.fap:.2g})")
        ax.set_xlabel(f"period [{pu}]")
        ax.set_ylabel("fraction of residual variance")
        ax.set_title("least-squares periodogram of the residual before")
        ax.legend(fontsize=8)
        fig.tight_layout()
        p = out / "spectrum.png"
        fig.savefig(p, dpi=100)
        plt.close(fig)
        paths.append(p)
    return paths
