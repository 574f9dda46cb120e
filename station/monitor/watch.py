"""The station watches itself: its own evidence against its own model, on control charts.

Two kinds of evidence (docs/monitor.md):

* **Every inspection: the grating against the model.** For each hole measured, the
  grating's reading minus the carriage position the station's model predicted for the
  command (``FrameObservation.carriage_pred_mm``), averaged over the hole's frames (one
  approach). The mean over the inspection's holes, less its baseline, in units of its
  standard error (the Z axis' stated repeatability over the root of the number of
  holes), goes on an EWMA chart. The baseline is the mean of the first
  ``phase1_inspections`` after a start or an accepted check (Phase I): what the model
  and the machine agreed on then. A departure may or may not reach the holes (the
  grating corrects the carriage, but a warm grating reads short and a warm frame
  carries the point unseen, with the same signature as a warm screw), so it asks for a
  check on the master: the alarm is raised when the chart signals and the departure's
  estimate exceeds the model's stated standard uncertainty (``gate_um``).
* **Every inspection: the frames' scatter.** Each hole is measured in several frames
  from one approach; the scatter of their axial readings pooled over the inspection's
  holes (variance ``s^2`` with ``nu`` degrees of freedom) against its Phase I value
  ``s0^2``: ``x = (ln(s^2 / s0^2) + 1/nu) / sqrt(2/nu)`` (the log-variance chart of
  Crowder and Hamilton, 1992: about standard normal in control) on a third EWMA. Only a
  growth alarms (a loose endoscope, a vibrating stand, a camera out of focus: the
  station's repeatability is no longer what its U assumes); ln chi-square's upper tail
  is lighter than the normal's, so the stated false-alarm rate is an upper bound.
* **Checks on the certified master**: per position characteristic,
  ``z = (measured - certified) / sqrt(u_station^2 + u_certificate^2)`` (standard
  uncertainties, k = 1); their mean times the root of their number goes on a second
  EWMA chart (in control: standard normal if the stated uncertainties are honest). The
  alarm is raised when the chart signals and its smoothed mean z is beyond 2 (the
  difference beyond the combined expanded uncertainty: E_n > 1), or at once when any
  single ``|z| > z_single`` (a knocked datum shows as a large step at the first check
  after it), or when the check's pooled statistic (mean z times the root of their
  number) is beyond ``z_single`` (every hole a little off the same way: a drift the
  chart, restarted at the last correction, has not yet smoothed in).

Each chart's limit is set from the wanted in-control average run length by the
Markov-chain computation of ``station.monitor.ewma``: the false-alarm rate is stated,
not guessed. An alarm puts the station in ``needs_check`` (the MES reads it over REST:
"station needs a check") until a master check in control clears it; that check then
restarts the grating chart from a new baseline (the state the master just confirmed).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Iterable

import numpy as np

from station.monitor.ewma import EwmaChart, limit_for_arl


@dataclass(frozen=True)
class Alarm:
    """An alarm: after which observation (``index``: inspections so far), by which
    chart, and why (a sentence for the operator and the event log)."""

    index: int
    chart: str
    reason: str

    def to_json(self) -> dict:
        return {"index": self.index, "chart": self.chart, "reason": self.reason}


@dataclass(frozen=True)
class CharacteristicCheck:
    """One characteristic of a master check: measured against certified."""

    id: str
    measured: float | None
    certified: float
    u_station: float | None  # standard, same unit
    u_certificate: float  # standard

    @property
    def z(self) -> float | None:
        if self.measured is None or self.u_station is None:
            return None
        return (self.measured - self.certified) / math.hypot(self.u_station, self.u_certificate)

    @property
    def en(self) -> float | None:
        """ISO 13528's E_n: the difference over the expanded uncertainties (k = 2)."""
        z = self.z
        return None if z is None else z / 2.0


def frame_scatter_um2(holes: Iterable[Any]) -> tuple[float, int] | None:
    """The pooled variance (um^2) of the holes' frames' axial readings about each
    hole's mean, and its degrees of freedom; None without a hole of two frames."""
    ss, nu = 0.0, 0
    for h in holes:
        ax = [f.axial_mm * 1e3 for f in getattr(h, "frames", ()) if getattr(f, "axial_mm", None) is not None]
        if len(ax) >= 2:
            ss += float(np.sum((np.asarray(ax) - np.mean(ax)) ** 2))
            nu += len(ax) - 1
    return (ss / nu, nu) if nu else None


def grating_residual_um(holes: Iterable[Any]) -> tuple[float, int] | None:
    """The mean over holes of (grating - model's carriage) averaged over each hole's
    frames (um), and the number of holes; None when no hole has both."""
    per_hole = []
    for h in holes:
        r = [(f.grating_mm - f.carriage_pred_mm) * 1e3 for f in getattr(h, "frames", ())
             if getattr(f, "grating_mm", None) is not None and getattr(f, "carriage_pred_mm", None) is not None]
        if r:
            per_hole.append(float(np.mean(r)))
    if not per_hole:
        return None
    return float(np.mean(per_hole)), len(per_hole)


@dataclass
class StationWatch:
    """The charts of one station and its ``needs_check`` state."""

    #: the Z axis' repeatability (ISO 230-2 s, um) as the station's acceptance stated it
    z_repeatability_um: float = 0.3
    #: the station's stated standard uncertainty of its model at the detection point (um)
    gate_um: float = 0.35
    #: in-control ARLs: inspections between false alarms of the grating chart, master
    #: checks between false alarms of the master chart
    #: (100,000 and 10,000: over 500 inspections with a check every 10, under 1 % for
    #: a false alarm of either chart on a world that agrees with the model)
    arl0_inspections: float = 100000.0
    arl0_checks: float = 10000.0
    lam_inspections: float = 0.2
    lam_checks: float = 0.4
    lam_scatter: float = 0.2
    #: Phase I: the baseline is the mean of this many inspections (its standard error,
    #: 0.05 um with two holes at 0.3 um, is small beside the gate)
    phase1_inspections: int = 20
    #: a single master characteristic this many combined standard uncertainties off alarms at once
    z_single: float = 4.5

    index: int = 0
    needs_check: str | None = None
    alarms: list[Alarm] = field(default_factory=list)

    def __post_init__(self):
        self.grating = EwmaChart("grating", self.lam_inspections, limit_for_arl(self.lam_inspections,
                                                                                 self.arl0_inspections))
        self.master = EwmaChart("master", self.lam_checks, limit_for_arl(self.lam_checks, self.arl0_checks))
        self.scatter = EwmaChart("scatter", self.lam_scatter, limit_for_arl(self.lam_scatter, self.arl0_inspections))
        self._phase1_scatter: list[tuple[float, int]] = []
        self.scatter_ref_um2: float | None = None
        self.last_scatter_um2: float | None = None
        self._phase1: list[float] = []
        self.baseline_um: float | None = None
        self.last_residual_um: float | None = None
        self.last_master_z: float | None = None

    # ------------------------------------------------------------------ evidence
    def observe_inspection(self, holes: Iterable[Any]) -> list[Alarm]:
        """One production inspection's holes (``HoleResult``s); the alarms it raises."""
        self.index += 1
        holes = list(holes)
        alarms = self._observe_scatter(holes)
        res = grating_residual_um(holes)
        if res is None:
            return alarms
        r_um, n = res
        self.last_residual_um = r_um
        if self.baseline_um is None:
            self._phase1.append(r_um)
            if len(self._phase1) >= self.phase1_inspections:
                self.baseline_um = float(np.mean(self._phase1))
            return alarms
        se_um = self.z_repeatability_um / math.sqrt(n)
        signal = self.grating.add((r_um - self.baseline_um) / se_um)
        departure_um = self.grating.z * se_um
        if signal and abs(departure_um) > self.gate_um and self.needs_check is None:
            # once asked for, a check is not asked for again at every inspection
            return alarms + self._raise("grating", f"the grating departs from the station's model by "
                                                   f"{departure_um:+.2f} um (EWMA; baseline {self.baseline_um:+.2f} um): "
                                                   f"the station's errors may exceed its stated U; check it on the master")
        return alarms

    def _observe_scatter(self, holes: list) -> list[Alarm]:
        res = frame_scatter_um2(holes)
        if res is None:
            return []
        s2, nu = res
        self.last_scatter_um2 = s2
        if self.scatter_ref_um2 is None:
            self._phase1_scatter.append(res)
            if len(self._phase1_scatter) >= self.phase1_inspections:
                tot = sum(n for _, n in self._phase1_scatter)
                self.scatter_ref_um2 = sum(v * n for v, n in self._phase1_scatter) / tot
            return []
        x = (math.log(max(s2, 1e-12) / max(self.scatter_ref_um2, 1e-12)) + 1.0 / nu) / math.sqrt(2.0 / nu)
        signal = self.scatter.add(x)
        if signal and self.scatter.z > 0 and self.needs_check is None:
            ratio = math.sqrt(s2 / self.scatter_ref_um2)
            return self._raise("scatter", f"the frames' scatter grew (EWMA {self.scatter.z:+.2f} > "
                                          f"{self.scatter.limit:.2f}; last {math.sqrt(s2):.2f} um against "
                                          f"{math.sqrt(self.scatter_ref_um2):.2f} um, x{ratio:.1f}): the endoscope, "
                                          f"the stand or the focus; check the station on the master")
        return []

    def observe_master(self, checks: Iterable[CharacteristicCheck]) -> list[Alarm]:
        """One master check's position characteristics; its alarms, or none and the
        ``needs_check`` state cleared (and the grating chart restarted from the state
        the master has just confirmed)."""
        zs = [(c.id, c.z) for c in checks]
        missing = [cid for cid, z in zs if z is None]
        if missing:
            return self._raise("master", f"master check: {', '.join(missing)} not measured")
        if not zs:
            raise ValueError("a master check needs at least one characteristic")
        worst_id, worst = max(zs, key=lambda p: abs(p[1]))
        root_n = math.sqrt(len(zs))
        stat = float(np.mean([z for _, z in zs]) * root_n)
        self.last_master_z = stat
        # the chart signals on the statistics; the alarm needs the smoothed mean error
        # beyond the combined expanded uncertainty as well (ISO 13528's E_n > 1): a bias
        # the station's U covers is not "outside its stated U"
        signal = self.master.add(stat) and abs(self.master.z / root_n) > 2.0
        if abs(worst) > self.z_single or abs(stat) > self.z_single or signal:
            if abs(worst) > self.z_single:
                why = f"{worst_id} is {worst:+.1f} combined standard uncertainties from its certificate"
            elif abs(stat) > self.z_single:
                why = (f"its {len(zs)} positions are {stat / root_n:+.1f} combined standard uncertainties from their "
                       f"certificate on average (pooled {stat:+.1f})")
            else:
                why = f"the results drift from the certificate (EWMA {self.master.z:+.2f})"
            # the alarm is raised; the next check is judged afresh (a step put right is not a drift)
            self.master.restart()
            return self._raise("master", f"master check: {why}: the station is outside its stated U")
        # in control: the station is within its stated U. If a check was asked for, the
        # state the master has just confirmed becomes the grating chart's new reference
        if self.needs_check is not None:
            self.needs_check = None
            self.grating.restart()
            self._phase1 = []
            self.baseline_um = None
            self.scatter.restart()
        return []

    def model_changed(self) -> None:
        """A new model is in use: its predictions are the new reference; the charts start again."""
        self.grating.restart()
        self.master.restart()
        self._phase1 = []
        self.baseline_um = None

    def _raise(self, chart: str, reason: str) -> list[Alarm]:
        alarm = Alarm(self.index, chart, reason)
        self.alarms.append(alarm)
        self.needs_check = reason
        return [alarm]

    # ------------------------------------------------------------------ reading
    def state(self) -> dict:
        """What the MES, the panel and the metrics read."""
        return {
            "needs_check": self.needs_check is not None,
            "reason": self.needs_check,
            "inspections_observed": self.index,
            "grating": {"baseline_um": self.baseline_um, "last_residual_um": self.last_residual_um,
                        "ewma": self.grating.z, "limit": self.grating.limit, "arl0": self.arl0_inspections},
            "scatter": {"reference_um": None if self.scatter_ref_um2 is None else math.sqrt(self.scatter_ref_um2),
                        "last_um": None if self.last_scatter_um2 is None else math.sqrt(self.last_scatter_um2),
                        "ewma": self.scatter.z, "limit": self.scatter.limit},
            "master": {"last_z": self.last_master_z, "ewma": self.master.z, "limit": self.master.limit,
                       "arl0_checks": self.arl0_checks},
            "alarms": len(self.alarms),
        }
