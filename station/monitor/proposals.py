"""The loop closes: from the station's own evidence to a proposed model, approved by an engineer.

The master checks measure what no other sensor of the station sees: where the holes
are on the part against where a calibration laboratory found them. When a check is out
of the station's stated U, the mean of its position errors over the checks since the
alarm is the station's axial datum error, and the physics that moved it is named: the
installation error along Z of the calibration block J that carries the part
(ISO 230-1: a location error of the workholding, EZ0 of the part datum). The
proposal corrects that one parameter by the amount the model's own sensitivity says
(the finite difference of the model's predicted detection point), and states the
expected change of every hole's measured position.

Proposals live under ``<data>/models/``: ``proposals/<id>.json`` (what, why, the
evidence, the expected change), and ``approved.json`` (the accepted changes in order,
applied over the station's configured model at every start). Every proposal, approval
and rejection is an event of the store's log (the audit trail).
"""

from __future__ import annotations

import json
import os
import uuid
from dataclasses import asdict, dataclass, field, replace
from datetime import datetime, timezone
from pathlib import Path
from typing import Iterable

import numpy as np

from station.kinematics.model import StationModel
from station.kinematics.parameters import COMPONENTS, SixDof, motion_names

#: the parameter a master check names when the datum moved
DATUM_BODY = "J"
DATUM_TERM = f"installation.{DATUM_BODY}.z_um"
#: the part's expansion from its datum face (ppm), the master standing in for a thermometer
SCALE_TERM = "part.scale_ppm"


class ProposalError(ValueError):
    """A proposal that does not exist or cannot change state as asked."""


@dataclass
class Change:
    """One parameter of the model changed: ``installation.<body>.<key>`` by ``delta``."""

    term: str
    delta: float
    why: str = ""
    #: the change's standard uncertainty, when it was measured with one (self-calibration)
    u: float | None = None

    def apply(self, model: StationModel) -> StationModel:
        if self.term.startswith("motion."):
            # an error motion's effect (the station's own check of Z: station.checks.axis)
            from station.checks.axis import apply_motion_change

            return apply_motion_change(model, self)
        if self.term.startswith("node."):
            # an error-motion curve at one node of a self-calibration (station.calibration.proposal)
            from station.calibration.proposal import apply_node_change

            return apply_node_change(model, self)
        if self.term == SCALE_TERM:
            return model  # the part's, not the machine's: ``part_scale_ppm`` (session settings)
        section, body, key = self.term.split(".")
        if section != "installation":
            raise ProposalError(f"cannot change {self.term}: only installation errors are proposed")
        old = model.static_errors.get(body, SixDof())
        new = replace(old, **{key: getattr(old, key) + self.delta})
        return replace(model, static_errors={**model.static_errors, body: new})


@dataclass
class Proposal:
    id: str
    created_at: str
    base_version: str
    reason: str
    changes: list[Change]
    #: the checks it rests on: per characteristic, measured - certified (um)
    evidence: dict[str, list[float]]
    #: per hole: the expected change of its measured position with the change (um)
    expected_change_um: dict[str, float]
    state: str = "proposed"
    #: what the checks over time say the change is (station.monitor.evidence.Explanation)
    explanation: dict = field(default_factory=dict)
    decided_by: str | None = None
    decided_at: str | None = None
    decision_note: str | None = None

    def to_json(self) -> dict:
        return asdict(self)

    @classmethod
    def from_json(cls, d: dict) -> Proposal:
        d = dict(d)
        d["changes"] = [Change(**c) for c in d["changes"]]
        return cls(**d)


def datum_sensitivity(model: StationModel, z_mm: float, c_deg: float, term: str = DATUM_TERM) -> float:
    """d(predicted axial position of the detection point)/d(term), um per um, at a pose:
    a central difference of the model (the change is linear to far below a nm)."""
    h = 1.0
    up = Change(term, +h).apply(model)
    down = Change(term, -h).apply(model)
    ax = [m.part_coordinates(m.errors([z_mm], [c_deg]).actual_point_mm)[0][0] for m in (up, down)]
    return float((ax[0] - ax[1]) * 1e3 / (2 * h))


def datum_proposal(model: StationModel, base_version: str, reason: str,
                   errors_um: dict[str, list[float]], holes_mm: dict[str, float],
                   consistency_um: float = 3.0, explanation=None, scale_ppm: float | None = None) -> Proposal:
    """A proposal from master checks' position errors (``errors_um``: characteristic
    id -> measured - certified, um) at the holes' axial places (``holes_mm``: hole id ->
    mm): the datum's error is their mean, corrected through the model's sensitivity at
    each hole. Errors further apart than ``consistency_um`` (4.5 standard
    uncertainties of a difference of two of them) are not one datum shift: refused.
    ``explanation`` (``station.monitor.evidence.Explanation``): what the checks over
    time say the change is (a step, a drift), which names the physics. ``scale_ppm``:
    the part's expansion the checks show and the station has not corrected: corrected
    first (``part.scale_ppm``, about the part's datum face), the datum then takes the
    rest."""
    evidence = {cid: list(es) for cid, es in errors_um.items()}
    pooled = [e for es in errors_um.values() for e in es]
    if not pooled:
        raise ProposalError("no master check results to propose from")
    if max(pooled) - min(pooled) > consistency_um:
        # one datum moves every hole alike: errors this far apart are not one shift (a
        # check the knock fell into, a dirty master): no proposal, check again
        raise ProposalError(f"the master's position errors disagree ({min(pooled):+.2f} .. {max(pooled):+.2f} um, "
                            f"more than {consistency_um:g} um apart): not one datum shift; check again")
    scale_change = None
    if scale_ppm:
        # a hole at a mm from the face reads scale * 1e-3 * a um long; reported times
        # (1 - scale 1e-6), it reads that much less
        shrink = {h: -scale_ppm * 1e-3 * a for h, a in holes_mm.items()}
        errors_um = {cid: [e + shrink.get(cid.rsplit(".", 1)[0], 0.0) for e in es] for cid, es in errors_um.items()}
        pooled = [e for es in errors_um.values() for e in es]
        scale_change = Change(SCALE_TERM, float(scale_ppm), why=(
            f"the holes read long in proportion to their distance from the part's datum face by {scale_ppm:+.0f} ppm "
            f"(the part {'warmer' if scale_ppm > 0 else 'colder'} than 20 degC by about {abs(scale_ppm) / 23.0:.1f} K at an "
            f"aluminium alloy's 23 ppm/K; thermal expansion, ISO 1): reported at 20 degC, the master of the parts' "
            f"material standing in for a thermometer"))
    mean_um = float(np.mean(pooled))
    sens = [datum_sensitivity(model, z, 0.0) for z in holes_mm.values()]
    s = float(np.mean(sens))
    if abs(s) < 0.5:
        raise ProposalError(f"the datum term {DATUM_TERM} barely moves the holes (sensitivity {s:.3f} um/um)")
    # the station measures a hole at target + (its image offset from the true point):
    # a world datum moved by d puts the point -s d from the model's prediction, so the
    # holes read e = -s d high; a model moved by delta moves its prediction s delta and
    # the readings with it: delta = -e / s removes e
    delta = -mean_um / s
    spread = (f"spread {float(np.std(pooled, ddof=1)):.2f} um over {len(pooled)} values" if len(pooled) > 1
              else "one value")
    seen = f"master checks: positions {mean_um:+.2f} um from the certificate now ({spread})"
    kind = getattr(explanation, "kind", None)
    if kind == "drift":
        why = (f"{seen}; {explanation.description}. The station has no thermometer: its axial datum "
               f"(the calibration block's installation error along Z, ISO 230-1 EZ0) is set to its present value, "
               f"a change of {delta:+.2f} um, and its stated uncertainty covers the drift between checks while it lasts")
    elif kind == "step":
        why = (f"{seen}; {explanation.description}: the calibration block's installation error along Z "
               f"(ISO 230-1: location error EZ0 of the workholding) changes by {delta:+.2f} um")
    else:
        why = (f"{seen}: the part's axial datum moved; the calibration block's installation error along Z (ISO "
               f"230-1: location error EZ0 of the workholding) changes by {delta:+.2f} um"
               + (f" ({explanation.description})" if explanation is not None else ""))
    change = Change(DATUM_TERM, delta, why=why)
    after = change.apply(model)
    expected = {}
    for hole, z in holes_mm.items():
        a0 = model.part_coordinates(model.errors([z], [0.0]).actual_point_mm)[0][0]
        a1 = after.part_coordinates(after.errors([z], [0.0]).actual_point_mm)[0][0]
        # compensation cancels the model's predicted shift, so the world's point moves
        # the other way and the hole's image offset, the reading, by the shift itself
        expected[hole] = float((a1 - a0) * 1e3)
        if scale_change is not None:
            expected[hole] += -scale_change.delta * 1e-3 * z
    changes = [change] if scale_change is None else [scale_change, change]
    return Proposal(uuid.uuid4().hex[:12], datetime.now(timezone.utc).isoformat(), base_version, reason, changes,
                    evidence, expected, explanation=explanation.to_json() if explanation is not None else {})


@dataclass
class ProposalBook:
    """Proposals and the approved changes of one station (``<data>/models``)."""

    data_dir: Path
    folder: Path = field(init=False)

    def __post_init__(self):
        self.folder = Path(self.data_dir) / "models"
        (self.folder / "proposals").mkdir(parents=True, exist_ok=True)

    def _path(self, pid: str) -> Path:
        if not pid.isalnum() or len(pid) > 64:
            raise ProposalError(f"no proposal {pid!r}")
        return self.folder / "proposals" / f"{pid}.json"

    def _write(self, path: Path, data) -> None:
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps(data, indent=2))
        with open(tmp, "rb+") as f:
            os.fsync(f.fileno())
        os.replace(tmp, path)  # whole or not at all

    def add(self, p: Proposal) -> Proposal:
        from station.monitor.plots import write_proposal_plot

        write_proposal_plot(p, self.plot_path(p.id))
        self._write(self._path(p.id), p.to_json())
        return p

    def plot_path(self, pid: str) -> Path:
        """The proposal's before/after picture (PNG; it may not exist: a proposal without
        check history to show has none)."""
        return self._path(pid).with_suffix(".png")

    def get(self, pid: str) -> Proposal:
        path = self._path(pid)
        if not path.is_file():
            raise ProposalError(f"no proposal {pid!r}")
        return Proposal.from_json(json.loads(path.read_text()))

    def list(self) -> list[Proposal]:
        out = [Proposal.from_json(json.loads(f.read_text())) for f in (self.folder / "proposals").glob("*.json")]
        return sorted(out, key=lambda p: p.created_at)

    def decide(self, pid: str, approve: bool, who: str, note: str = "") -> Proposal:
        p = self.get(pid)
        if p.state != "proposed":
            raise ProposalError(f"proposal {pid} is already {p.state}")
        p.state = "approved" if approve else "rejected"
        p.decided_by, p.decided_at, p.decision_note = who, datetime.now(timezone.utc).isoformat(), note or None
        if approve:
            approved = self.approved_changes()
            approved.extend(p.changes)
            self._write(self.folder / "approved.json", [asdict(c) for c in approved])
        self._write(self._path(pid), p.to_json())
        return p

    def approved_changes(self) -> list[Change]:
        f = self.folder / "approved.json"
        return [Change(**c) for c in json.loads(f.read_text())] if f.is_file() else []


def part_scale_ppm(changes: Iterable[Change]) -> float:
    """The part's expansion the approved changes correct (ppm)."""
    return float(sum(c.delta for c in changes if c.term == SCALE_TERM))


def apply_changes(model: StationModel, changes: Iterable[Change], name_suffix: str = "") -> StationModel:
    for c in changes:
        model = c.apply(model)
    return replace(model, name=model.name + name_suffix) if name_suffix else model


def motion_component(model: StationModel, term: str, body: str, motion: str) -> str:
    """The component name (``dx`` ... ``ez``) of ``body``'s error motion ``motion`` in
    ``model``, for a change ``term`` of it: ProposalError when the body is not in the
    topology, has no joint, or has no such error motion."""
    try:
        joint = model.topology.by_name(body)
    except KeyError:
        raise ProposalError(f"cannot change {term}: no body {body!r} in the model's topology") from None
    if joint.joint is None:
        raise ProposalError(f"cannot change {term}: body {body} has no joint, hence no error motions")
    names = motion_names(body)
    if motion not in names:
        raise ProposalError(f"cannot change {term}: {body}'s error motions are {', '.join(names)}")
    return COMPONENTS[names.index(motion)]
