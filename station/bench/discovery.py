"""``station bench discovery``: how often discovery is wrong, how sensitive it is, how fast.

* false-claim rate: over clean recordings (varied campaigns, noise level and AR(1)
  correlation), the fraction in which any effect is claimed (goal <= 5 %);
* power curve: per effect, the detection rate against effect size in noise units
  (size = the effect's peak contribution / noise sigma);
* coverage: the fraction of true parameters within +-1.96 reported standard errors
  (95 % if the errors are honest), over the detected datasets of size >= 4;
* time for a 10,000-point recording (goal <= 5 s), median of 3.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
import typer
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from station.discovery import discover
from station.discovery.library import LocalDefect
from station.discovery.synth import Campaign, linear_model, make_recording, rotary_campaign, rotary_model
from station.effects import Backlash, Eccentricity, Offset, Periodic, Scale, ThermalDrift, ThermalExpansion

#: effect sizes (peak contribution / noise sigma) of the power curve
SIZES = (0.5, 1.0, 2.0, 4.0)
TRAVEL_MM = 120.0
WARMUP_K = 4.0


def _clean_case(rng: np.random.Generator, seed: int):
    """A clean recording from a varied campaign: kind, spacing, noise, correlation, extras."""
    sigma = float(rng.uniform(0.2, 1.0))
    phi = float(rng.uniform(0.0, 0.6))
    if rng.random() < 0.25:
        return rotary_model(sigma), rotary_campaign(sigma=sigma, phi=phi, seed=seed)
    c = Campaign(sigma=sigma, phi=phi, seed=seed, n_targets=int(rng.integers(8, 16)),
                 n_runs=int(rng.integers(3, 7)))
    if rng.random() < 0.3:
        c = replace(c, temperature=(20.0 + float(rng.uniform(-1, 1)), 20.0 + float(rng.uniform(1, 4))))
    if rng.random() < 0.2:
        c = replace(c, dense_runs=2, dense_span=(20.0, 60.0), dense_step=0.5)
    return linear_model(sigma), c


def _effect_case(name: str, size: float, seed: int, rng: np.random.Generator):
    """A recording hiding one effect whose peak contribution is ``size`` noise sigmas."""
    sigma = 0.5
    phi = 0.3
    c = Campaign(sigma=sigma, phi=phi, seed=seed)
    amp = size * sigma
    phase = float(rng.uniform(-np.pi, np.pi))
    if name == "eccentricity":
        return rotary_model(sigma), (Eccentricity(amp, phase),), rotary_campaign(sigma=sigma, phi=phi, seed=seed)
    if name == "offset":
        eff = Offset(amp)
    elif name == "backlash":
        eff = Backlash(amp)                                   # reversal = size sigma
    elif name == "scale":
        eff = Scale(amp / (TRAVEL_MM * 1e3) * 1e6)           # error at full travel = size sigma
    elif name == "periodic":
        eff = Periodic(5.0, amp, phase)
        c = replace(c, dense_runs=2, dense_span=(20.0, 60.0), dense_step=0.5)
    elif name == "thermal_drift":
        eff = ThermalDrift(amp, 500.0)
        c = replace(c, dwell_s=8.0, pause_s=60.0)
    elif name == "thermal_expansion":
        eff = ThermalExpansion(amp / (TRAVEL_MM * 1e3 * WARMUP_K) * 1e6)   # at full travel, end of warm-up
        c = replace(c, temperature=(20.0, 20.0 + WARMUP_K))
    elif name == "local_defect":
        eff = LocalDefect(float(rng.uniform(30, 90)), 4.0, amp)
        c = replace(c, n_targets=49)
    else:  # pragma: no cover
        raise ValueError(name)
    return linear_model(sigma), (eff,), c


EFFECTS = ("offset", "backlash", "scale", "periodic", "thermal_drift", "thermal_expansion",
           "eccentricity", "local_defect")


def run_bench(n_clean: int, per_effect: int, seed: int = 0, progress: Progress | None = None,
              timing_repeats: int = 3) -> dict:
    rng = np.random.default_rng(seed)
    total = n_clean + per_effect * len(EFFECTS) * len(SIZES) + timing_repeats
    task = progress.add_task("discovery bench", total=total) if progress else None

    def tick():
        if progress:
            progress.advance(task)

    false_claims, verdicts, claimed = 0, {}, {}
    for i in range(n_clean):
        model, c = _clean_case(rng, 10_000 + i)
        rep = discover(model, make_recording(model, (), c)).report
        verdicts[rep["verdict"]] = verdicts.get(rep["verdict"], 0) + 1
        if rep["effects"]:
            false_claims += 1
            for e in rep["effects"]:
                claimed[e["name"]] = claimed.get(e["name"], 0) + 1
        tick()

    power: dict[str, dict[str, float]] = {}
    inside = total_params = 0
    coverage_by: dict[str, list[int]] = {}
    for name in EFFECTS:
        power[name] = {}
        for size in SIZES:
            hits = 0
            for k in range(per_effect):
                model, hidden, c = _effect_case(name, size, 20_000 + 1000 * SIZES.index(size) + k, rng)
                rep = discover(model, make_recording(model, hidden, c)).report
                found = {e["name"]: e for e in rep["effects"]}
                if name in found:
                    hits += 1
                    if size >= 4.0:
                        truth = hidden[0]
                        for p, v in truth.parameters.items():
                            se = found[name]["stderr"].get(p)
                            if se is None:
                                continue
                            got = found[name]["parameters"][p]
                            d = got - v if p != "phase" else float(np.remainder(got - v + np.pi, 2 * np.pi) - np.pi)
                            ok = int(abs(d) <= 1.96 * se)
                            inside += ok
                            total_params += 1
                            coverage_by.setdefault(f"{name}.{p}", []).append(ok)
                tick()
            power[name][f"{size:g}"] = hits / per_effect

    # time for a 10,000-point recording: ISO cycles plus dense short-step runs
    model = linear_model(0.5)
    c = Campaign(seed=7, n_targets=21, dense_runs=4, dense_span=(0.0, 120.0), dense_step=0.098)
    rec = make_recording(model, (Backlash(2.0), Scale(20.0), Periodic(5.0, 0.5, 0.3)), c)
    times = []
    for _ in range(max(timing_repeats, 1)):
        t0 = time.perf_counter()
        discover(model, rec)
        times.append(time.perf_counter() - t0)
        tick()
    return {
        "clean_datasets": n_clean,
        "false_claim_rate": false_claims / max(n_clean, 1),
        "false_claims_by_effect": claimed,
        "clean_verdicts": verdicts,
        "per_effect_datasets": per_effect,
        "sizes_in_noise_units": list(SIZES),
        "power": power,
        "coverage_95": inside / total_params if total_params else None,
        "coverage_by_parameter": {k: float(np.mean(v)) for k, v in sorted(coverage_by.items())},
        "time_10k_points_s": float(np.median(times)),
        "time_10k_rows": len(rec),
    }


def register(bench_app: typer.Typer) -> None:
    @bench_app.command("discovery")
    def discovery_bench(
        json_out: bool = typer.Option(False, "--json", help="one JSON object on stdout"),
        clean: int = typer.Option(200, "--clean", help="clean datasets for the false-claim rate"),
        per_effect: int = typer.Option(25, "--per-effect", help="datasets per effect and size"),
        seed: int = typer.Option(0, "--seed"),
    ) -> None:
        """False-claim rate, power curve, standard-error coverage and speed of discovery."""
        # imported here: station.cli imports this module while it registers the benches
        from station.cli.common import err_console, out_console, print_json

        with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                      TimeElapsedColumn(), console=err_console, transient=True) as progress:
            res = run_bench(clean, per_effect, seed, progress)
        if json_out:
            print_json(res)
            return
        t = Table(title="discovery: power (detection rate) by effect size [noise sigmas]")
        t.add_column("effect")
        for s in SIZES:
            t.add_column(f"{s:g} sigma", justify="right")
        for name, row in res["power"].items():
            t.add_row(name, *[f"{row[f'{s:g}']:.0%}" for s in SIZES])
        out_console.print(t)
        s = Table(title="discovery: errors and speed")
        s.add_column("measure")
        s.add_column("value", justify="right")
        s.add_column("goal", justify="right")
        s.add_row(f"false-claim rate ({res['clean_datasets']} clean)", f"{res['false_claim_rate']:.1%}", "<= 5 %")
        cov = res["coverage_95"]
        s.add_row("coverage of +-1.96 se", "-" if cov is None else f"{cov:.1%}", "~95 %")
        s.add_row(f"time, {res['time_10k_rows']} points", f"{res['time_10k_points_s']:.2f} s", "<= 5 s")
        out_console.print(s)
