"""Mismatch discovery end to end: replay, noise floor, findings, selection, report.

``discover(model, recording)`` is pure (no files); ``write_outputs`` writes
``report.json``, ``model.toml`` and the plots.  The report follows the contract
``shared/spec/discovery.md`` section 4 and adds ``noise``, ``ambiguities``,
``not_analysed``, ``outliers``, ``selection`` and ``notes``.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from station.axis_model import AxisModel
from station.recording import Recording
from station.discovery.data import Prepared, prepare
from station.discovery.fit import FitResult, bic, fit_terms
from station.discovery.noise import NoiseFloor, Whitener, estimate_noise
from station.discovery.scans import PeriodicScan
from station.discovery.select import Selection, forward_select
from station.discovery.signatures import find_signatures
from station.discovery.whiteness import whiteness

#: "near the noise floor": the after-residual rms may exceed the repeatability by
#: this factor and still count as explained (the brief's acceptance bound)
NEAR_FLOOR_FACTOR = 1.3
#: re-run the selection when the noise correlation seen after the fit differs by more
PHI_TOLERANCE = 0.05


@dataclass
class Discovery:
    report: dict
    model: AxisModel              # input model plus the effects found
    prep: Prepared
    before_residual: np.ndarray
    after_residual: np.ndarray
    scan: PeriodicScan | None
    selection: Selection


def _summary(prep: Prepared, W: Whitener, r: np.ndarray, rss_w: float, k: int) -> dict:
    w = whiteness(W(r))
    return {"rms": float(np.sqrt(np.mean(r ** 2))), "bic": bic(rss_w, prep.n, k), "white": w["white"],
            "ljung_box_p": w["ljung_box_p"], "runs_p": w["runs_p"], "max_abs": float(np.max(np.abs(r)))}


def _effect_entry(fit: FitResult, i: int, step: dict | None) -> dict:
    e = fit.terms[i].effect
    return {
        "name": e.name,
        "parameters": e.parameters,
        "stderr": fit.stderr[i],
        "delta_bic": None if step is None else step["delta_bic"],
        "p_value": None if step is None else step["p_value"],
        "explanation": e.explanation,
    }


def discover(model: AxisModel, recording: Recording) -> Discovery:
    """Find what the model misses in the recording (see module and docs/discovery.md)."""
    prep = prepare(model, recording)
    if prep.n < 5:
        raise ValueError(f"{recording.source}: only {prep.n} usable rows; discovery needs at least 5")
    noise0 = estimate_noise(prep)
    W = Whitener(prep.prev, noise0.phi)
    sel = forward_select(prep, W)
    # the noise floor and its correlation, seen again once the deterministic effects are removed
    noise = estimate_noise(dataclasses.replace(prep, residual=sel.fit.residual))
    if abs(noise.phi - noise0.phi) > PHI_TOLERANCE:
        W = Whitener(prep.prev, noise.phi)
        sel = forward_select(prep, W)
        noise = estimate_noise(dataclasses.replace(prep, residual=sel.fit.residual))
    fit = sel.fit
    ctx = prep.ctx()
    eff_idx, desc_idx = sel.effect_indices, sel.descriptor_indices
    r0 = prep.residual
    rw0 = W(r0)
    before = _summary(prep, W, r0, float(rw0 @ rw0), 0)
    # "after" is the recording minus the model *with the effects claimed* (what model.toml
    # predicts); structure outside the vocabulary stays in it and is reported as findings
    r_after = r0 - sum((fit.terms[i].effect.evaluate(ctx) for i in eff_idx), np.zeros_like(r0))
    rw_after = W(r_after)
    after = _summary(prep, W, r_after, float(rw_after @ rw_after), sum(len(fit.terms[i].free) + len(fit.terms[i].scanned) for i in eff_idx))
    findings_before, scan = find_signatures(prep, r0, W)
    # the findings after: what is left beyond effects and descriptors, and each descriptor
    findings_after, _ = find_signatures(prep, fit.residual, W) if fit.terms else (findings_before, scan)
    for f in findings_before:
        f["stage"] = "before"
    for f in findings_after:
        f["stage"] = "after"
    accepted = {d["name"]: d for d in sel.descriptors}
    described = [_descriptor_finding(prep, fit.terms[i].effect, accepted[fit.terms[i].effect.name])
                 for i in desc_idx]
    findings_after = described + findings_after
    steps = {s["name"]: s for s in sel.steps}
    effects = [_effect_entry(fit, i, steps.get(fit.terms[i].effect.name)) for i in eff_idx]
    near_floor = after["rms"] <= NEAR_FLOOR_FACTOR * noise.sigma
    if not effects and not described and not findings_before and before["white"]:
        verdict = "no-mismatch"
    elif effects and not described and after["white"] and near_floor and not findings_after:
        verdict = "explained"
    else:
        verdict = "partly-explained"
    if verdict == "partly-explained":
        fitted = bool(effects or described)
        findings = findings_before + findings_after if fitted else findings_before
        remaining = findings_after if fitted else findings_before
        if not remaining:
            # structure remains but no single signature is significant: say so plainly
            why = []
            if not after["white"]:
                why.append(f"the residual is not white (Ljung-Box p = {after['ljung_box_p']:.2g}, "
                           f"runs p = {after['runs_p']:.2g})")
            if not near_floor:
                why.append(f"its rms {after['rms']:.3g} exceeds {NEAR_FLOOR_FACTOR} x the noise floor "
                           f"{noise.sigma:.3g}")
            findings.append({"signature": "time", "stage": "after",
                             "range": [float(prep.x.min()), float(prep.x.max())], "direction": "both",
                             "description": "unexplained structure: " + "; ".join(why or ["see plots"])})
    else:
        findings = findings_before + (findings_after if effects or described else [])
    ambiguities = list(sel.ambiguities)
    names = {e["name"] for e in effects}
    temp_ok = prep.temperature_c is not None and np.ptp(prep.temperature_c) >= 0.1
    if "scale" in names and not temp_ok:
        ambiguities.append({
            "effects": ["scale", "thermal_expansion"],
            "description": "at constant (or unknown) temperature a scale error and thermal expansion "
                           "give the same error proportional to position; reported as scale",
            "separate_by": "temperature logging during a warm-up, or a campaign at another temperature",
        })
    if "backlash" in names and prep.time_s is None:
        ambiguities.append({
            "effects": ["backlash", "thermal_drift"],
            "description": "without trustworthy time stamps a drift that coincides with the direction "
                           "changes cannot be excluded",
            "separate_by": "a recording with time stamps, and a run in reversed order (approach -1 first)",
        })
    report = {
        "verdict": verdict,
        "noise_floor": noise.sigma,
        "before": before,
        "after": after,
        "findings": findings,
        "effects": effects,
        "ambiguities": ambiguities,
        "not_analysed": prep.not_analysed,
        "outliers": prep.outliers,
        "noise": noise.to_dict(),
        "selection": {
            "steps": sel.steps,
            "descriptors": sel.descriptors,
            "trials": [[t.to_dict() for t in step] for step in sel.trials],
            "notes": sel.notes,
        },
        "axis": {"name": model.name, "kind": model.kind},
        "recording": {"source": recording.source, "rows": len(recording), "rows_used": prep.n,
                      "runs": int(np.unique(prep.run).size)},
    }
    if verdict == "no-mismatch":
        report["effects"] = []
    claimed = [fit.terms[i].effect for i in eff_idx]
    new_model = model.with_effects(*claimed) if verdict != "no-mismatch" else model
    return Discovery(report, new_model, prep, r0, r_after, scan, sel)


def _descriptor_finding(prep: Prepared, d, step: dict) -> dict:
    """A descriptor as the report's finding: located, described, never an effect."""
    unit = ("um", "mm") if prep.kind == "linear" else ("arcsec", "deg")
    return {"signature": d.signature, "stage": "after", **d.finding(prep, unit),
            "outside_vocabulary": True, "descriptor": d.name, "p_value": step["p_value"],
            "delta_bic": step["delta_bic"]}


def write_outputs(d: Discovery, out_dir: str | Path, plots: bool = True) -> list[Path]:
    """Write report.json, model.toml and (optionally) the PNG plots into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / "report.json", out / "model.toml"]
    paths[0].write_text(json.dumps(d.report, indent=2, allow_nan=False, default=_json_default) + "\n")
    d.model.to_toml(paths[1])
    if plots:
        from station.discovery.plots import write_plots
        paths += write_plots(d, out)
    return paths


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")
