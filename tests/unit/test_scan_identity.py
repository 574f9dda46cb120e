"""Hole identity in the bore scan, tested by feeding the plan its messages' answers.

A small ideal station answers the plan: the axes go where they are told, the
error-free model puts the detection point at the command, and the "vision stage"
reports the whole holes of a frame at their exact pixel places (a false, unconfident
detection may be added, as the real vision stage gives for a blotch). So the
decisions of the plan (search zones, one physical hole per spec hole, the part's
angular datum, unexpected holes) are tested apart from pixels and drives; the
end-to-end cases with the twins are in tests/e2e/test_identity.py.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from station.inspection.scan import CameraGeometry, HoleTarget, ScanResult, ScanSettings, bore_scan
from station.inspection.service import hole_targets
from station.kinematics.model import load_model
from station.parts.spec import PartSpec
from station.sequencer import messages as m

GEO = CameraGeometry(0.010, 1280, 1024, 11.1)
MODEL = load_model().without_errors()
SETTINGS = ScanSettings(frames_per_hole=2, settle_s=0.0)


class IdealStation:
    """Answers a plan's messages for true holes ``(name, axial mm, angle deg, diameter mm)``."""

    def __init__(self, holes, *, c_start_deg=0.0, blotches=()):
        self.holes = list(holes)
        self.blotches = list(blotches)  # (axial, angle): dark patches the vision scores low
        self.pos = {"Z": 0.0, "C": c_start_deg}
        self.frames = 0
        self.moves = []
        self.shots = []  # the axes' positions at each frame

    def detections(self, z_mm, c_deg):
        cx, cy = GEO.centre_px
        s = GEO.mm_per_px
        out = []
        for name, axial, angle, d in self.holes + [("blotch", a, g, 0.6) for a, g in self.blotches]:
            du = math.radians((angle - c_deg + 180.0) % 360.0 - 180.0) * GEO.bore_radius_mm
            x, y, r = cx + du / s, cy - (axial - z_mm) / s, d / s / 2
            if x + r < 0 or x - r > GEO.width_px - 1 or y + r < 0 or y - r > GEO.height_px - 1:
                continue
            partial = x - r < 3 or y - r < 3 or x + r > GEO.width_px - 4 or y + r > GEO.height_px - 4
            out.append(SimpleNamespace(x_px=x, y_px=y, diameter_px=d / s, partial=partial,
                                       confidence=0.05 if name == "blotch" else 0.95,
                                       diameter_u_px=0.02, y_u_px=0.02, truth=name))
        return out

    def answer(self, msg):
        if isinstance(msg, m.Move):
            self.pos[msg.axis] = msg.position
            self.moves.append((msg.axis, msg.position))
            return None
        if isinstance(msg, m.ReadAxis):
            return self.pos[msg.axis]
        if isinstance(msg, m.ReadEncoder):
            return SimpleNamespace(position_mm=self.pos["Z"], timestamp=0.0)
        if isinstance(msg, m.Capture):
            self.frames += 1
            self.shots.append(dict(self.pos))
            # the "image" carries the pose it was taken at (2-D, as a crop slices it)
            return SimpleNamespace(image=np.array([[self.pos["Z"], self.pos["C"]]]))
        if isinstance(msg, m.Measure):
            return self.detections(float(msg.image[0, 0]), float(msg.image[0, 1]))
        return None


def run(plan, station) -> ScanResult:
    result = None
    while True:
        try:
            msg = plan.send(result)
        except StopIteration as done:
            return done.value
        result = station.answer(msg)


def spec(holes, *, datum="hole_1", placement=None, angle_tol=None) -> PartSpec:
    data = {"part_number": "TEST-1", "bore": {"diameter_mm": 22.2, "depth_mm": 120.0},
            "placement": {"axial_mm": 0.5, **({"angular_datum": datum} if datum else {}), **(placement or {})},
            "holes": [{"id": hid, "angle_deg": ang, "diameter": {"nominal": 0.7, "tol": 0.125},
                       "position": {"nominal": ax, "tol": 0.1},
                       **({"angle_tol_deg": angle_tol} if angle_tol else {})} for hid, ax, ang in holes]}
    return PartSpec.model_validate(data)


STANDARD = [("hole_1", 71.03, 0.0), ("hole_2", 85.19, 0.0)]


def inspect(part: PartSpec, world, **kw):
    station = IdealStation(world, **kw)
    plan = bore_scan(MODEL, hole_targets(part), GEO, SETTINGS, datum=part.placement.angular_datum,
                     placement_angle_deg=part.placement.angle_deg)
    return run(plan, station), station


def by_name(res: ScanResult):
    return {h.name: h for h in res.holes}


def nearest_truth(world, h):
    """The true hole nearest a measured one (by axial position and angle on the wall)."""
    def dist(t):
        du = math.radians((t[2] - h.angle_deg + 180) % 360 - 180) * GEO.bore_radius_mm
        return math.hypot(t[1] - h.position_mm, du)
    return min(world, key=dist)


def assert_own_values(res: ScanResult, world):
    """No spec hole carries another hole's values: each found hole is the true hole of
    its name, measured where it is."""
    for h in res.holes:
        if h.found:
            t = nearest_truth(world, h)
            assert t[0] == h.name, f"{h.name} carries the values of {t[0]}"
            assert h.position_mm == pytest.approx(t[1], abs=1e-6)
            assert h.diameter_mm == pytest.approx(t[3], abs=1e-6)


def test_good_part_both_holes_at_their_places():
    world = [("hole_1", 71.03, 0.0, 0.70), ("hole_2", 85.19, 0.0, 0.70)]
    res, _ = inspect(spec(STANDARD), world)
    assert all(h.found for h in res.holes)
    assert_own_values(res, world)
    assert [f.kind for f in res.findings] == ["datum"]
    assert res.datum_deg == pytest.approx(0.0, abs=1e-9)


def test_missing_hole_has_no_value_and_says_where_the_station_looked():
    # the issue's defect 1: a world with hole_1 only; hole_2 used to get hole_1's values
    world = [("hole_1", 71.044, 0.0, 0.712)]
    res, _ = inspect(spec(STANDARD), world)
    h = by_name(res)
    assert h["hole_1"].found and h["hole_1"].position_mm == pytest.approx(71.044, abs=1e-6)
    assert not h["hole_2"].found and math.isnan(h["hole_2"].position_mm)
    reason = h["hole_2"].reason
    assert "not found" in reason and "axial 84.590..85.790 mm" in reason
    assert " Z " in reason and " C " in reason  # the axes' ranges it looked at
    assert not [f for f in res.findings if f.kind == "unexpected_hole"]


def test_hole_round_the_bore_is_not_the_sought_one():
    # hole_2 at 187 deg on a part whose holes lie on one line: not hole_2, and hole_1's
    # values never appear under hole_2's name
    world = [("hole_1", 71.03, 0.0, 0.70), ("hole_2", 85.19, 187.0, 0.70)]
    res, _ = inspect(spec(STANDARD), world)
    h = by_name(res)
    assert h["hole_1"].found and not h["hole_2"].found
    assert_own_values(res, world)


@pytest.mark.parametrize("turn_deg", [37.0, 137.5, 251.0, 359.0])
def test_rotated_part_found_from_its_angular_datum(turn_deg):
    world = [("hole_1", 71.03, turn_deg, 0.70), ("hole_2", 85.19, (turn_deg + 12.0) % 360, 0.68)]
    part = spec([("hole_1", 71.03, 0.0), ("hole_2", 85.19, 12.0)], angle_tol=2.0)
    res, station = inspect(part, world, c_start_deg=400.0)
    assert all(h.found for h in res.holes)
    assert_own_values(res, world)
    assert res.datum_deg == pytest.approx(turn_deg, abs=1e-6)
    # the survey goes round once, forward from where the table stood
    survey = [shot["C"] for shot in station.shots[:7]]
    assert survey[0] == pytest.approx(400.0, abs=0.01)
    assert all(b > a for a, b in zip(survey, survey[1:]))
    assert survey[-1] - survey[0] < 360.0


def test_rotated_part_without_a_datum_is_looked_for_only_within_the_fixture_zone():
    world = [("hole_1", 71.03, 60.0, 0.70), ("hole_2", 85.19, 60.0, 0.70)]
    part = spec(STANDARD, datum=None, placement={"angle_deg": 3.0}, angle_tol=2.0)
    res, _ = inspect(part, world)
    assert not any(h.found for h in res.holes)
    assert all("angle 0.00 +/- 5.00 deg" in h.reason for h in res.holes)
    # a part within the fixture's zone is found
    world = [("hole_1", 71.03, 4.0, 0.70), ("hole_2", 85.19, 4.5, 0.70)]
    res, _ = inspect(part, world)
    assert all(h.found for h in res.holes)
    assert_own_values(res, world)


def test_datum_hole_missing_the_next_hole_sets_the_angle():
    world = [("hole_2", 85.19, 212.0, 0.70)]
    res, _ = inspect(spec(STANDARD), world)
    h = by_name(res)
    assert not h["hole_1"].found and "all round" in h["hole_1"].reason
    assert h["hole_2"].found and h["hole_2"].position_mm == pytest.approx(85.19, abs=1e-6)
    datum = [f for f in res.findings if f.kind == "datum"][0]
    assert datum.subject == "hole_2" and "was not found" in datum.message


def test_stray_drilling_near_a_hole_is_reported_not_taken():
    world = [("hole_1", 71.03, 100.0, 0.70), ("hole_2", 85.19, 100.0, 0.70), ("stray", 73.0, 101.0, 0.70)]
    res, _ = inspect(spec(STANDARD), world)
    assert all(h.found for h in res.holes)
    assert_own_values(res, world)
    stray = [f for f in res.findings if f.kind == "unexpected_hole"]
    assert len(stray) == 1 and stray[0].axial_mm == pytest.approx(73.0, abs=1e-6)
    assert stray[0].angle_deg == pytest.approx(101.0, abs=1e-6)


def test_stray_in_the_datum_band_is_told_apart_by_the_other_hole():
    # two holes in hole_1's band: the one under which hole_2 is where the drawing puts it
    world = [("hole_1", 71.03, 10.0, 0.70), ("hole_2", 85.19, 10.0, 0.70), ("stray", 71.03, 200.0, 0.70)]
    res, _ = inspect(spec(STANDARD, angle_tol=2.0), world)
    assert all(h.found for h in res.holes)
    assert_own_values(res, world)
    assert res.datum_deg == pytest.approx(10.0, abs=1e-6)
    assert [f.angle_deg for f in res.findings if f.kind == "unexpected_hole"] == [pytest.approx(200.0, abs=1e-6)]


def test_stray_in_the_datum_band_nothing_else_to_tell_is_ambiguous():
    world = [("hole_1", 71.03, 10.0, 0.70), ("stray", 71.03, 200.0, 0.70)]
    res, _ = inspect(spec([("hole_1", 71.03, 0.0)]), world)
    assert not res.holes[0].found and "angular datum not known" in res.holes[0].reason
    assert [f.kind for f in res.findings].count("ambiguous_identity") == 1


def test_a_blotch_is_not_a_hole():
    world = [("hole_1", 71.03, 0.0, 0.70), ("hole_2", 85.19, 0.0, 0.70)]
    res, _ = inspect(spec(STANDARD), world, blotches=[(71.2, 120.0), (87.0, 2.0)])
    assert all(h.found for h in res.holes)
    assert_own_values(res, world)
    assert not [f for f in res.findings if f.kind == "unexpected_hole"]


@pytest.mark.parametrize("axial_mm, found", [(71.61, True), (71.65, False), (70.45, True), (70.41, False)])
def test_zone_edges(axial_mm, found):
    # hole_1's zone: 70.93 .. 71.13 widened by 0.5 mm: 70.43 .. 71.63
    world = [("hole_1", axial_mm, 0.0, 0.70), ("hole_2", 85.19, 0.0, 0.70)]
    res, _ = inspect(spec(STANDARD, datum="hole_2"), world)
    h = by_name(res)["hole_1"]
    assert h.found is found
    if found:
        assert h.position_mm == pytest.approx(axial_mm, abs=1e-6)  # measured where it is
    else:
        assert "outside the zone" in h.reason
        assert [f.axial_mm for f in res.findings if f.kind == "unexpected_hole"] == [pytest.approx(axial_mm, abs=1e-6)]
    assert_own_values(res, world)


def test_two_holes_in_one_zone_the_one_in_tolerance_is_taken_else_none():
    world = [("hole_1", 71.05, 0.0, 0.70), ("hole_2", 85.19, 0.0, 0.70), ("extra", 71.50, 3.0, 0.70)]
    res, _ = inspect(spec(STANDARD, datum="hole_2"), world)
    assert by_name(res)["hole_1"].found
    assert_own_values(res, world)
    world = [("hole_1", 71.40, 0.0, 0.70), ("hole_2", 85.19, 0.0, 0.70), ("extra", 70.60, 3.0, 0.70)]
    res, _ = inspect(spec(STANDARD, datum="hole_2"), world)
    h = by_name(res)["hole_1"]
    assert not h.found and "is not known" in h.reason
    assert any(f.kind == "ambiguous_identity" and f.subject == "hole_1" for f in res.findings)


def test_one_physical_hole_is_never_two_spec_holes():
    # zones overlap (71.0 and 71.8, each widened by 0.5 mm); the one hole is nearer hole_b
    part = spec([("hole_a", 71.0, 0.0), ("hole_b", 71.8, 0.0)], datum=None)
    world = [("hole_b", 71.45, 0.0, 0.70)]
    res, _ = inspect(part, world)
    h = by_name(res)
    assert h["hole_b"].found and not h["hole_a"].found
    assert_own_values(res, world)


def test_zone_wraps_through_zero_degrees():
    world = [("hole_1", 71.03, 358.0, 0.70), ("hole_2", 85.19, 3.0, 0.70)]
    part = spec(STANDARD, datum=None, placement={"angle_deg": 3.0}, angle_tol=4.0)
    res, _ = inspect(part, world)
    assert all(h.found for h in res.holes)
    assert_own_values(res, world)
    assert by_name(res)["hole_1"].angle_deg == pytest.approx(358.0, abs=1e-6)


def test_unknown_datum_is_refused():
    with pytest.raises(ValueError, match="angular datum"):
        next(bore_scan(MODEL, [HoleTarget("a", 71.0)], GEO, SETTINGS, datum="b"))
