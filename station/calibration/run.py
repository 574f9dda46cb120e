"""One self-calibration run on a session's station: plan the poses, measure them on the
artefact, identify, report (docs/calibration.md). Used by ``station calibrate master``;
the REST face (``POST /api/v1/calibrations/master``) is to call the same.

The z nodes of the error-motion curves are the artefact's rings: the targets are seen
there, so each z node is observed directly and the curves' interpolation between nodes
(which a world with finer structure would break) enters only through the +/-0.7 mm view
offsets. C's nodes are the targets' angles (every 45 deg for CA-22.2-5x8).
"""

from __future__ import annotations

import asyncio
import functools
import time
from dataclasses import dataclass

import numpy as np

from station.calibration.artefact import ArtefactCertificate
from station.calibration.identify import Identification, NoiseModel, Parameterisation, identify
from station.calibration.measure import (
    SIGMA_GRATING_RUN_UM,
    SLIDE_REPEATABILITY_UM,
    CalibrationRun,
    MeasureSettings,
    run_calibration,
)
from station.calibration.observability import ObservabilityReport, analyse
from station.calibration.planner import candidate_poses, plan_poses, subset


def artefact_parameterisation(model, cert: ArtefactCertificate) -> Parameterisation:
    """The parameterisation whose nodes are the artefact's rings (z) and angles (C),
    shaped by the station's present model: between the nodes each curve keeps the
    model's own shape (its finer table, its effects), and only the node values' changes
    are interpolated (as the proposal applies them)."""
    rings = tuple(sorted({float(t.nominal_position_mm) for t in cert.targets}))
    angles = tuple(sorted({float(t.nominal_angle_deg) for t in cert.targets}))
    return Parameterisation(model, z_nodes_mm=rings, c_nodes_deg=angles, shaped=True)


@dataclass
class CalibrationOutcome:
    par: Parameterisation
    result: Identification
    report: ObservabilityReport
    run: CalibrationRun
    cycle: dict | None
    truth: np.ndarray | None
    wall_s: float

    def to_json(self, model_version: str | None = None) -> dict:
        """The issue's output contract; ``model_version``: the id of the model proposal
        made from this result (``station.calibration.proposal``), null when none was made."""
        rep = self.report.to_dict()
        return {
            "parameters": self.result.parameters(self.truth),
            "observability": {"rank": rep["rank"], "n_parameters": rep["n_parameters"],
                              "condition": rep["condition"], "unobservable": rep["unobservable"]},
            "residual_rms_um": self.result.residual_rms_um,
            "model_version": model_version,
            "chi2_per_dof": self.result.chi2_per_dof,
            "poses": int(self.run.observations.design.z_mm.size),
            "sightings": int(self.run.observations.design.pose.size),
            "missed": self.run.missed,
            "machine_s": None if self.cycle is None else self.cycle.get("machine_s"),
            # the noise model's figures of this run (sigmas as estimated from the residuals,
            # the camera's scale at the view offsets, the grating reference's offset)
            "noise": {k: v for k, v in self.result.noise.items() if k != "carriage_um"},
        }


async def calibrate(session, cert: ArtefactCertificate, *, n_poses: int = 40, seed: int = 0,
                    settings: MeasureSettings | None = None, suggestions: bool = True,
                    progress=None) -> CalibrationOutcome:
    """Plan ``n_poses`` poses (greedy D-optimal among the artefact's candidate views),
    measure them with the artefact on the table (in simulation the twin's, made with
    ``seed``), identify from the station's present model and the certificate."""
    say = progress or (lambda text: None)
    t0 = time.perf_counter()
    st = session.station
    par = artefact_parameterisation(st.model, cert)
    cand = candidate_poses(cert)
    say(f"planning {n_poses} poses among {cand.z_mm.size} candidate views")
    design = subset(cand, plan_poses(par, cert, cand, n_poses, sigma_grating_um=SIGMA_GRATING_RUN_UM,
                                     free_carriage_off_nodes=True))
    say(f"measuring {design.z_mm.size} poses, {design.pose.size} target sightings")
    with st.artefact_on_table(cert, seed=seed):
        run, cycle = await run_calibration(session, cert, design, par.z_nodes_mm[0], settings)
        truth_model = st.world_model_now() if hasattr(st, "world_model_now") else None
    if run.missed:
        say(f"{len(run.missed)} sighting(s) not found: " + ", ".join(f"{x['target']}" for x in run.missed[:5]))
    say("identifying")
    # off the event loop: it carries the drives' heartbeats (seconds of linear algebra)
    res = await asyncio.to_thread(functools.partial(identify, par, st.model, cert, run.observations,
                                                    noise=NoiseModel(repeatability_um=SLIDE_REPEATABILITY_UM)))
    rep = await asyncio.to_thread(analyse, par, cert, run.observations.design,
                                  candidate_poses=cand if suggestions else None, sigma_grating_um=SIGMA_GRATING_RUN_UM,
                                  free_carriage_off_nodes=True)
    truth = None if truth_model is None else par.values_from_model(truth_model)
    return CalibrationOutcome(par, res, rep, run, cycle, truth, time.perf_counter() - t0)
