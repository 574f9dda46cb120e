"""bore_scan checked without hardware: the plan is fed its messages' answers by
station.sequencer.simulate (no engine, no event loop, no driver), and what it asked
for is checked -- moves within the Z travel, every frame taken at rest, settled and
with both axes arrived from below (the direction compensation was solved for), the
planned frames per hole, the search zones; check_limits refuses a plan that would
leave the travel. (Hole identity decisions are test_scan_identity.py's.)
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import pytest

from station.inspection.scan import CameraGeometry, ScanSettings
from station.inspection.service import hole_targets, scan_plan
from station.kinematics.model import load_model
from station.parts.loader import load_part
from station.parts.spec import PartSpec
from station.sequencer import messages as m
from station.sequencer.simulate import PlanOutOfLimits, SimWorld, check_limits, summarize_plan

GEO = CameraGeometry(0.010, 1280, 1024, 11.1)
#: the error-free model: the detection point is where the command puts it, so the
#: fake vision stage needs no kinematics (the compensated poses are checked below
#: with the station's own model)
IDEAL = load_model().without_errors()
SETTINGS = ScanSettings(frames_per_hole=3, settle_s=0.02)
STANDARD = load_part("ZDZG-22.2-12.3851")
Z_TRAVEL = IDEAL.z_travel_mm


def sees(holes, edge_sigma_px=None):
    """A vision stage for the ideal station: the true holes ``(axial mm, angle deg,
    diameter mm)`` whole in the frame taken at ``pose``, at their pixel places.
    ``edge_sigma_px``: each hole's edge profile width (px), in the holes' order; None:
    the measurements carry none."""
    cx, cy = GEO.centre_px
    s = GEO.mm_per_px

    def measure(pose):
        out = []
        for i, (axial, angle, d) in enumerate(holes):
            du = math.radians((angle - pose["C"] + 180.0) % 360.0 - 180.0) * GEO.bore_radius_mm
            x, y, r = cx + du / s, cy - (axial - pose["Z"]) / s, d / s / 2
            if r < x < GEO.width_px - 1 - r and r < y < GEO.height_px - 1 - r:
                edge = {} if edge_sigma_px is None else {"edge_sigma_px": edge_sigma_px[i]}
                out.append(SimpleNamespace(x_px=x, y_px=y, diameter_px=d / s, partial=False, confidence=0.95,
                                           diameter_u_px=0.02, y_u_px=0.02, **edge))
        return out

    return measure


def standard_world():
    return SimWorld({"Z": 0.0, "C": 0.0}, measure=sees([(71.03, 0.0, 0.70), (85.19, 0.0, 0.70)]))


def test_bore_scan_of_the_standard_part_asks_for_what_the_scan_must():
    summary = check_limits(scan_plan(IDEAL, STANDARD, GEO, SETTINGS), {"Z": Z_TRAVEL}, standard_world())
    result = summary.result
    assert [h.name for h in result.holes if h.found] == ["hole_1", "hole_2"], summary.describe()
    assert result.holes[0].position_mm == pytest.approx(71.03, abs=1e-9)

    # the hole search zones, in the order the plan searches: the datum survey round the
    # bore at hole_1's band, then hole_2's zone (hole_1's limits widened by 0.5 mm)
    assert summary.notes[0].startswith("angular datum: survey round the bore for hole_1")
    zone_notes = [n for n in summary.notes if "search zone" in n]
    assert [n.split(":")[0] for n in zone_notes] == ["hole_2"]
    t1, t2 = hole_targets(STANDARD)
    assert (t1.zone_axial_mm, t2.zone_axial_mm) == ((70.43, 71.63), (84.59, 85.79))

    # every frame: both axes at rest (their moves collected), settled, arrived from below
    assert summary.frames
    for f in summary.frames:
        assert f.moving == () and f.settled, f
        assert all(d == +1 for d in f.arrived.values()), f
    # a frame per planned pose: the survey frames at hole_1's band, hole_2's search
    # frames inside its zone, frames_per_hole at each measured hole (no re-centring
    # needed: the search frames are on the nominal places here)
    survey = [f for f in summary.frames if f.label == "hole_1 survey search"]
    search2 = [f for f in summary.frames if f.label == "hole_2 search"]
    measured = [f for f in summary.frames if f.label.endswith(" measure")]
    assert survey and all(t1.zone_axial_mm[0] <= f.pose["Z"] <= t1.zone_axial_mm[1] for f in survey)
    assert search2 and all(t2.zone_axial_mm[0] <= f.pose["Z"] <= t2.zone_axial_mm[1] for f in search2)
    assert len(survey) + len(search2) + len(measured) == len(summary.frames)
    assert len(measured) == 2 * SETTINGS.frames_per_hole
    assert summary.encoder_reads == len(measured)  # a grating reading with every measurement frame
    assert [p[:2] for p in summary.progress][-1] == (6, 6)
    # the survey turns the table once round, forward: 360 deg in equal columns
    angles = sorted({round(f.pose["C"], 6) for f in survey})
    assert len(angles) >= 2 and all(b > a for a, b in zip(angles, angles[1:]))


def test_each_measurement_frame_keeps_its_holes_edge_width_for_the_cameras_blur():
    """The vision stage's edge profile width of the hole (``edge_sigma_px``) goes with each
    measurement frame's observation: the coverage scan reads the camera's blur from it
    for its frames, most of which show no hole. A vision stage that gives none: None."""
    world = SimWorld({"Z": 0.0, "C": 0.0}, measure=sees([(71.03, 0.0, 0.70), (85.19, 0.0, 0.70)],
                                                        edge_sigma_px=(1.62, 1.71)))
    result = summarize_plan(scan_plan(IDEAL, STANDARD, GEO, SETTINGS), world).result
    h1, h2 = (h for h in result.holes if h.found)
    assert [f.edge_sigma_px for f in h1.frames] == [1.62] * SETTINGS.frames_per_hole
    assert [f.edge_sigma_px for f in h2.frames] == [1.71] * SETTINGS.frames_per_hole
    plain = summarize_plan(scan_plan(IDEAL, STANDARD, GEO, SETTINGS), standard_world()).result
    frames = [f for h in plain.holes for f in h.frames]
    assert len(frames) == 2 * SETTINGS.frames_per_hole and all(f.edge_sigma_px is None for f in frames)


def test_the_compensated_plan_stays_inside_the_z_travel_and_approaches_from_below():
    """The station's own model (errors and all): the commanded poses differ from the
    nominal ones, and still every Z command is inside the travel and every frame is
    reached moving positive on both axes. The world shows no hole: the plan searches
    everything it would."""
    model = load_model()
    summary = check_limits(scan_plan(model, STANDARD, GEO, SETTINGS), {"Z": model.z_travel_mm}, SimWorld())
    lo, hi = summary.span("Z")
    assert model.z_travel_mm[0] <= lo and hi <= model.z_travel_mm[1]
    assert not any(h.found for h in summary.result.holes)
    for f in summary.frames:
        assert f.moving == () and f.settled and f.arrived == {"Z": 1, "C": 1}, f


def test_check_limits_refuses_a_part_whose_hole_lies_beyond_the_z_travel():
    data = STANDARD.model_dump(mode="json")
    data["part_number"] = "TOO-DEEP"
    data["bore"]["depth_mm"] = 180.0
    data["holes"][1]["position"]["nominal"] = 160.0  # the Z travel ends at 150 mm
    data.pop("surface", None)  # its band (0..120 mm) would not hold that hole's rim
    deep = PartSpec.model_validate(data)
    with pytest.raises(PlanOutOfLimits) as info:
        check_limits(scan_plan(IDEAL, deep, GEO, SETTINGS), {"Z": Z_TRAVEL}, standard_world())
    assert all(v.move.axis == "Z" and v.move.target > Z_TRAVEL[1] for v in info.value.violations)
    assert "Z to 160.0000, outside its travel 0 .. 150" in str(info.value)


def corrupted(plan, nth_move: int, position: float):
    """``plan`` with its ``nth_move``-th Move of Z sent to ``position`` instead."""
    answer, k = None, 0
    while True:
        try:
            msg = plan.send(answer)
        except StopIteration as done:
            return done.value
        if isinstance(msg, m.Move) and msg.axis == "Z":
            if k == nth_move:
                msg = m.Move("Z", position, msg.wait, msg.velocity, msg.acceleration)
            k += 1
        answer = yield msg


@pytest.mark.parametrize("position", [150.2, -0.5, math.nan])
def test_a_corrupted_move_is_caught_and_named(position):
    plan = corrupted(scan_plan(IDEAL, STANDARD, GEO, SETTINGS), 2, position)  # the move to hole_2
    with pytest.raises(PlanOutOfLimits) as info:
        check_limits(plan, {"Z": Z_TRAVEL}, standard_world())
    (v,) = info.value.violations
    assert v.move.axis == "Z" and v.move.index == info.value.summary.moves_of("Z")[2].index


def test_unknown_message_is_refused_as_the_engine_refuses_it():
    def plan():
        yield m.Note("start")
        yield "not a message"

    with pytest.raises(TypeError, match="unknown message"):
        summarize_plan(plan())
