"""A certified master part in the twin's world: the certificate's holes, made.

A real master differs from its certificate by its calibration's own error, which the
certificate states as U (k = 2). The twin's master is the certificate's values plus
one normal draw per value with the certificate's standard uncertainty (U / 2), cut at
U: the truth is known to the twin and to nobody else (docs/monitor.md).
"""

from __future__ import annotations

import numpy as np

from sim.world import HoleTruth, PartTruth


def master_part(cert, *, bore_diameter_mm: float, seed: int = 0) -> PartTruth:
    """The world's master part for a ``station.checks.master.MasterCertificate``."""
    rng = np.random.default_rng(seed)

    def made(value_mm: float, U_um: float) -> float:
        e_um = float(np.clip(rng.normal(0.0, U_um / 2.0), -U_um, U_um))
        return value_mm + e_um * 1e-3

    holes = tuple(HoleTruth(h.id, made(h.position_mm, h.position_U_um), h.angle_deg,
                            made(h.diameter_mm, h.diameter_U_um)) for h in cert.holes)
    return PartTruth(cert.master_id, bore_diameter_mm, holes)


def artefact_part(cert, *, seed: int = 0) -> PartTruth:
    """The world's calibration artefact for a ``station.calibration.artefact.ArtefactCertificate``:
    each target hole at its certified axial position and angle plus one normal draw with
    the certificate's standard uncertainty (U / 2), cut at U, as ``master_part`` makes a
    master. The angle's U is stated as arc length at the wall (um), so its draw is turned
    into an angle at the bore's radius. The truth is the twin's alone."""
    rng = np.random.default_rng(seed)
    r_mm = cert.bore_diameter_mm / 2.0

    def draw_um(U_um: float) -> float:
        return float(np.clip(rng.normal(0.0, U_um / 2.0), -U_um, U_um))

    holes = []
    for t in cert.targets:
        axial_mm = t.position_mm + draw_um(t.position_U_um) * 1e-3
        angle_deg = (t.angle_deg + np.degrees(draw_um(t.tangential_U_um) * 1e-3 / r_mm)) % 360.0
        holes.append(HoleTruth(t.id, axial_mm, float(angle_deg), t.diameter_mm))
    return PartTruth(cert.artefact_id, cert.bore_diameter_mm, tuple(holes))
