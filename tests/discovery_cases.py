"""Concealed-effect cases for the discovery tests: each hides known effects in a
realistic recording (station.discovery.synth) and says what discovery must find.

Parameters are chosen as on the station: a 120 mm Z axis with 0.3-0.5 um
repeatability, a C table with 0.4 arcsec; effect sizes a few times the noise,
not hundreds, so the tests fail when discovery is wrong.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from station.discovery.library import LocalDefect
from station.discovery.synth import Campaign, linear_model, rotary_campaign, rotary_model
from station.effects import Backlash, Eccentricity, Periodic, Scale, ThermalDrift, ThermalExpansion


@dataclass
class Case:
    name: str
    kind: str
    hidden: tuple
    campaign: Campaign
    verdict: str
    effects: tuple[str, ...]
    #: parameters compared with a relative tolerance of 25 % (period 5 %); phases
    #: and centres are compared absolutely (see tests/unit/test_discovery.py)
    model_sigma: float = 0.5
    notes: str = ""

    def model(self):
        return linear_model(self.model_sigma) if self.kind == "linear" else rotary_model(self.model_sigma)

    def with_seed(self, seed: int) -> "Case":
        return replace(self, campaign=replace(self.campaign, seed=seed))


CASES = [
    Case("backlash", "linear", (Backlash(3.0),), Campaign(sigma=0.5, phi=0.3),
         "explained", ("backlash",), notes="3 um reversal in 0.5 um AR(1) noise"),
    Case("drift_not_backlash", "linear", (ThermalDrift(5.0, 500.0),),
         Campaign(sigma=0.5, phi=0.3, dwell_s=8.0, pause_s=60.0),
         "explained", ("thermal_drift",),
         notes="warm-up drift; the - pass of every run is later than the + pass, so an ISO "
               "reversal analysis reports a reversal value B"),
    Case("scale_hides_periodic", "linear", (Scale(40.0), Periodic(5.0, 0.8, 0.4)),
         Campaign(sigma=0.3, phi=0.3, dense_runs=2, dense_span=(20.0, 60.0), dense_step=0.5),
         "explained", ("scale", "periodic"), model_sigma=0.3,
         notes="5 mm lead-screw error of 0.8 um under a 40 ppm (4.8 um over the travel) scale error"),
    Case("thermal_expansion", "linear", (ThermalExpansion(11.5),),
         Campaign(sigma=0.5, phi=0.3, temperature=(20.5, 24.5)),
         "explained", ("thermal_expansion",), notes="steel 11.5 ppm/K, 4 K warm-up logged"),
    Case("eccentricity", "rotary", (Eccentricity(4.0, 0.7),), rotary_campaign(sigma=0.4, phi=0.3),
         "explained", ("eccentricity",), model_sigma=0.4,
         notes="4 arcsec once-per-revolution on top of the monotone error the baseline carries"),
    Case("backlash_and_scale", "linear", (Backlash(2.5), Scale(-15.0)), Campaign(sigma=0.5, phi=0.3),
         "explained", ("backlash", "scale")),
    Case("local_defect", "linear", (LocalDefect(70.0, 4.0, 2.5),),
         Campaign(sigma=0.5, phi=0.3, n_targets=49),
         "explained", ("local_defect",),
         notes="a 2.5 um bump at 70 mm, outside the contract's vocabulary"),
    Case("clean", "linear", (), Campaign(sigma=0.5, phi=0.3), "no-mismatch", ()),
]
