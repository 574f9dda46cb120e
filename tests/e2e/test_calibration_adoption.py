"""Adopting a self-calibration (issue 21): on a world that differs from the station's
model, calibrate on the artefact, approve the proposal through the approval flow
(``Session.decide``), inspect the standard part: within 3 um of the twin's truth (goal
1 um), and no laser anywhere.

The world is a drawn one (``sim.worlds``: the station's model plus each term's
laser-campaign uncertainty, wear, a screw-lead error; its axial datum within the
master's U) whose slide has also been bent: its pitch EBZ grows by 0.5 arcsec per mm
above the artefact's first ring, which tilts the endoscope and moves the detection
point along the bore through its 11.1 mm offset, where the grating cannot see it. The
station's model does not know it, so the part's holes are read off by that much
before; the self-calibration sees EBZ, the proposal changes it, and after approval
the same inspection is back at the truth.
"""

from __future__ import annotations

import asyncio
from dataclasses import replace
from pathlib import Path

import numpy as np

from sim.worlds import draw_world_model, write_world_scenario
from station.calibration.artefact import load_artefact
from station.calibration.proposal import propose_from_calibration
from station.calibration.run import calibrate
from station.effects import ErrorCurve
from station.kinematics.model import load_model
from station.parts import load_part
from station.runtime import open_session

PART = "ZDZG-22.2-12.3851"
SEED = 5
#: the bend: EBZ's slope above the first ring (arcsec per mm)
BEND_ARCSEC_PER_MM = 0.5
Z_BEND_MM = 10.0


def bent_world():
    world = draw_world_model(SEED)
    mz = world.motions_of("Z")
    b = mz.b
    t = np.union1d(np.asarray(b.target), [Z_BEND_MM])
    dev = b.baseline(t) + BEND_ARCSEC_PER_MM * np.clip(t - Z_BEND_MM, 0.0, None)
    return replace(world, motions={**world.motions, "Z": replace(mz, b=ErrorCurve.table(t, dev, b.kind, b.effects))})


def knock_at_holes_um(world, holes_mm) -> np.ndarray:
    """What the bend alone moves the detection point along the bore at the holes (um)."""
    unbent = draw_world_model(SEED)
    z = np.asarray(holes_mm, dtype=float)
    c = np.zeros_like(z)

    def axial(m):
        return m.part_coordinates(m.errors(z, c).actual_point_mm)[0] * 1e3

    return axial(world) - axial(unbent)


def errors_um(outcome) -> dict[str, float]:
    assert outcome.state == "complete", outcome.reason
    return {c.id: (c.measured - c.true_value) * 1e3 for c in outcome.characteristics if c.id.endswith(".position")}


def test_adopting_the_calibration_brings_inspections_to_the_truth(tmp_path: Path):
    world = bent_world()
    scenario = write_world_scenario(tmp_path / "world", SEED, world_model=world)
    cert = load_artefact("CA-22.2-5x8")
    spec = load_part(PART)
    holes_mm = [h.position.nominal for h in spec.holes]
    knock = knock_at_holes_um(world, holes_mm)
    assert np.all(np.abs(knock) > 1.0)  # the bend is felt at the holes, and no sensor sees it

    async def go():
        async with open_session(None, scenario=scenario, time_scale=50.0, data_dir=tmp_path / "var") as s:
            assert s.station.model.name == load_model().name  # the station keeps its own model
            before = errors_um(await s.inspect(spec, "ADOPT-0"))
            out = await calibrate(s, cert, n_poses=40, seed=SEED, suggestions=False)
            p = await propose_from_calibration(s, out, cert.artefact_id,
                                               holes={h.id: (h.position.nominal, h.angle_deg) for h in spec.holes})
            version = s.model_version
            await s.decide(p.id, True, "engineer", "self-calibration")
            after = errors_um(await s.inspect(spec, "ADOPT-1"))
            return before, out, p, version, s.model_version, after

    before, out, p, v0, v1, after = asyncio.run(go())
    par, res = out.par, out.result
    # EBZ is seen, within 3u of the bent world's truth, and changed by the proposal
    ebz = [j for j, n in enumerate(par.names) if n.startswith("EBZ@")]
    assert all(res.observable[j] for j in ebz)
    assert all(abs(res.value[j] - out.truth[j]) <= 3.0 * res.u[j] for j in ebz), \
        [(par.names[j], res.value[j], out.truth[j], res.u[j]) for j in ebz]
    assert any(c.term.startswith("node.Z.EBZ(") for c in p.changes)
    assert v1 != v0
    # before: the bend's error (and the datum's, within the master's U); after: the truth
    worst_before = max(abs(v) for v in before.values())
    worst_after = max(abs(v) for v in after.values())
    assert worst_before > 0.5 * float(np.abs(knock).max()), (before, knock)
    assert worst_after <= 3.0, after  # the acceptance
    assert worst_after <= 1.0, after  # the goal
    assert worst_after < 0.5 * worst_before, (before, after)
    # what the proposal said approving it would do to the holes' readings is what it did
    moved = {c.rsplit(".", 1)[0]: after[c] - before[c] for c in before}
    assert set(p.expected_change_um) == set(moved) == {h.id for h in spec.holes}
    assert all(abs(p.expected_change_um[h] - moved[h]) < 1.0 for h in moved), (p.expected_change_um, moved)
