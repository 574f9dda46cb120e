"""Simulated measuring instruments: the laser interferometer and the rotary calibrator.

They measure the world as the real instruments would in an ISO 230-2 campaign and
write recordings in the contract's format (``station.recording``): the laser's
reflector rides the endoscope (body N) and reads its displacement along z in the
machine frame; the calibrator rides the table (body C) and reads its rotation.
Both are zeroed at the first target, as an operator zeroes them at the start.

Repeatability is applied per approach (one draw per target reached), which is what
an ISO 230-2 run's ``s`` estimates; AR(1) correlation between successive approaches
is available because real noise (air turbulence, thermal micro-drift) is correlated.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.world import World
from station.kinematics.rigid import ARCSEC_PER_RAD, angles_xyz, then_rotate_z
from station.recording import Recording


def iso230_sequence(targets, runs: int = 5, dwell_s: float = 2.0, speed: float = 10.0, overrun: float = 2.0):
    """Commanded moves of a standard ISO 230-2 campaign: ``runs`` bidirectional runs,
    each going up through the targets and back down (the linear-axis test cycle).
    Returns (time_s, run, direction, target) arrays; time includes travel and dwell."""
    targets = np.sort(np.asarray(targets, dtype=float))
    t = 0.0
    pos = targets[0] - overrun
    rows = []
    for run in range(1, runs + 1):
        for direction, seq in ((+1, targets), (-1, targets[::-1])):
            for x in seq:
                t += abs(x - pos) / speed + dwell_s
                pos = x
                rows.append((t, run, direction, x))
            # overrun past the end before reversing, as the standard asks
            end = seq[-1] + direction * overrun
            t += abs(end - pos) / speed
            pos = end
    a = np.array(rows)
    return a[:, 0], a[:, 1].astype(int), a[:, 2].astype(int), a[:, 3]


@dataclass
class LaserInterferometer:
    world: World
    sigma_um: float = 0.3
    ar1: float = 0.0
    seed: int = 0
    c_deg: float = 0.0  # table angle during the Z campaign

    def measure_z(self, time_s, run, direction, target_mm, approach_error_mm=None) -> Recording:
        """The laser's recording of the given approaches. ``approach_error_mm`` is the
        axis's own random error at each approach (``World.approach_error`` read while
        the axis stood there), which the laser sees like any other error."""
        rng = np.random.default_rng(self.seed)
        temp = self.world.temperature.at(time_s)
        model = self.world.model
        ctx = dict(direction_z=direction, time_s=time_s, temperature_c=temp)
        actual = model.body_pose("N", target_mm, self.c_deg, **ctx).p[..., 2]
        ideal = model.body_pose("N", target_mm, self.c_deg, ideal=True).p[..., 2]
        dev_um = (actual - ideal) * 1e3
        if approach_error_mm is not None:
            dev_um = dev_um + np.asarray(approach_error_mm, dtype=float) * 1e3
        dev_um = dev_um - dev_um[0] + _ar1_noise(rng, dev_um.size, self.sigma_um, self.ar1)
        return Recording(np.asarray(time_s, float), np.asarray(run), np.asarray(direction), np.asarray(target_mm, float),
                         dev_um, temperature_c=temp,
                         metadata={"axis": "Z", "kind": "linear", "instrument": "simulated laser interferometer"},
                         source="<simulated laser>")


@dataclass
class RotaryCalibrator:
    world: World
    sigma_arcsec: float = 0.5
    ar1: float = 0.0
    seed: int = 0

    def measure_c(self, time_s, run, direction, target_deg) -> Recording:
        rng = np.random.default_rng(self.seed)
        temp = self.world.temperature.at(time_s)
        pose = self.world.model.body_pose("C", 0.0, target_deg, direction_c=direction, time_s=time_s, temperature_c=temp)
        # rotation about z beyond the commanded angle: the angle of R_actual Rz(-C)
        R = then_rotate_z(pose, -np.radians(np.asarray(target_deg, float))).R
        dev = angles_xyz(R)[..., 2] * ARCSEC_PER_RAD
        dev = dev - dev[0] + _ar1_noise(rng, dev.size, self.sigma_arcsec, self.ar1)
        return Recording(np.asarray(time_s, float), np.asarray(run), np.asarray(direction), np.asarray(target_deg, float),
                         dev, temperature_c=temp,
                         metadata={"axis": "C", "kind": "rotary", "instrument": "simulated rotary calibrator"},
                         source="<simulated calibrator>")


def _ar1_noise(rng, n: int, sigma: float, phi: float) -> np.ndarray:
    """Stationary AR(1) noise with marginal standard deviation ``sigma``."""
    e = rng.normal(0.0, sigma * np.sqrt(1.0 - phi**2), n)
    out = np.empty(n)
    prev = rng.normal(0.0, sigma)
    for i in range(n):
        prev = phi * prev + e[i]
        out[i] = prev
    return out
