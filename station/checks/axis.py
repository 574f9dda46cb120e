"""The station's own short ISO 230-2 check of Z against its grating, and discovery on it.

Every inspection compares the grating's reading with the carriage position the
station's model predicts for the command (``station.inspection.scan.predicted_carriage_mm``)
at the one or two places and the one direction the holes need; the grating chart
(``station.monitor.watch``) asks for a check when the two depart. This check asks the
same question all over the stroke the bore scans use, in both directions, repeatedly,
as ISO 230-2 asks of a positioning test, with the grating as the instrument:

* targets: ``targets`` (11) spread over ``lo_mm .. hi_mm``: by default from the
  overrun above the bottom of Z's travel (so the lower overrun ends at the travel's
  start, the axis' home) to the part family's deepest search zone plus ``margin_mm``;
  ISO 230-2's irregular spacing (each interior target moved by a fixed pseudo-random
  part of the interval, the same every check) so a periodic error of the screw is not
  sampled at one phase;
* ``runs`` (3) bidirectional runs: up through every target, ``overrun_mm`` past the
  last, down through every target, ``overrun_mm`` below the first (ISO 230-2's
  standard test cycle: every reversal made beyond the targets, so each target is
  reached moving in its run's direction); C is not moved (its angle is read and
  recorded);
* at each target: ``settle_s`` still, then ``readings`` grating readings, averaged.

Each point records the command, the model's carriage prediction for it in its
approach direction, the grating's mean reading, ``deviation_um`` = grating minus
prediction, the direction, the run and ``time_s``: the drives' clock since the
check's first reading (the host's ``time.monotonic`` of each reading times the
config's time scale: on hardware, time scale 1, the host's clock is the machine's; in
simulation the drives' clock, on which the world's drift runs).

Files (``shared/spec/discovery.md``, kept exactly): ``recording.csv`` (section 1):
``deviation`` is the grating's reading minus the command, um, as a laser recording's
is actual minus commanded; extra columns ``model`` (the station's EZZ there, um: the
prediction minus the command) and ``grating_mm``. ``axis_model.toml`` (section 2): the
station's own EZZ of Z (baseline and effects, as its model holds them) with
``noise.sigma`` the Z repeatability the station states. Discovery's residual, the
recording minus that model, is then exactly grating minus prediction, the check's
``deviation_um``. ``station discover --model axis_model.toml --recording
recording.csv`` repeats the analysis; ``report.json`` and ``model.toml`` (the
station's EZZ plus what was found) are its outputs.

A model change from the report: each effect discovery is confident in becomes a
change of the error motion EZZ of the Z joint, term ``motion.Z.EZZ.<effect>`` (with
its shape parameters in brackets where it has any: ``motion.Z.EZZ.periodic(period=5.0,
phase=0.3)``) and its size parameter as the delta (``backlash``: the reversal, um;
``scale``: ppm; ``offset``: um; ``amplitude`` or ``height`` of the others). Effects of
time, temperature or a recorded channel are not proposed: the station evaluates its
model for a command without them, so they would change nothing it does. The grating
corrects Z's positioning in inspections, so such a change leaves the holes' readings
where they were (``expected_change_um`` ~ 0, computed with the model); it moves the
grating chart's residual and the compensation's commands (docs/monitor.md, The
station's own check of Z).
"""

from __future__ import annotations

import asyncio
import json
import math
import re
import uuid
from dataclasses import dataclass, field, replace
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from station.axis_model import AxisModel, read_axis_model
from station.effects import VOCABULARY, EffectSpecError, effect_from_dict
from station.kinematics.inverse import compensate
from station.kinematics.model import StationModel
from station.monitor.proposals import Change, Proposal, ProposalError, motion_component
from station.motion import AxisLimits
from station.recording import Recording, read_recording
from station.inspection.scan import predicted_carriage_mm
from station.sequencer import messages as m

#: the Z joint's body in the topology, and its positioning error motion
Z_BODY = "Z"
EZZ = "EZZ"
MOTION_PREFIX = "motion."
#: which parameter of an effect is its size (the change's delta); effects not named
#: here use ``amplitude`` when they have one, else they are not proposed
SIZE_PARAMETER = {"offset": "value", "scale": "ppm", "backlash": "reversal", "step": "height"}
#: an effect that needs more than the approach direction (time, temperature, an angle
#: channel) is evaluated as zero by the station for a command: not a model change
EVALUATED_FOR_A_COMMAND = {"direction"}


@dataclass(frozen=True)
class AxisCheckSettings:
    """How the check runs (module docstring). ``lo_mm``/``hi_mm`` None: from the
    model's travel and the part family (:func:`check_stroke`)."""

    targets: int = 11
    runs: int = 3
    lo_mm: float | None = None
    hi_mm: float | None = None
    #: beyond the end targets before each reversal (mm): several times any lost
    #: motion of a ball screw, and twice the scans' approach distance
    overrun_mm: float = 1.0
    #: the deepest hole's search zone plus this (mm): the scans' frames reach past it
    margin_mm: float = 5.0
    #: still at each target before reading (s): the scans' own settle is 0.05 s; a
    #: check that names the machine's physics waits four times as long
    settle_s: float = 0.2
    #: grating readings averaged at each target
    readings: int = 5
    #: ISO 230-2's irregular spacing (a pseudo-random part of each interval, fixed seed)
    irregular: bool = True
    seed: int = 2302

    def __post_init__(self):
        if self.targets < 3:
            raise ValueError(f"an axis check needs at least 3 targets, not {self.targets}")
        if self.runs < 1:
            raise ValueError(f"an axis check needs at least 1 run, not {self.runs}")
        if self.readings < 1:
            raise ValueError(f"at least one grating reading per target, not {self.readings}")
        if not self.overrun_mm > 0 or not self.settle_s >= 0 or not self.margin_mm >= 0:
            raise ValueError("overrun must be positive, settle and margin not negative")


def check_stroke(model: StationModel, family=None,
                 settings: AxisCheckSettings = AxisCheckSettings()) -> tuple[float, float]:
    """The span the targets cover (mm): ``settings``' own, else from the overrun above
    the start of Z's travel to the family's deepest search zone (its holes' upper
    position limits plus the part's axial placement) plus the margin, rounded up to a
    whole mm; without a family, the whole travel less the overrun."""
    travel_lo, travel_hi = model.z_travel_mm
    lo = settings.lo_mm if settings.lo_mm is not None else travel_lo + settings.overrun_mm
    if settings.hi_mm is not None:
        hi = settings.hi_mm
    elif family is not None and family.holes:
        deepest = max(h.position.upper_limit for h in family.holes) + family.placement.axial_mm
        hi = float(math.ceil(deepest + settings.margin_mm))
    else:
        hi = travel_hi - settings.overrun_mm
    hi = min(hi, travel_hi - settings.overrun_mm)
    if not hi > lo:
        raise ValueError(f"the check's span {lo:g}..{hi:g} mm is empty (Z travels {travel_lo:g}..{travel_hi:g} mm)")
    return float(lo), float(hi)


def check_targets(lo_mm: float, hi_mm: float, settings: AxisCheckSettings = AxisCheckSettings()) -> list[float]:
    """The targets, ascending: ``settings.targets`` over ``lo .. hi`` at a mean
    interval p; with ``irregular`` every interior one moved by up to p/5 either way
    (a fixed draw: every check uses the same targets), to the micrometre."""
    n = settings.targets
    t = np.linspace(lo_mm, hi_mm, n)
    if settings.irregular and n > 2:
        p = (hi_mm - lo_mm) / (n - 1)
        r = np.random.default_rng(settings.seed).uniform(-0.2, 0.2, n - 2) * p
        t[1:-1] += r
    return [round(float(v), 3) for v in t]


@dataclass
class AxisPoint:
    """One target of one run: the command, what the model predicts of the carriage
    for it (approached in ``direction``), what the grating read (mean of its readings)."""

    run: int
    direction: int
    target_mm: float
    predicted_mm: float
    grating_mm: float
    grating_sd_um: float
    time_s: float
    c_deg: float | None

    @property
    def deviation_um(self) -> float:
        """The grating minus the model's carriage prediction: what the model did not know."""
        return (self.grating_mm - self.predicted_mm) * 1e3

    @property
    def error_um(self) -> float:
        """The grating minus the command: Z's positioning error as the grating sees it."""
        return (self.grating_mm - self.target_mm) * 1e3

    @property
    def model_um(self) -> float:
        """The model's EZZ for the command and direction (um)."""
        return (self.predicted_mm - self.target_mm) * 1e3

    def to_json(self) -> dict:
        return {"run": self.run, "direction": self.direction, "target_mm": self.target_mm,
                "predicted_mm": self.predicted_mm, "grating_mm": self.grating_mm,
                "deviation_um": self.deviation_um, "grating_sd_um": self.grating_sd_um,
                "time_s": self.time_s, "c_deg": self.c_deg}


@dataclass
class AxisCheckData:
    """The plan's return value: every point, in the order taken."""

    targets_mm: list[float]
    points: list[AxisPoint] = field(default_factory=list)
    c_deg: float | None = None

    def mean_deviations_um(self) -> dict[tuple[float, int], float]:
        """Per (target, direction): the mean over runs of grating minus prediction (um)."""
        out: dict[tuple[float, int], list[float]] = {}
        for p in self.points:
            out.setdefault((p.target_mm, p.direction), []).append(p.deviation_um)
        return {k: float(np.mean(v)) for k, v in sorted(out.items())}


def axis_check_plan(model: StationModel, targets_mm: list[float], settings: AxisCheckSettings = AxisCheckSettings(),
                    motion: Mapping[str, AxisLimits] | None = None, time_scale: float | None = None):
    """The check as a plan (a generator of ``station.sequencer.messages``; returns an
    :class:`AxisCheckData`). Z moves at its limits (``motion``) when known; C is not moved."""
    targets = sorted(float(t) for t in targets_mm)
    lim = (motion or {}).get("Z")
    kw = {} if lim is None else {"velocity": lim.velocity, "acceleration": lim.acceleration}
    scale = float(time_scale or 1.0)
    data = AxisCheckData(targets)
    c = yield m.ReadAxis("C")
    data.c_deg = float(c) if isinstance(c, (int, float)) and math.isfinite(c) else None
    below, above = targets[0] - settings.overrun_mm, targets[-1] + settings.overrun_mm
    total = 2 * settings.runs * len(targets)
    t0: list[float] = []
    yield m.Note(f"axis check of Z: {len(targets)} targets {targets[0]:g}..{targets[-1]:g} mm, {settings.runs} "
                 f"bidirectional run(s), overrun {settings.overrun_mm:g} mm, {settings.readings} grating readings "
                 f"per target; C held at {data.c_deg if data.c_deg is not None else '?'} deg")
    # every run starts below the first target: the first one reached moving up
    yield m.Move("Z", below, **kw)
    for run in range(1, settings.runs + 1):
        for direction, order, past in ((+1, targets, above), (-1, targets[::-1], below)):
            for t in order:
                yield m.Move("Z", t, **kw)
                if settings.settle_s > 0:
                    yield m.Settle(settings.settle_s)
                readings = []
                for _ in range(settings.readings):
                    r = yield m.ReadEncoder()
                    # a reading the head flags (signal low, overspeed, hardware) is not a reading
                    if r is not None and getattr(r.status, "ok", True):
                        readings.append((float(r.position_mm), float(r.timestamp)))
                if not readings:
                    yield m.Note(f"axis check: no good grating reading at Z {t:g} mm (run {run}); point left out")
                    continue
                pos = np.array([v for v, _ in readings])
                if not t0:
                    t0.append(readings[0][1])
                data.points.append(AxisPoint(
                    run, direction, t, predicted_carriage_mm(model, t, direction), float(pos.mean()),
                    float(pos.std(ddof=1) * 1e3) if pos.size > 1 else 0.0,
                    (readings[0][1] - t0[0]) * scale, data.c_deg))
                yield m.Progress(len(data.points), total, f"run {run} {'up' if direction > 0 else 'down'} {t:g} mm")
                yield m.Checkpoint(f"axis check run {run} {t:g} mm")
            # the reversal beyond the targets (ISO 230-2); the last run ends at its last target
            if not (run == settings.runs and direction < 0):
                yield m.Move("Z", past, **kw)
    return data


# ---------------------------------------------------------------------------------
# The files of the contract, and discovery on them


def recording_of(data: AxisCheckData, started_utc: str | None = None) -> Recording:
    """The check as a recording (contract section 1): ``deviation`` the grating minus
    the command (um); extra ``model`` (the station's EZZ there, um) and ``grating_mm``."""
    pts = data.points
    if not pts:
        raise ValueError("the axis check has no points")
    meta = {"axis": "Z", "kind": "linear", "instrument": "station grating (axis check, ISO 230-2 style)",
            "date": (started_utc or datetime.now(timezone.utc).isoformat(timespec="seconds")),
            "clock": "time_s is the drives' clock since the first reading (the host's times the time scale)",
            "runs": str(max(p.run for p in pts)), "targets": str(len(data.targets_mm))}
    if data.c_deg is not None:
        meta["c_deg"] = f"{data.c_deg:.4f}"
    return Recording(
        time_s=np.array([p.time_s for p in pts]), run=np.array([p.run for p in pts], dtype=int),
        direction=np.array([p.direction for p in pts], dtype=int), target=np.array([p.target_mm for p in pts]),
        # to the picometre: the float noise of a difference of millimetres is not data
        deviation=np.round([p.error_um for p in pts], 6), metadata=meta,
        extra={"model": [repr(round(p.model_um, 6)) for p in pts], "grating_mm": [repr(p.grating_mm) for p in pts]},
        source="station axis check")


def axis_model_of(model: StationModel, repeatability_um: float) -> AxisModel:
    """The station's belief of Z's positioning (contract section 2): its EZZ as held,
    the noise the Z repeatability it states."""
    return AxisModel(name="Z", kind="linear", curve=model.motions_of(Z_BODY).z, noise_sigma=float(repeatability_um),
                     extra={"axis": {"source": f"station model {model.name}: error motion EZZ of the Z joint"}})


def run_discovery(data: AxisCheckData, model: StationModel, repeatability_um: float, out_dir: str | Path,
                  plots: bool = True):
    """Write the recording and the axis model into ``out_dir``, run the station's
    discovery on those files and write its outputs beside them. Returns (Discovery,
    the paths written)."""
    from station.discovery import discover, write_outputs

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rec_path, model_path = out / "recording.csv", out / "axis_model.toml"
    recording_of(data).to_csv(rec_path)
    axis_model_of(model, repeatability_um).to_toml(model_path)
    d = discover(read_axis_model(model_path), read_recording(rec_path))
    paths = [rec_path, model_path] + write_outputs(d, out, plots=plots)
    return d, paths


# ---------------------------------------------------------------------------------
# From the report to the station's model


def size_parameter(name: str) -> str | None:
    """The parameter that is an effect's size (the change's delta), or None when the
    effect cannot be a change of the station's model (module docstring)."""
    cls = VOCABULARY.get(name)
    if cls is None or not set(cls.needs) <= EVALUATED_FOR_A_COMMAND:
        return None
    params = {f for f in cls.__dataclass_fields__}
    if name in SIZE_PARAMETER:
        return SIZE_PARAMETER[name] if SIZE_PARAMETER[name] in params else None
    return "amplitude" if "amplitude" in params else None


def motion_term(effect: str, shape: Mapping[str, float] | None = None, body: str = Z_BODY, motion: str = EZZ) -> str:
    """``motion.<body>.<error motion>.<effect>`` with its shape parameters, if any, in brackets."""
    s = ",".join(f"{k}={float(v)!r}" for k, v in sorted((shape or {}).items()))
    return f"{MOTION_PREFIX}{body}.{motion}.{effect}" + (f"({s})" if s else "")


_TERM = re.compile(r"^motion\.(?P<body>[A-Za-z0-9_]+)\.(?P<motion>E[XYZABC][A-Za-z0-9_]+)\.(?P<effect>[a-z_]+)"
                   r"(?:\((?P<shape>[^()]*)\))?$")


def parse_motion_term(term: str) -> tuple[str, str, str, dict[str, float]]:
    """(body, error motion, effect, shape) of a ``motion.`` term; ProposalError when malformed."""
    mt = _TERM.match(term)
    if mt is None:
        raise ProposalError(f"cannot change {term}: a motion term is motion.<body>.<error motion>.<effect>[(k=v,...)]")
    shape: dict[str, float] = {}
    for part in filter(None, (mt["shape"] or "").split(",")):
        k, eq, v = part.partition("=")
        try:
            shape[k.strip()] = float(v)
        except ValueError:
            raise ProposalError(f"cannot change {term}: {part!r} is not key=number") from None
        if not eq or not math.isfinite(shape[k.strip()]):
            raise ProposalError(f"cannot change {term}: {part!r} is not key=number")
    return mt["body"], mt["motion"], mt["effect"], shape


def apply_motion_change(model: StationModel, change: Change) -> StationModel:
    """A new model with ``change`` (term ``motion.<body>.<EXX>.<effect>[(shape)]``)
    applied to the error motion's curve: the delta added to the size of its effect of
    that name and shape, or that effect added with the delta as its size."""
    body, motion, effect, shape = parse_motion_term(change.term)
    comp = motion_component(model, change.term, body, motion)
    size = size_parameter(effect)
    if size is None:
        known = ", ".join(sorted(k for k in VOCABULARY if size_parameter(k)))
        raise ProposalError(f"cannot change {change.term}: {effect!r} is not an effect the station's model "
                            f"evaluates for a command (known: {known})")
    delta = float(change.delta)
    if not math.isfinite(delta):
        raise ProposalError(f"cannot change {change.term}: the delta {change.delta!r} is not a number")
    motions = model.motions_of(body)
    curve = getattr(motions, comp)
    effects = list(curve.effects)
    for i, e in enumerate(effects):
        p = e.parameters
        if e.name == effect and set(shape) == set(p) - {size} and all(
                math.isclose(p[k], v, rel_tol=1e-9, abs_tol=1e-12) for k, v in shape.items()):
            effects[i] = e.with_parameters(**{size: p[size] + delta})
            break
    else:
        try:
            new = effect_from_dict({"name": effect, **shape, size: delta}, change.term)
        except EffectSpecError as exc:
            raise ProposalError(f"cannot change {change.term}: {exc}") from None
        if curve.kind not in new.kinds:
            raise ProposalError(f"cannot change {change.term}: {effect!r} does not apply to a {curve.kind} axis")
        effects.append(new)
    new_curve = replace(curve, effects=tuple(effects))
    return replace(model, motions={**model.motions, body: replace(motions, **{comp: new_curve})})


def axis_changes(report: dict, model: StationModel) -> list[Change]:
    """The changes of Z's positioning error motion EZZ that a check's discovery report
    claims (none when it says ``no-mismatch``); effects that are not a change of the
    station's model (time, temperature, a channel) are left out (see :func:`left_out`)."""
    if report.get("verdict") == "no-mismatch":
        return []
    curve = model.motions_of(Z_BODY).z
    out = []
    for e in report.get("effects", []):
        name = e["name"]
        size = size_parameter(name)
        if size is None or size not in e["parameters"]:
            continue
        params = {k: float(v) for k, v in e["parameters"].items()}
        delta = params.pop(size)
        se = (e.get("stderr") or {}).get(size)
        have = [x.parameters[size] for x in curve.effects if x.name == name
                and all(math.isclose(x.parameters.get(k, math.nan), v, rel_tol=1e-9) for k, v in params.items())]
        unit = "ppm" if size == "ppm" else "um"
        now = (f"the model's {have[0]:.3g} {unit} becomes {have[0] + delta:.3g} {unit}" if have
               else "the model has none")
        shape = "".join(f", {k} {v:.4g}" for k, v in params.items())
        pm = f" +/- {se:.2g}" if se is not None and math.isfinite(se) else ""
        out.append(Change(motion_term(name, params), delta, why=(
            f"Z against its grating: {name}{shape}, {size} {delta:+.3g}{pm} {unit} beyond the station's model of "
            f"Z's positioning (EZZ of the Z joint; {now}): {e.get('explanation', '')}")))
    return out


def left_out(report: dict) -> list[str]:
    """The effects of a report that :func:`axis_changes` does not turn into changes."""
    if report.get("verdict") == "no-mismatch":
        return []
    return [e["name"] for e in report.get("effects", []) if size_parameter(e["name"]) is None]


def expected_change_um(old: StationModel, new: StationModel, holes_mm: Mapping[str, float],
                       angle_deg: float | Mapping[str, float] = 0.0) -> dict[str, float]:
    """Per hole: how much the change from ``old`` to ``new`` moves the hole's measured
    position (um), if the machine is as ``new`` says (``angle_deg``: where the table
    stands for it, one angle or one per hole). A scan measures a hole at
    ``target + (grating - predicted carriage) + image offset``; with ``old`` the
    command is ``old``'s and the grating's term carries what ``old`` did not know;
    with ``new`` the command is ``new``'s and the term is nil. Both are computed with
    the models (compensation, the detection point, the carriage prediction), in the
    scans' approach direction (+1)."""
    out = {}
    for hole, a in holes_mm.items():
        errs = []
        at = float(angle_deg[hole]) if isinstance(angle_deg, Mapping) else float(angle_deg)
        for cmd_model in (old, new):
            sol = compensate(cmd_model, [a], [at], direction_z=+1, direction_c=+1)
            z, c = float(sol.z_mm[0]), float(sol.c_deg[0])
            point = new.part_coordinates(new.errors([z], [c], direction_z=[1], direction_c=[1]).actual_point_mm)[0][0]
            grating_term = predicted_carriage_mm(new, z, +1) - predicted_carriage_mm(cmd_model, z, +1)
            # reading minus the hole = target - where the point truly is + the grating's term
            errs.append(a - float(point) + grating_term)
        out[hole] = (errs[1] - errs[0]) * 1e3
    return out


def grating_residual_change_um(old: StationModel, new: StationModel, holes_mm: Mapping[str, float],
                               angle_deg: float | Mapping[str, float] = 0.0) -> dict[str, float]:
    """Per hole: how much the change moves what the grating chart watches there, the
    grating's reading minus the carriage prediction (um), if the machine is as ``new``
    says (the chart starts again from a new baseline when a model is approved);
    ``angle_deg`` as ``expected_change_um`` takes it."""
    out = {}
    for hole, a in holes_mm.items():
        r = []
        at = float(angle_deg[hole]) if isinstance(angle_deg, Mapping) else float(angle_deg)
        for cmd_model in (old, new):
            sol = compensate(cmd_model, [a], [at], direction_z=+1, direction_c=+1)
            z = float(sol.z_mm[0])
            r.append(predicted_carriage_mm(new, z, +1) - predicted_carriage_mm(cmd_model, z, +1))
        out[hole] = (r[1] - r[0]) * 1e3
    return out


def axis_proposal(report: dict, data: AxisCheckData, model: StationModel, base_version: str,
                  holes_mm: Mapping[str, float], machine_s: float | None = None) -> Proposal | None:
    """A proposal from a check's report: the changes of EZZ it claims, the report's
    explanations, the per-target mean deviations (grating minus prediction) as the
    evidence and each hole's expected change; None when it claims none."""
    changes = axis_changes(report, model)
    if not changes:
        return None
    from station.monitor.proposals import apply_changes

    new = apply_changes(model, changes)
    expected = expected_change_um(model, new, holes_mm)
    chart = grating_residual_change_um(model, new, holes_mm)
    evidence = {f"Z {t:.3f} mm {'up' if d > 0 else 'down'}": [round(v, 4)]
                for (t, d), v in data.mean_deviations_um().items()}
    skipped = left_out(report)
    b, a = report["before"], report["after"]
    reason = (f"station check of Z against its grating ({len(data.points)} points, {len(data.targets_mm)} targets "
              f"{data.targets_mm[0]:g}..{data.targets_mm[-1]:g} mm"
              + (f", {machine_s:.0f} s of machine time" if machine_s is not None else "") + f"): {report['verdict']}, "
              f"rms {b['rms']:.3g} -> {a['rms']:.3g} um against a noise floor of {report['noise_floor']:.3g} um; "
              f"the model's EZZ lacks " + ", ".join(c.term.split(".", 3)[3] for c in changes)
              + ". The grating corrects Z's positioning in inspections, so the holes' readings do not move; the "
              "grating chart's residual at the holes does (" + ", ".join(f"{h} {v:+.2f} um" for h, v in chart.items())
              + ") and the compensation's commands with it"
              + (f". Not proposed (not evaluated for a command): {', '.join(skipped)}" if skipped else ""))
    kw: dict[str, Any] = dict(id=uuid.uuid4().hex[:12], created_at=datetime.now(timezone.utc).isoformat(),
                              base_version=base_version, reason=reason, changes=changes, evidence=evidence,
                              expected_change_um=expected)
    return Proposal(**kw)


# ---------------------------------------------------------------------------------
# The check run on a station (Session.check_axis)


@dataclass
class AxisCheckOutcome:
    """A check of Z against the grating: the points, discovery's report, the files,
    the machine time, and the proposal it made (when asked and it claims a change)."""

    state: str  # complete | aborted | faulted
    reason: str = ""
    data: AxisCheckData | None = None
    report: dict | None = None
    changes: list[Change] = field(default_factory=list)
    proposal: Proposal | None = None
    files: list[Path] = field(default_factory=list)
    out_dir: Path | None = None
    machine_s: float | None = None
    cycle: dict | None = None
    model_version: str = ""

    @property
    def verdict(self) -> str | None:
        return None if self.report is None else self.report["verdict"]

    def summary(self) -> str:
        if self.report is None:
            return f"axis check of Z did not complete: {self.reason}"
        r = self.report
        eff = "; ".join(f"{e['name']} " + ", ".join(f"{k} {v:.3g}" for k, v in e["parameters"].items())
                        for e in r["effects"]) or "none"
        return (f"axis check of Z on {self.model_version}: {r['verdict']}; effects: {eff}; rms "
                f"{r['before']['rms']:.3g} -> {r['after']['rms']:.3g} um"
                + (f"; machine time {self.machine_s:.1f} s" if self.machine_s is not None else ""))

    def to_json(self) -> dict:
        r = self.report
        return {"state": self.state, "reason": self.reason, "model_version": self.model_version,
                "verdict": self.verdict, "machine_s": self.machine_s, "cycle": self.cycle,
                "noise_floor_um": None if r is None else r["noise_floor"],
                "rms_before_um": None if r is None else r["before"]["rms"],
                "rms_after_um": None if r is None else r["after"]["rms"],
                "effects": [] if r is None else r["effects"],
                "findings": [] if r is None else r["findings"],
                "changes": [{"term": c.term, "delta": c.delta, "why": c.why} for c in self.changes],
                "not_proposed": [] if r is None else left_out(r),
                "proposal": None if self.proposal is None else self.proposal.to_json(),
                "targets_mm": [] if self.data is None else self.data.targets_mm,
                "c_deg": None if self.data is None else self.data.c_deg,
                "mean_deviation_um": [] if self.data is None else [
                    {"target_mm": t, "direction": d, "deviation_um": v}
                    for (t, d), v in self.data.mean_deviations_um().items()],
                "points": [] if self.data is None else [p.to_json() for p in self.data.points],
                "out_dir": None if self.out_dir is None else str(self.out_dir),
                "files": [str(p) for p in self.files]}


def _machine_s(engine, time_scale: float | None) -> dict | None:
    from station.sequencer.cycle import machine_time

    try:
        poll = {n: float(getattr(engine.devices.axis(n), "poll_s", 0.0) or 0.0) for n in ("Z", "C")}
        mt = machine_time(engine.ledger.steps, time_scale=time_scale, camera=None, poll_s=poll)
    except Exception:  # noqa: BLE001 - the figure must not cost the check
        return None
    return {"machine_s": mt.total_s, "basis": mt.basis, "breakdown": dict(mt.breakdown)}


async def run_axis_check(session, family=None, *, settings: AxisCheckSettings | None = None,
                         out_dir: str | Path | None = None, propose: bool = False, plots: bool = True,
                         holes_mm: Mapping[str, float] | None = None) -> AxisCheckOutcome:
    """Run the check on a session's station (``Session.check_axis``): home when needed,
    the plan on its engine, discovery on the files in ``out_dir`` (default
    ``<data>/checks/axis/<UTC time>``), and with ``propose`` a proposal in the
    station's book when the report claims a change; every step logged."""
    from station.inspection.service import ensure_ready, motion_limits
    from station.sequencer.engine import PlanEnded, link_fault

    settings = settings or AxisCheckSettings()
    st = session.station
    model = st.model
    version = session.model_version
    if session.engine.devices.encoder is None:
        raise ValueError("the station has no grating encoder: the check of Z needs it")
    if family is None:
        raise ValueError("the check needs the part family whose stroke it covers")
    lo, hi = check_stroke(model, family, settings)
    targets = check_targets(lo, hi, settings)
    holes = dict(holes_mm) if holes_mm is not None else {h.id: h.position.nominal for h in family.holes}
    stamp = datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%S")
    out = Path(out_dir) if out_dir is not None else Path(session.store.data_dir) / "checks" / "axis" / stamp
    time_scale = getattr(st, "time_scale", None)
    for attempt in (1, 2):
        try:
            await ensure_ready(session.engine)
            plan = axis_check_plan(model, targets, settings, motion_limits(session.engine.devices), time_scale)
            data: AxisCheckData = await session.engine.run(plan)
            break
        except PlanEnded as ended:
            if attempt == 1 and link_fault(session.engine):
                # the check holds no part and its data are all retaken: once more from
                # the start, after the reset and homing that ensure_ready does
                await asyncio.to_thread(session.store.log_event, "alarm",
                                        f"axis check stopped by a drive's link watchdog ({ended.reason}): "
                                        "reset, homed and run once more")
                continue
            res = AxisCheckOutcome("faulted" if ended.outcome == "faulted" else "aborted", ended.reason,
                                   cycle=_machine_s(session.engine, time_scale), model_version=version)
            await asyncio.to_thread(session.store.log_event, "check", res.summary())
            return res
    cycle = _machine_s(session.engine, time_scale)
    sigma = float(getattr(session.watch, "z_repeatability_um", 0.3))
    d, files = await asyncio.to_thread(run_discovery, data, model, sigma, out, plots)
    res = AxisCheckOutcome("complete", "", data, d.report, axis_changes(d.report, model), None, files, out,
                           None if cycle is None else cycle["machine_s"], cycle, version)
    res.files.append(out / "check.json")
    text = json.dumps(res.to_json(), indent=2, default=_json_default) + "\n"
    await asyncio.to_thread((out / "check.json").write_text, text)
    await asyncio.to_thread(session.store.log_event, "check", res.summary())
    if propose:
        p = axis_proposal(d.report, data, model, version, holes, res.machine_s)
        if p is not None:
            await asyncio.to_thread(session.proposals.add, p)
            await asyncio.to_thread(session.store.log_event, "proposal", f"model proposal {p.id} on {p.base_version}: "
                                    + "; ".join(c.why for c in p.changes))
            res.proposal = p
    return res


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")
