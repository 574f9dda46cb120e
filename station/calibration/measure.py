"""The measurement plan of a self-calibration run on the station: the planned poses
visited, each target in view measured by the vision stage, the grating read at every
frame; the observations in the form ``identify.identify`` consumes.

**Raw poses, not compensated ones.** Identification needs what the *machine* does at a
known command: the observation model (``identify.predict``) is the error model evaluated
at the commanded (z, C). A compensated command would be the present model's inverse,
i.e. a function of the very parameters being identified, and would hide part of the
error it is meant to see. So each planned pose is commanded as it is (nominal), every
axis approaching from below (``station.inspection.scan.approach``, as the scans do:
backlash taken up the same way at every pose, so a direction effect is one constant).

**The grating's zero.** The grating reads where the carriage is: the command plus EZZ
at it, including EZZ's constant part. The parameterisation keeps curves zero at their
first node (the gauge) and that constant in a static error, so the run first reads the
grating at the first z node (approached from below, like every pose) and reports each
pose's reading minus the command *relative to that reference*: exactly what the gauged
model predicts (EZZ(z) - EZZ(z_ref)).

**Pixels to part-frame offsets** as the bore scan does (``scan.measure_at``): the image
centre is the detection point; a hole at (x, y) px lies ``(x - cx) s`` along the wall
(tangential, increasing angle to the right) and ``(cy - y) s`` along the axis (up in
the image). Only targets near the centre are used (``max_offset_mm``), where the lens's
barrel distortion (uncorrected here, as in the scans' search frames) is below
0.2 um (k1 = -0.08 at fx = 1400 px: 2e-4 of a 0.7 mm offset).

The plan is a generator of ``station.sequencer.messages`` run by the engine (devices
come through the session's engine, never from ``sim``)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from station.calibration.artefact import ArtefactCertificate
from station.calibration.identify import Observations, Sightings
from station.inspection.scan import CameraGeometry, ScanSettings, approach, wrap_deg
from station.motion import AxisLimits
from station.sequencer import messages as m

#: the slide's repeatability per approach (ISO 230-2 s, 0.3 um for a ball-screw slide of
#: this class: the scenario's and the axis check's figure): the nominal of the
#: identification's noise model (``identify.NoiseModel``), which estimates it from the run
SLIDE_REPEATABILITY_UM = 0.3
#: the grating row's standard uncertainty in a run (um), for planning: the grating's
#: 0.05 um plus the repeatability, which moves the carriage between the reference reading
#: and each pose (the identification has both as terms of its own)
SIGMA_GRATING_RUN_UM = math.hypot(0.05, SLIDE_REPEATABILITY_UM)


@dataclass(frozen=True)
class MeasureSettings:
    #: frames per pose, each with its grating reading; averaged
    frames_per_pose: int = 2
    #: still after each move (s), as the scans' settle
    settle_s: float = 0.05
    #: approaches of the reference position, one grating reading each: their mean's
    #: repeatability (0.3 / sqrt(10) = 0.1 um) is common to every grating row (a
    #: nuisance of the fit: ``identify.NoiseModel``)
    reference_approaches: int = 10
    #: a detection further than this (mm on the wall) from where the target should be
    #: is not taken for it: the error motions move a target by tens of um, the next
    #: target is 8.7 mm (45 deg) or 32.5 mm away
    accept_mm: float = 0.25
    #: a detection below this confidence is not a target (ScanSettings.min_confidence)
    min_confidence: float = 0.3
    approach_z_mm: float = 0.5
    approach_c_deg: float = 0.5
    #: a sighting's vision u where the vision stage states none (px; as
    #: ``ScanSettings.vision_centre_u_px``)
    vision_centre_u_px: float = 0.05

    def scan_settings(self) -> ScanSettings:
        """The scan settings whose approach and settle this plan uses (for the cycle ledger)."""
        return ScanSettings(settle_s=self.settle_s, approach_z_mm=self.approach_z_mm,
                            approach_c_deg=self.approach_c_deg)


@dataclass
class CalibrationRun:
    """What one run measured: the observations (sightings not found are left out),
    the grating's reference, what was missed, and per frame the raw figures."""

    observations: Observations
    z_reference_mm: float
    grating_reference_um: float
    missed: list[dict] = field(default_factory=list)
    frames: int = 0

    def to_json(self) -> dict:
        d = self.observations.design
        return {"z_reference_mm": self.z_reference_mm, "grating_reference_um": self.grating_reference_um,
                "frames": self.frames, "missed": self.missed,
                "poses": [{"z_mm": float(z), "c_deg": float(c), "grating_um": float(g)}
                          for z, c, g in zip(d.z_mm, d.c_deg, self.observations.grating_um)],
                "sightings": [{"pose": int(p), "target": int(t), "tangential_um": float(u), "axial_um": float(v)}
                              for p, t, u, v in zip(d.pose, d.target, self.observations.tangential_um,
                                                    self.observations.axial_um)]}


def visiting_order(design: Sightings) -> np.ndarray:
    """Poses in the order they are visited: ring by ring up the stroke, and round the
    table forward within a ring (every approach from below is then mostly one move)."""
    return np.lexsort((design.c_deg % 360.0, np.round(design.z_mm, 3)))


def calibration_plan(cert: ArtefactCertificate, design: Sightings, geo: CameraGeometry, z_reference_mm: float,
                     settings: MeasureSettings | None = None, motion: Mapping[str, AxisLimits] | None = None):
    """The plan (a generator for ``Engine.run``) returning a :class:`CalibrationRun`."""
    settings = settings or MeasureSettings()
    scan = settings.scan_settings()
    motion = dict(motion or {})
    axes_at: dict[str, float] = {}
    cx, cy = geo.centre_px
    s = geo.mm_per_px
    r = cert.radius_mm
    a_nom = np.array([t.nominal_position_mm for t in cert.targets])
    phi_nom = np.array([t.nominal_angle_deg for t in cert.targets])

    # the grating's reference: its reading at the first z node, approached from below
    # (each reading after an approach of its own: the slide's repeatability is drawn per
    # approach, and readings of one approach share it)
    yield m.Checkpoint("grating reference")
    ref = []
    for _ in range(settings.reference_approaches):
        axes_at.pop("Z", None)
        yield from approach({"Z": float(z_reference_mm)}, scan, motion, axes_at)
        yield m.Settle(settings.settle_s)
        rd = yield m.ReadEncoder()
        ref.append((float(rd.position_mm) - z_reference_mm) * 1e3)
    ref_um = float(np.mean(ref))

    order = visiting_order(design)
    M = design.z_mm.size
    grating = np.full(M, np.nan)
    tang: dict[int, list[float]] = {}
    axial: dict[int, list[float]] = {}
    #: the vision stage's own u of each reading (um), per sighting
    tang_u: dict[int, list[float]] = {}
    axial_u: dict[int, list[float]] = {}
    c_now = 0.0
    frames = 0
    total = M * settings.frames_per_pose
    for i, p in enumerate(order):
        z_cmd = float(design.z_mm[p])
        # an endless table: the command is the angle's turn nearest the present one
        c_cmd = c_now + float(wrap_deg(float(design.c_deg[p]) - c_now))
        yield m.Checkpoint(f"pose {i + 1} of {M}")
        # Z approaches afresh at every pose (from below, even when it is already there):
        # poses of one ring would otherwise share one approach's repeatability, which
        # the fit takes as independent per pose
        axes_at.pop("Z", None)
        moved = yield from approach({"C": c_cmd, "Z": z_cmd}, scan, motion, axes_at)
        c_now = c_cmd
        if moved:
            yield m.Settle(settings.settle_s)
        ks = np.nonzero(design.pose == p)[0]
        # where each sighted target should appear (px): its nominal offset from the pose
        expect = {int(k): (cx + math.radians(float(wrap_deg(phi_nom[design.target[k]] - design.c_deg[p]))) * r / s,
                           cy - (a_nom[design.target[k]] - z_cmd) / s) for k in ks}
        readings = []
        for f in range(settings.frames_per_pose):
            rd = yield m.ReadEncoder()
            readings.append((float(rd.position_mm) - z_cmd) * 1e3 - ref_um)
            frame = yield m.Capture()
            holes = yield m.Measure(frame.image)
            frames += 1
            yield m.Progress(frames, total, f"pose {i + 1} frame {f + 1}")
            whole = [h for h in holes or [] if not getattr(h, "partial", False)
                     and getattr(h, "confidence", 1.0) >= settings.min_confidence]
            for k, (ex, ey) in expect.items():
                near = [h for h in whole if math.hypot(h.x_px - ex, h.y_px - ey) * s <= settings.accept_mm]
                if not near:
                    continue
                h = min(near, key=lambda h: math.hypot(h.x_px - ex, h.y_px - ey))
                tang.setdefault(k, []).append((h.x_px - cx) * s * 1e3)
                axial.setdefault(k, []).append((cy - h.y_px) * s * 1e3)
                tang_u.setdefault(k, []).append(_u_px(getattr(h, "x_u_px", None), settings) * s * 1e3)
                axial_u.setdefault(k, []).append(_u_px(getattr(h, "y_u_px", None), settings) * s * 1e3)
        grating[p] = float(np.mean(readings))

    found = np.array(sorted(tang), dtype=int)
    missed = [{"pose": int(design.pose[k]), "target": cert.targets[int(design.target[k])].id,
               "z_mm": float(design.z_mm[design.pose[k]]), "c_deg": float(design.c_deg[design.pose[k]])}
              for k in range(design.pose.size) if k not in tang]
    kept = Sightings(design.z_mm.copy(), design.c_deg % 360.0, design.pose[found], design.target[found])
    # a sighting's u: the mean of its frames' own (as ``scan.vision_u_px``: the frames of
    # one pose see the same wall, so their errors are not independent)
    obs = Observations(kept, grating, np.array([np.mean(tang[k]) for k in found]),
                       np.array([np.mean(axial[k]) for k in found]), reference_approaches=len(ref),
                       tangential_u_um=np.array([np.mean(tang_u[k]) for k in found]),
                       axial_u_um=np.array([np.mean(axial_u[k]) for k in found]))
    return CalibrationRun(obs, float(z_reference_mm), ref_um, missed, frames)


def _u_px(u: float | None, settings: MeasureSettings) -> float:
    """A reading's own u (px), else the fixed one."""
    return float(u) if u is not None and math.isfinite(u) and u > 0 else settings.vision_centre_u_px


async def run_calibration(session, cert: ArtefactCertificate, design: Sightings, z_reference_mm: float,
                          settings: MeasureSettings | None = None) -> tuple[CalibrationRun, dict | None]:
    """Run the plan on the session's station (homing first when needed); returns the
    run and its machine time at the axes' real speeds (``run_cycle``'s summary from
    the engine's ledger, None when it cannot be told)."""
    from station.inspection.service import motion_limits, run_cycle

    settings = settings or MeasureSettings()
    st = session.station
    geo = CameraGeometry(st.mm_per_px, st.frame_size_px[0], st.frame_size_px[1], cert.radius_mm)
    from station.inspection.service import ensure_ready

    # the readiness rules every job keeps (reset after a fault, home when idle)
    await ensure_ready(session.engine)
    engine = session.engine
    run = await engine.run(calibration_plan(cert, design, geo, z_reference_mm, settings, motion_limits(engine.devices)))
    try:
        cycle = run_cycle(engine.ledger.steps, engine.devices, settings.scan_settings(), st.time_scale)
    except Exception:  # noqa: BLE001 - the figure must not cost the run
        cycle = None
    return run, cycle
