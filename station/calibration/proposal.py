"""A self-calibration's result as a model proposal (issue 21, stage 3; docs/calibration.md).

The proposal changes **only the parameters the run observed** (the observability
report's estimable ones) **and contradicts**: each whose identified value differs from
the station's present one by more than ``MIN_SIGNIFICANCE`` (2) u changes by that
difference, with the identification's standard uncertainty; an observable parameter
within 2 u of the present value is confirmed and kept (the present value came from a
laser campaign, often far more precise than what the camera sees through a short arm);
every other parameter keeps the station's current value (the named unobservable
combinations cannot be told apart by this artefact and plan, so nothing is claimed
about them). It goes through the same
approval flow as the master checks' proposals (``station model proposals``,
``/api/v1/model-proposals``, the store's audit log).

Two kinds of change:

* a static error (``installation.<body>.<key>``), as the master checks propose; the
  artefact's own seat on the table (body M) is a nuisance of the run, never proposed;
* an error-motion curve at one node of the identification
  (``node.<body>.<motion>(at=..,lo=..,hi=..)``): the node's hat function of the
  parameterisation (1 at ``at``, 0 at its neighbours ``lo`` and ``hi``; without ``hi``
  it is held at 1 beyond ``at``, as the last node's basis is) times the delta, added to
  the curve's baseline table. The identification's gauge (a curve is zero at its first
  node) is kept: the hat is zero there, so the curve's constant part stays in the
  static errors where it was.

The proposal's picture: each curve with an observed node, the present model's and the
proposed model's, the identified node values with their 2u bars
(:func:`write_calibration_plot`, under the shared plot lock).
"""

from __future__ import annotations

import asyncio
import math
import re
import uuid
from dataclasses import fields, replace
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from station.effects import ErrorCurve
from station.kinematics.model import StationModel
from station.kinematics.parameters import COMPONENTS, SixDof, motion_names
from station.monitor.proposals import Change, Proposal, ProposalError, motion_component

NODE_PREFIX = "node."
#: the artefact's installation on the table: the run's nuisance, not the station's
ARTEFACT_SEAT_BODY = "M"
#: points per curve in the picture
CURVE_SAMPLES = 121

_NODE_TERM = re.compile(r"^node\.(?P<body>[A-Za-z0-9_]+)\.(?P<motion>E[XYZABC][A-Za-z0-9_]+)"
                        r"\((?P<args>[^()]*)\)$")


def node_term(body: str, motion: str, at: float, lo: float, hi: float | None) -> str:
    args = f"at={float(at)!r},lo={float(lo)!r}" + ("" if hi is None else f",hi={float(hi)!r}")
    return f"{NODE_PREFIX}{body}.{motion}({args})"


def parse_node_term(term: str) -> tuple[str, str, float, float, float | None]:
    mt = _NODE_TERM.match(term)
    if mt is None:
        raise ProposalError(f"cannot change {term}: a node term is node.<body>.<error motion>(at=..,lo=..[,hi=..])")
    args: dict[str, float] = {}
    for part in filter(None, mt["args"].split(",")):
        k, eq, v = part.partition("=")
        try:
            args[k.strip()] = float(v)
        except ValueError:
            raise ProposalError(f"cannot change {term}: {part!r} is not key=number") from None
        if not eq or not math.isfinite(args[k.strip()]):
            raise ProposalError(f"cannot change {term}: {part!r} is not key=number")
    if set(args) - {"at", "lo", "hi"} or not {"at", "lo"} <= set(args):
        raise ProposalError(f"cannot change {term}: needs at= and lo= (and hi=, except at a linear axis's last node)")
    if not args["lo"] < args["at"] < args.get("hi", math.inf):
        raise ProposalError(f"cannot change {term}: lo < at < hi is required")
    return mt["body"], mt["motion"], args["at"], args["lo"], args.get("hi")


def _hat(kind: str, at: float, lo: float, hi: float | None) -> ErrorCurve:
    if hi is None:
        return ErrorCurve.table((lo, at), (0.0, 1.0), kind)
    return ErrorCurve.table((lo, at, hi), (0.0, 1.0, 0.0), kind)


def apply_node_change(model: StationModel, change: Change) -> StationModel:
    """A new model with the node change added to the curve's baseline table (exactly:
    the merged table has every breakpoint of both, and both are linear between them)."""
    body, motion, at, lo, hi = parse_node_term(change.term)
    delta = float(change.delta)
    if not math.isfinite(delta):
        raise ProposalError(f"cannot change {change.term}: the delta {change.delta!r} is not a number")
    comp = motion_component(model, change.term, body, motion)
    motions = model.motions_of(body)
    curve = getattr(motions, comp)
    hat = _hat(curve.kind, at, lo, hi)
    old_t = np.asarray(curve.target, dtype=float)
    new_pts = np.array([lo, at] + ([] if hi is None else [hi]))
    if curve.kind == "rotary":
        if old_t.size > 1 and old_t[-1] - old_t[0] >= 359.999:
            old_t = old_t[:-1]  # a closed turn: its last point is its first
        t = np.unique(np.round(np.mod(np.concatenate([old_t, new_pts]), 360.0), 9))
    else:
        t = np.unique(np.concatenate([old_t, new_pts]))
    dev = curve.baseline(t) + delta * hat.baseline(t)
    new_curve = ErrorCurve.table(t, dev, curve.kind, curve.effects)
    return replace(model, motions={**model.motions, body: replace(motions, **{comp: new_curve})})


def _node_neighbours(nodes: tuple[float, ...], k: int, kind: str) -> tuple[float, float | None]:
    lo = nodes[k - 1]
    if k + 1 < len(nodes):
        return lo, nodes[k + 1]
    return lo, (nodes[0] + 360.0 if kind == "rotary" else None)


#: an observable parameter is changed only when the calibration contradicts the present
#: model: identified minus present beyond this many u (k = 2, the coverage factor of an
#: expanded uncertainty). A parameter seen only weakly (EAC through the 11.1 mm arm: u of
#: tens of arcsec, where the laser campaign behind the model had 1) would otherwise be
#: replaced by a value far less certain than the one the station has
MIN_SIGNIFICANCE = 2.0


def significant(par, result, prior: StationModel, min_significance: float = MIN_SIGNIFICANCE) -> np.ndarray:
    """(n_model,) bool: observable, and identified minus the present value beyond
    ``min_significance`` u."""
    before = par.values_from_model(prior)
    obs = np.asarray(result.observable[:par.size], dtype=bool)
    u = np.where(obs, np.asarray(result.u[:par.size], dtype=float), np.inf)
    with np.errstate(invalid="ignore"):
        return obs & (np.abs(np.asarray(result.value[:par.size]) - before) > min_significance * u)


def calibration_changes(par, result, prior: StationModel, min_significance: float = MIN_SIGNIFICANCE) -> list[Change]:
    """The changes of the observable model parameters the calibration contradicts
    (identified minus the station's present value, beyond ``min_significance`` u), each
    with its u; the rest are left as they are: the unobservable ones (nothing is known
    of them), the confirmed ones (the present value is within the calibration's
    expanded uncertainty, and was measured at least as well)."""
    before = par.values_from_model(prior)
    keys = [f.name for f in fields(SixDof)]
    change = significant(par, result, prior, min_significance)
    out: list[Change] = []
    for j, slot in enumerate(par.slots):
        if not change[j]:
            continue
        name, unit, u = par.names[j], par.units[j], float(result.u[j])
        value = float(result.value[j])
        delta = value - float(before[j])
        if slot[0] == "static":
            if slot[1] == ARTEFACT_SEAT_BODY:
                continue
            term = f"installation.{slot[1]}.{keys[slot[2]]}"
        else:
            body, k = slot[1], slot[3]
            nodes, _ = par.nodes_of(body)
            lo, hi = _node_neighbours(nodes, k, par.kind_of(body))
            term = node_term(body, motion_names(body)[slot[2]], nodes[k], lo, hi)
        out.append(Change(term, delta, why=(
            f"self-calibration on the artefact: {name} identified {value:+.3g} +/- {u:.2g} {unit} (u, k = 1), "
            f"the present model's {float(before[j]):+.3g} {unit}: changes by {delta:+.3g} {unit}"), u=u))
    return out


def _curve_pictures(par, result, prior: StationModel, after: StationModel,
                    min_significance: float = MIN_SIGNIFICANCE) -> list[dict]:
    """Per curve with an observed node: the present and proposed curves (sampled, in the
    identification's gauge: zero at the first node) and the identified nodes."""
    before_v = par.values_from_model(prior)
    changed = significant(par, result, prior, min_significance)
    out = []
    for body in par.base.joint_bodies:
        nodes, unit = par.nodes_of(body)
        kind = par.kind_of(body)
        x = (np.linspace(0.0, 360.0, CURVE_SAMPLES) if kind == "rotary"
             else np.linspace(nodes[0], nodes[-1], CURVE_SAMPLES))
        for i, motion in enumerate(motion_names(body)):
            idx = [j for j, s in enumerate(par.slots) if s[0] == "motion" and s[1] == body and s[2] == i]
            if not any(result.observable[j] for j in idx):
                continue
            comp = COMPONENTS[i]
            curves = {}
            for tag, m in (("before", prior), ("after", after)):
                cv = getattr(m.motions_of(body), comp)
                curves[tag] = (cv.evaluate(x) - cv.evaluate(np.array([nodes[0]]))[0]).tolist()
            out.append({
                "name": motion, "body": body, "unit": par.units[idx[0]], "axis_unit": unit,
                "x": x.tolist(), **curves,
                "nodes": [float(nodes[par.slots[j][3]]) for j in idx],
                "before_nodes": [float(before_v[j]) for j in idx],
                "value": [float(result.value[j]) for j in idx],
                "u": [float(result.u[j]) if result.observable[j] else None for j in idx],
                "observable": [bool(result.observable[j]) for j in idx],
                "changed": [bool(changed[j]) for j in idx]})
    return out


def calibration_proposal(outcome, base_version: str, reason: str | None = None,
                         artefact_id: str = "", min_significance: float = MIN_SIGNIFICANCE) -> Proposal:
    """The proposal from a ``station.calibration.run.CalibrationOutcome``: the changes of
    the observable parameters the calibration contradicts, the confirmed and the
    unobservable ones named in its explanation, and the picture's data
    (``explanation.curves``). ProposalError when nothing is observable, or nothing
    observed contradicts the present model."""
    par, res = outcome.par, outcome.result
    prior = par.base
    changes = calibration_changes(par, res, prior, min_significance)
    n_seen = int(np.count_nonzero(res.observable[: par.size]))
    if not n_seen:
        raise ProposalError("the calibration observed no parameter of the station's model: nothing to propose")
    if not changes:
        raise ProposalError(f"the calibration confirms the station's model: each of the {n_seen} observable "
                            f"parameters is within {min_significance:g} u of its present value; nothing to propose")
    seat = [s[0] == "static" and s[1] == ARTEFACT_SEAT_BODY for s in par.slots]
    confirmed = [n for n, o, c, m in zip(par.names, res.observable[:par.size],
                                         significant(par, res, prior, min_significance), seat) if o and not c and not m]
    after = prior
    for c in changes:
        after = c.apply(after)
    unobs = [c["name"] for c in outcome.report.to_dict()["unobservable"]]
    n_kept = int(par.size - np.count_nonzero(res.observable[: par.size]))
    description = (
        f"self-calibration on artefact {artefact_id or '?'}: {len(changes)} observable parameter(s) of the error "
        f"model take their identified values, each differing from the present one by more than "
        f"{min_significance:g} u (rank {res.rank}, residual rms {res.residual_rms_um:.2f} um, "
        f"chi2/dof {res.chi2_per_dof:.2f}). {len(confirmed)} observable parameter(s) are within "
        f"{min_significance:g} u of the present model, which they keep (confirmed). The {n_kept} parameters "
        f"this artefact and plan cannot see keep the "
        f"station's current values: nothing is claimed about them"
        + (f" (unobservable combinations: {'; '.join(unobs[:8])}{' ...' if len(unobs) > 8 else ''})" if unobs else "")
        + ". The artefact's seat on the table (installation of M) is the run's nuisance and is not proposed.")
    explanation = {
        "kind": "calibration",
        "description": description,
        "artefact": artefact_id,
        "rank": int(res.rank), "n_parameters": len(res.names),
        "residual_rms_um": float(res.residual_rms_um), "chi2_per_dof": float(res.chi2_per_dof),
        "unobservable": unobs,
        "unchanged_parameters": [n for j, n in enumerate(par.names) if not res.observable[j]],
        "confirmed_parameters": confirmed,
        "min_significance": float(min_significance),
        "curves": _curve_pictures(par, res, prior, after, min_significance),
    }
    return Proposal(uuid.uuid4().hex[:12], datetime.now(timezone.utc).isoformat(), base_version,
                    reason or f"self-calibration on artefact {artefact_id}", changes, {}, {},
                    explanation=explanation)


def expected_readings_change_um(model: StationModel, changes, holes: dict[str, tuple[float, float]]) -> dict[str, float]:
    """Per hole (``holes``: id -> (axial place mm, table angle deg)): how much approving
    ``changes`` on ``model`` moves the hole's measured place (um), if the machine is as
    the changed model says (``station.checks.axis.expected_change_um``)."""
    from station.checks.axis import expected_change_um
    from station.monitor.proposals import apply_changes

    new = apply_changes(model, changes)
    return expected_change_um(model, new, {h: mm for h, (mm, _) in holes.items()},
                              {h: a for h, (_, a) in holes.items()})


async def propose_from_calibration(session, outcome, artefact_id: str,
                                   min_significance: float = MIN_SIGNIFICANCE,
                                   holes: dict[str, tuple[float, float]] | None = None) -> Proposal:
    """Build the proposal on the session's present model, keep it in the session's
    proposal book (its picture written) and log it (the audit trail). Its
    ``expected_change_um`` is given at ``holes`` (id -> (axial place mm, table angle
    deg)), by default at the master's holes of the session's last master check (none
    without one)."""
    p = calibration_proposal(outcome, session.model_version, artefact_id=artefact_id,
                             min_significance=min_significance)
    if holes is None and session.history:
        # the master's holes, as its last check read them: approving moves its history
        # into the new model's frame by these figures (Session.decide)
        last = session.history[-1]
        holes = {h: (mm, last.angle_deg.get(h, 0.0)) for h, mm in last.position_mm.items()}
    if holes:
        p.expected_change_um = await asyncio.to_thread(
            expected_readings_change_um, session.station.model, p.changes, holes)
    await asyncio.to_thread(session.proposals.add, p)
    await asyncio.to_thread(session.store.log_event, "proposal",
                            f"model proposal {p.id} on {p.base_version}: self-calibration on artefact {artefact_id}, "
                            f"{len(p.changes)} observable parameter(s) changed, the rest kept")
    return p


# ---------------------------------------------------------------------- picture
def write_calibration_plot(p: Proposal, path: Path) -> Path | None:
    curves = (p.explanation or {}).get("curves") or []
    if not curves:
        return None
    from station.discovery.plots import PLOT_LOCK

    with PLOT_LOCK:
        return _draw(p, curves, path)


def _draw(p: Proposal, curves: list[dict], path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(curves)
    cols = min(3, n)
    rows = (n + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.2 * rows), squeeze=False)
    for ax, c in zip(axes.flat, curves):
        ax.plot(c["x"], c["before"], color="0.5", lw=1.2, label="present model")
        ax.plot(c["x"], c["after"], color="C0", lw=1.2, label="proposed")
        obs = np.array(c["observable"], dtype=bool)
        nodes = np.array(c["nodes"])
        val = np.array(c["value"])
        u = np.array([np.nan if v is None else v for v in c["u"]], dtype=float)
        changed = np.array(c.get("changed", c["observable"]), dtype=bool)
        ax.errorbar(nodes[changed], val[changed], yerr=2.0 * u[changed], fmt="o", color="C3", ms=4, capsize=2,
                    label="identified (2u): changed")
        kept = obs & ~changed
        if kept.any():
            ax.errorbar(nodes[kept], val[kept], yerr=2.0 * u[kept], fmt="o", mfc="none", color="C2", ms=4,
                        capsize=2, label="identified (2u): confirms the model, kept")
        if (~obs).any():
            ax.plot(nodes[~obs], np.array(c["before_nodes"])[~obs], "x", color="0.3", label="not observable: kept")
        ax.axhline(0.0, color="k", lw=0.4)
        ax.set_title(f"{c['name']} ({c['body']} axis)", fontsize=9)
        ax.set_xlabel(f"{c['body']} [{c['axis_unit']}]")
        ax.set_ylabel(f"[{c['unit']}], zero at the first node")
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    axes.flat[0].legend(loc="best", fontsize=7)
    fig.suptitle(f"proposal {p.id}: self-calibration\n{len(p.changes)} observable parameter(s) changed, the rest kept",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path
