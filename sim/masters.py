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
