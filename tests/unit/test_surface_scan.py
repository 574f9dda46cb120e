"""The surface inspection's pieces (issue 23, part B): the part spec's [surface], the
coverage plan, the plan's messages, the stitched picture's geometry, the judging."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from station.inspection.scan import CameraGeometry, FrameObservation, HoleResult, ScanSettings, wrap_deg
from station.inspection.service import judge_surface, wants_surface
from station.inspection.surface import SurfaceDefect, SurfaceResult
from station.inspection.surface_scan import (SurfaceSettings, _Picture, _Sighting, camera_marks, coverage_plan,
                                             physical_limit, surface_scan)
from station.motion import AxisLimits
from station.parts import load_part
from station.parts.loader import PartSpecError, parse_part
from station.sequencer import messages as m

GEO = CameraGeometry(mm_per_px=0.01, width_px=1280, height_px=1024, bore_radius_mm=11.1)

SPEC = """
part_number = "T-SURF"
[bore]
diameter_mm = 22.2
depth_mm = 120.0
[[holes]]
id = "hole_1"
angle_deg = 0.0
diameter = { nominal = 0.7, tol = 0.125 }
position = { nominal = 71.03, tol = 0.1 }
[surface]
axial_from_mm = 60.0
axial_to_mm = 95.0
max_pore_mm = 0.4
max_burr_mm = 0.05
[[surface.zones]]
id = "seal"
axial_from_mm = 62.0
axial_to_mm = 70.0
max_pore_mm = 0.2
max_scratch_mm = 0.2
"""


def spec(text: str = SPEC):
    return parse_part(text, "t-surf.toml")


def covered(plan, geo: CameraGeometry, place: tuple[float, float], margin_mm: float) -> bool:
    """Whether some frame of the plan shows ``place`` at least ``margin_mm`` inside its edges."""
    fw, fh = geo.width_px * geo.mm_per_px, geo.height_px * geo.mm_per_px
    for a in plan.axials_mm:
        for g in plan.angles_deg:
            du = math.radians((place[1] - g + 180.0) % 360.0 - 180.0) * geo.bore_radius_mm
            if abs(place[0] - a) <= fh / 2 - margin_mm and abs(du) <= fw / 2 - margin_mm:
                return True
    return False


@pytest.mark.parametrize("band", [(0.0, 120.0), (60.0, 95.0), (10.0, 14.0), (0.0, 10.24)])
def test_the_coverage_plan_shows_every_place_of_the_band_with_the_overlap_and_uses_no_frame_too_many(band):
    o = SurfaceSettings().overlap_mm
    plan = coverage_plan(band, GEO, o)
    rng = np.random.default_rng(1)
    # the band's ends are the frames' edges (beyond is not asked for: the bore's end, or
    # another band); inside, every place lies half the overlap inside some frame: a pore
    # up to the overlap is whole in one
    pts = np.column_stack([rng.uniform(band[0] + o / 2, band[1] - o / 2, 4000), rng.uniform(0, 360, 4000)])
    assert all(covered(plan, GEO, tuple(p), o / 2 - 1e-9) for p in pts)
    # one ring or one column fewer cannot cover it with that overlap
    fw, fh = GEO.width_px * GEO.mm_per_px, GEO.height_px * GEO.mm_per_px
    cols = len(plan.angles_deg)
    assert (cols - 1) * (fw - o) < 2 * math.pi * GEO.bore_radius_mm
    rows = len(plan.axials_mm)
    assert rows == 1 or (rows - 1) * (fh - o) + o < band[1] - band[0]


def test_the_physical_limit_is_the_fewest_frames_with_one_column_turn_each():
    cam = SimpleNamespace(exposure_s=0.01, readout_s=0.03)
    lim = physical_limit((0.0, 120.0), GEO, 0.6, cam, AxisLimits(90.0, 720.0), 0.05)
    plan = coverage_plan((0.0, 120.0), GEO, 0.6)
    assert lim["frames"] == plan.frames == 13 * 6
    # a 60 deg column turn at 90 deg/s, 720 deg/s^2: 60/90 + 90/720 s
    assert lim["limit_s"] == pytest.approx(78 * 0.01 + 77 * (60 / 90 + 90 / 720 + 0.05))


def test_a_surface_table_is_validated_and_names_the_field():
    bad = SPEC.replace("axial_to_mm = 70.0", "axial_to_mm = 99.0")
    with pytest.raises(PartSpecError, match=r"surface\.zones\[0\]|surface.zones.0"):
        spec(bad)
    with pytest.raises(PartSpecError, match="max_pore_mm"):
        spec(SPEC.replace("max_pore_mm = 0.4", "max_pore_mm = 0.0"))
    with pytest.raises(PartSpecError, match="overlaps"):
        spec(SPEC + '[[surface.zones]]\nid = "seal_b"\naxial_from_mm = 69.0\naxial_to_mm = 75.0\n')
    with pytest.raises(PartSpecError, match="id of a hole"):
        spec(SPEC.replace('id = "seal"', 'id = "hole_1"'))
    with pytest.raises(PartSpecError, match="hole_1 .* outside the band"):
        spec(SPEC.replace("axial_to_mm = 95.0", "axial_to_mm = 70.5").replace("axial_to_mm = 70.0", "axial_to_mm = 70.4"))
    with pytest.raises(PartSpecError, match="unknown|Extra|extra"):
        spec(SPEC.replace("max_burr_mm = 0.05", "max_bur_mm = 0.05"))


def test_surface_characteristics_and_who_asks_for_the_scan():
    p = spec()
    assert [c.id for c in p.surface_characteristics()] == [
        "surface.pore", "surface.seal.pore", "surface.seal.scratch", "hole_1.burr"]
    assert wants_surface(p, None) is True  # every_part by default
    assert wants_surface(p, False) is False
    shipped = load_part("ZDZG-22.2-12.3851")
    assert wants_surface(shipped, None) is False and wants_surface(shipped, True) is True
    no_surface = spec(SPEC.split("[surface]")[0])
    assert wants_surface(no_surface, None) is False
    with pytest.raises(ValueError, match="no \\[surface\\]"):
        wants_surface(no_surface, True)


def _d(kind, axial, length, hole=None, zone=None):
    return SurfaceDefect("", kind, axial, 10.0, length, length / 2, 0.02, 0.01, 0.9, hole=hole, zone=zone)


def test_the_criteria_take_the_largest_defect_where_each_applies_and_name_what_breaks():
    p = spec()
    defects = [_d("pore", 65.0, 0.25, zone="seal"),  # over the zone's 0.2
               _d("pore", 80.0, 0.35),  # under the 0.4 elsewhere
               _d("scratch", 90.0, 3.0),  # no scratch limit outside the zone
               _d("burr", 71.3, 0.04, hole="hole_1")]
    out = {c.id: c for c in judge_surface(p, SurfaceResult(defects))}
    assert out["surface.seal.pore"].measured == 0.25 and not out["surface.seal.pore"].passed
    assert out["surface.pore"].measured == 0.35 and out["surface.pore"].passed
    assert out["surface.seal.scratch"].measured == 0.0 and out["surface.seal.scratch"].uncertainty_k2 is None
    assert out["hole_1.burr"].measured == 0.04 and out["hole_1.burr"].passed
    assert [d.rejects for d in defects] == ["surface.seal.pore", None, None, None]
    # a hole the scan did not find: its rim was never seen, its criterion has no value
    lost = {c.id: c for c in judge_surface(p, SurfaceResult([]), [HoleResult("hole_1", False)])}
    assert lost["hole_1.burr"].measured is None and not lost["hole_1.burr"].passed
    assert lost["surface.pore"].measured == 0.0 and lost["surface.pore"].passed


def test_the_plan_turns_the_table_forward_and_analyses_each_frame_while_the_axes_move():
    """The coverage plan driven message by message: one capture per frame of the plan,
    the table commanded ever forward, and each frame's analysis sent between the next
    move and its wait (hidden in the motion), the last one after."""
    p = spec()
    plan = coverage_plan(p.surface_band_mm(), GEO, SurfaceSettings().overlap_mm)
    log, result = _drive(surface_scan(load_ideal_model(), p, GEO,
                                      ScanSettings(), [HoleResult("hole_1", True, 71.03, 0.001, 0.7, 0.001, 0.0)]))
    captures = [i for i, x in enumerate(log) if isinstance(x, m.Capture)]
    assert len(captures) == plan.frames == result.frames
    c_targets = [x.position for x in log if isinstance(x, m.Move) and x.axis == "C"]
    assert all(b >= a for a, b in zip(c_targets, c_targets[1:]))
    assert c_targets[-1] - c_targets[0] >= 360.0 * (len(plan.axials_mm) - 1)
    analyses = [i for i, x in enumerate(log) if isinstance(x, m.MeasureSurface)]
    assert len(analyses) == plan.frames
    for cap, ana in zip(captures[:-1], analyses[:-1]):
        between = log[cap:ana]
        assert any(isinstance(x, m.Move) for x in between), "analysed before the next move was sent"
        assert not any(isinstance(x, m.Capture) for x in log[cap + 1:ana])
    assert analyses[-1] > captures[-1]
    assert result.coverage == 1.0 and result.defects == []


def load_ideal_model():
    from station.kinematics.model import load_model

    return load_model(None).without_errors()


def _drive(gen, defects=lambda n: []):
    """Run a surface scan plan message by message as the station would: the table at 0,
    a grey frame for every capture, ``defects(n)`` for the n-th ``MeasureSurface``
    (0-based). Returns the messages and the plan's result."""
    log = []
    reply = None
    image = np.full((GEO.height_px, GEO.width_px), 120, np.uint8)
    analysed = 0
    try:
        while True:
            msg = gen.send(reply)
            log.append(msg)
            reply = None
            if isinstance(msg, m.ReadAxis):
                reply = 0.0
            elif isinstance(msg, m.Capture):
                reply = SimpleNamespace(image=image)
            elif isinstance(msg, m.MeasureSurface):
                reply = defects(analysed)
                analysed += 1
    except StopIteration as stop:
        return log, stop.value


def _observation(edge_sigma_px):
    """A bore scan's measurement frame of a hole, with the vision stage's edge width."""
    return FrameObservation(71.03, 0.0, 0.7, 640.0, 512.0, 70.0, 0.95, 71.0, 71.0, 0.0,
                            edge_sigma_px=edge_sigma_px)


def test_every_frame_s_defects_get_the_camera_blur_the_bore_scan_read_at_the_holes_edges():
    """The camera's blur is the same in every frame of an inspection, but most coverage
    frames show no hole to read it from: the scan takes the median of the blur read at
    the found holes' edges in the bore scan's frames (``camera_blur_from_edge``; a frame
    without an edge width, and a hole not found, give none) and hands it to every
    ``MeasureSurface``, the coverage frames' and the re-centred ones' alike, and records
    it with the result. No edge measured: None, the detection reads the blur itself."""
    from station.vision.defects import Defect

    edges = [1.55, 1.60, 1.58, 1.62, 1.70]
    holes = [HoleResult("hole_1", True, 71.03, 0.001, 0.7, 0.001, 0.0,
                        frames=[_observation(e) for e in edges[:3]] + [_observation(None)]),
             HoleResult("hole_2", True, 85.19, 0.001, 0.7, 0.001, 0.0, frames=[_observation(e) for e in edges[3:]]),
             HoleResult("hole_3", False, frames=[_observation(3.0)])]
    want = float(np.median([math.sqrt(e * e - 1.0 - 1.0 / 6.0) for e in edges]))
    assert want == pytest.approx(1.1804, abs=1e-4)  # the median edge's, 1.60 px
    cx, cy = GEO.centre_px
    # a pore 400 px off the first frame's centre: measured again in a frame centred on it
    pore = Defect("pore", cx + 400.0, cy, 20.0, 15.0, 0.9, 0.0, 1.0, 1.0, 30.0, False, None, 0.2, 0.15, 0.2,
                  0.01, 0.01)
    p = spec()
    log, result = _drive(surface_scan(load_ideal_model(), p, GEO, ScanSettings(), holes),
                         defects=lambda n: [pore] if n == 0 else [])
    asked = [x for x in log if isinstance(x, m.MeasureSurface)]
    plan = coverage_plan(p.surface_band_mm(), GEO, SurfaceSettings().overlap_mm)
    assert len(asked) == plan.frames + result.recentred and result.recentred == 1
    assert all(x.blur_px == pytest.approx(want, rel=1e-12) for x in asked), {x.blur_px for x in asked}
    assert result.blur_px == pytest.approx(want, rel=1e-12) and result.to_json()["blur_px"] == result.blur_px
    assert any("blur 1.18 px" in x.text and "5 bore scan frame" in x.text for x in log if isinstance(x, m.Note))
    # the holes' frames without an edge width (a vision stage that gives none): no blur given
    bare = [HoleResult("hole_1", True, 71.03, 0.001, 0.7, 0.001, 0.0, frames=[_observation(None)] * 3)]
    for found in (bare, [HoleResult("hole_1", True, 71.03, 0.001, 0.7, 0.001, 0.0)], []):
        log, result = _drive(surface_scan(load_ideal_model(), p, GEO, ScanSettings(), found))
        asked = [x for x in log if isinstance(x, m.MeasureSurface)]
        assert asked and all(x.blur_px is None for x in asked)
        assert result.blur_px is None and result.to_json()["blur_px"] is None


def test_each_frame_is_told_where_the_part_s_holes_show_in_it():
    """``hole_places``: a found hole where the bore scan measured it (its radius plus
    ``hole_place_reach_mm``), put through the lens's distortion, so that the scan's own
    ``place`` takes it back to the hole; a hole the bore scan did not find over the band it
    was searched in; a hole out of the frame by more than its reach, left out. Every
    ``MeasureSurface`` of the scan carries them (the frames away from the holes: none)."""
    from station.inspection.surface_scan import _SurfaceScan
    from station.vision.calibration import CameraCalibration

    text = SPEC.replace("[surface]", """[[holes]]
id = "hole_2"
angle_deg = 180.0
diameter = { nominal = 0.7, tol = 0.125 }
position = { nominal = 85.19, tol = 0.1 }
[surface]""")
    cx, cy = GEO.centre_px
    lens = CameraCalibration(np.array([[1000.0, 0, cx], [0, 1000.0, cy], [0, 0, 1]]), np.array([-0.25, 0.08, 0.0, 0.0]),
                             (GEO.width_px, GEO.height_px), 0.0, GEO.mm_per_px)
    geo = CameraGeometry(GEO.mm_per_px, GEO.width_px, GEO.height_px, GEO.bore_radius_mm, calibration=lens)
    holes = [HoleResult("hole_1", True, 71.06, 0.001, 0.72, 0.001, 2.0), HoleResult("hole_2", False)]
    reach = SurfaceSettings().hole_place_reach_mm
    scan = _SurfaceScan(load_ideal_model(), spec(text), geo, ScanSettings(), SurfaceSettings(), None, holes)
    centre = (75.0, 358.0)  # hole_1 4 deg and 3.9 mm off the centre: in a corner, where the lens bends most
    (place,) = scan.hole_places(centre)
    ideal = (cx + math.radians(4.0) * GEO.bore_radius_mm / 0.01, cy + 3.94 / 0.01)
    assert math.hypot(place[0] - ideal[0], place[1] - ideal[1]) > 10.0  # the distortion is in it
    back = scan.place(centre, place[0], place[1])
    assert back[0] == pytest.approx(71.06, abs=1e-6) and math.radians(wrap_deg(back[1] - 2.0)) * 11.1 < 1e-6
    assert place[2] == pytest.approx((0.36 + reach) / 0.01)
    # hole_2, not found: at its drawing's place, reaching over its search band (the
    # position's tolerance and the part's axial placement, 0.5 mm; the drawing's 25 deg
    # and the fixture's 5)
    (place,) = scan.hole_places((85.0, 181.0))
    assert place[0] == pytest.approx(cx - math.radians(1.0) * GEO.bore_radius_mm / 0.01, abs=0.5)
    band = math.hypot(0.1 + 0.5, math.radians(25.0 + 5.0) * GEO.bore_radius_mm)
    assert place[2] == pytest.approx((0.825 / 2 + band + reach) / 0.01)
    assert scan.hole_places((20.0, 90.0)) == ()
    # the part's angle set by a datum hole: the found holes say it (hole_1 at 2 deg for
    # its drawing's 0), and the band is the drawing's alone; none found: all round
    datum = spec(text.replace("[surface]", '[placement]\nangular_datum = "hole_1"\n[surface]'))
    scan = _SurfaceScan(load_ideal_model(), datum, geo, ScanSettings(), SurfaceSettings(), None, holes)
    (hole_2,) = scan.unfound
    axial, angle, r = scan.search_band(hole_2)
    assert axial == pytest.approx(85.19) and angle == pytest.approx(182.0)
    assert r == pytest.approx(0.825 / 2 + math.hypot(0.6, math.radians(25.0) * GEO.bore_radius_mm))
    blind = _SurfaceScan(load_ideal_model(), datum, geo, ScanSettings(), SurfaceSettings(), None, [])
    assert [t.name for t in blind.unfound] == ["hole_1", "hole_2"]
    assert blind.search_band(blind.unfound[1])[2] > math.pi * GEO.bore_radius_mm
    # the whole scan: every frame's detection is told
    p = spec()
    log, _ = _drive(surface_scan(load_ideal_model(), p, GEO, ScanSettings(), holes[:1]))
    asked = [x for x in log if isinstance(x, m.MeasureSurface)]
    assert asked and all(x.hole_places is not None for x in asked)
    shown = [x for x in asked if x.hole_places]
    assert shown and all(len(x.hole_places) == 1 for x in shown) and len(shown) < len(asked)


def test_a_pore_of_a_hole_s_size_is_reported_with_a_note_naming_the_bore_scan_s_finding():
    """A pore at least the least hole's size (a disc at none of the part's holes) is
    reported as a pore with a note; where the bore scan found an unexpected hole at its
    place, the note says so. A smaller pore gets no note."""
    from station.inspection.scan import ScanFinding
    from station.vision.calibration import CameraCalibration
    from station.vision.defects import Defect

    cx, cy = GEO.centre_px
    lens = CameraCalibration(np.array([[1000.0, 0, cx], [0, 1000.0, cy], [0, 0, 1]]), np.zeros(4),
                             (GEO.width_px, GEO.height_px), 0.0, GEO.mm_per_px)
    geo = CameraGeometry(GEO.mm_per_px, GEO.width_px, GEO.height_px, GEO.bore_radius_mm, calibration=lens)
    big = Defect("pore", cx + 20.0, cy, 80.0, 70.0, 1.0, 0.0, 1.0, 1.0, 300.0, False, None, 0.8, 0.7, 0.8,
                 0.01, 0.01)
    small = Defect("pore", cx - 300.0, cy + 100.0, 30.0, 25.0, 1.0, 0.0, 1.0, 1.0, 80.0, False, None, 0.3, 0.25, 0.3,
                   0.01, 0.01)
    p = spec()
    plan = coverage_plan(p.surface_band_mm(), geo, SurfaceSettings().overlap_mm)
    where = (plan.axials_mm[0], (plan.angles_deg[0] + math.degrees(0.2 / GEO.bore_radius_mm)) % 360.0)
    finding = ScanFinding("unexpected_hole", "unexpected hole", None, where[0], where[1], 0.79, 0.01)
    for findings, named in (((), False), ((finding,), True)):
        _, result = _drive(surface_scan(load_ideal_model(), p, geo, ScanSettings(), [], findings=findings),
                           defects=lambda n: [big, small] if n == 0 else [])
        pores = sorted(result.defects, key=lambda d: d.length_mm)
        assert [d.kind for d in pores] == ["pore", "pore"] and pores[1].length_mm == pytest.approx(0.8, abs=0.01)
        notes = [n for n in result.notes if "the size of a hole" in n]
        assert len(notes) == 1 and "0.80 x 0.70 mm" in notes[0], result.notes
        assert ("the bore scan found it too, an unexpected hole of 0.790 mm" in notes[0]) == named


def test_the_station_s_defect_detection_is_given_the_camera_blur(monkeypatch):
    """``vision_defects`` (the engine's ``surface`` device) hands ``blur_px`` and the
    part's holes' places on to ``detect_defects``; without them, None (the frame reads
    the blur itself, and takes every dark disc of a hole's size for a hole)."""
    import station.vision.defects as defects
    from station.inspection.session import vision_defects

    calls = []

    def fake(image, mm_per_px, **kw):
        calls.append((image, mm_per_px, kw))
        return ["found"]

    monkeypatch.setattr(defects, "detect_defects", fake)
    surface = vision_defects(0.01)
    assert surface("frame", blur_px=1.17) == ["found"]
    assert surface("frame 2") == ["found"]
    assert surface("frame 3", hole_places=((10.0, 20.0, 45.0),)) == ["found"]
    assert calls == [("frame", 0.01, {"blur_px": 1.17, "hole_places": None}),
                     ("frame 2", 0.01, {"blur_px": None, "hole_places": None}),
                     ("frame 3", 0.01, {"blur_px": None, "hole_places": ((10.0, 20.0, 45.0),)})]


def test_the_picture_puts_a_mark_of_a_frame_at_its_place_on_the_part():
    """A frame with a dark dot at a known pixel, stitched: the picture's darkest spot is
    where px_of puts the dot's place on the part (within a picture pixel)."""
    p = spec()
    cfg = SurfaceSettings()
    plan = coverage_plan(p.surface_band_mm(), GEO, cfg.overlap_mm)
    pic = _Picture(plan, GEO, cfg)
    cx, cy = GEO.centre_px
    rng = np.random.default_rng(3)
    ring = 1
    centre = (plan.axials_mm[ring] + 0.003, plan.angles_deg[2] + 0.01)
    dot = (cx + 173.0, cy - 121.0)  # px in the frame: +x is +angle, -y is +axial
    img = np.clip(rng.normal(150, 3, (GEO.height_px, GEO.width_px)), 0, 255).astype(np.uint8)
    yy, xx = np.mgrid[0:GEO.height_px, 0:GEO.width_px]
    img[(xx - dot[0]) ** 2 + (yy - dot[1]) ** 2 <= 10 ** 2] = 20
    pic.add(img, centre[0], centre[1], ring)
    s = GEO.mm_per_px
    place = (centre[0] + (cy - dot[1]) * s, centre[1] + math.degrees((dot[0] - cx) * s / GEO.bore_radius_mm))
    x, y = pic.picture.px_of(*place)
    shown = pic.image.astype(float)
    shown[~pic.filled] = 255
    iy, ix = np.unravel_index(np.argmin(cv_blur(shown)), shown.shape)
    assert abs(ix - x) <= 1.0 and abs(iy - y) <= 1.0, (ix, iy, x, y)
    assert 0 < pic.coverage < 1


def cv_blur(a):
    import cv2

    return cv2.GaussianBlur(a, (0, 0), 1.5)


# ---------------------------------------------------------------- scratches longer than a frame
def _scan(calibrated: bool = True):
    """A coverage scan of SPEC's band, as the station holds it; ``calibrated``: with a lens
    calibration of no distortion (a piece's place is then its pixel's, exactly)."""
    from station.inspection.surface_scan import _SurfaceScan
    from station.vision.calibration import CameraCalibration

    geo = GEO
    if calibrated:
        cx, cy = GEO.centre_px
        lens = CameraCalibration(np.array([[1000.0, 0, cx], [0, 1000.0, cy], [0, 0, 1]]), np.zeros(4),
                                 (GEO.width_px, GEO.height_px), 0.0, GEO.mm_per_px)
        geo = CameraGeometry(GEO.mm_per_px, GEO.width_px, GEO.height_px, GEO.bore_radius_mm, calibration=lens)
    return _SurfaceScan(load_ideal_model(), spec(), geo, ScanSettings(), SurfaceSettings(), None, [])


def _bent_line(start_mm: tuple[float, float], orientation_deg: float, length_mm: float, bends=(0.012, -0.01)):
    """A scratch's centre line on the unrolled wall (arc mm from angle 0, axial mm), 0.01 mm
    apart: straight from ``start_mm`` along ``orientation_deg`` (from circumferential towards
    +axial), bent across in two sine modes of the given shares of its length."""
    t = np.arange(0.0, length_mm + 1e-9, 0.01)
    s = t / length_mm
    bend = length_mm * (bends[0] * np.sin(np.pi * s) + bends[1] * np.sin(2 * np.pi * s))
    a = math.radians(orientation_deg)
    return np.column_stack([start_mm[0] + t * math.cos(a) - bend * math.sin(a),
                            start_mm[1] + t * math.sin(a) + bend * math.cos(a)])


def _seen(line: np.ndarray, centre: tuple[float, float], width_mm: float = 0.04, cut_short_px: float = 20.0,
          with_line: bool = False):
    """What a frame centred at ``centre`` (axial mm, angle deg) reports of a scratch along
    ``line``: each run of it inside the frame as one straight piece (its centre line's
    middle, its chord's direction, its arc length), ``partial`` where the border cuts it, a cut end
    read ``cut_short_px`` short of the border (the detector reads an end from a strip
    across the furrow, which the border cuts). ``with_line``: each piece carries its
    centre line (``Defect.line_px``, a point every ~10 px), as the detector reports it."""
    from station.vision.defects import Defect

    s, r = GEO.mm_per_px, GEO.bore_radius_mm
    cx, cy = GEO.centre_px
    u0 = math.radians(centre[1]) * r
    circ = 2 * math.pi * r
    du = (line[:, 0] - u0 + circ / 2) % circ - circ / 2
    x, y = cx + du / s, cy - (line[:, 1] - centre[0]) / s
    inside = (x >= 0) & (x <= GEO.width_px - 1) & (y >= 0) & (y <= GEO.height_px - 1)
    out = []
    idx = np.flatnonzero(inside)
    if idx.size == 0:
        return out
    for run in np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1):
        cut_lo, cut_hi = run[0] > 0, run[-1] < len(line) - 1
        step = np.hypot(np.diff(x[run]), np.diff(y[run]))
        arc = np.concatenate([[0.0], np.cumsum(step)])
        keep = (arc >= (cut_short_px if cut_lo else 0.0)) & (arc <= arc[-1] - (cut_short_px if cut_hi else 0.0))
        if keep.sum() < 10:
            continue
        xs, ys = x[run][keep], y[run][keep]
        length = float(np.hypot(np.diff(xs), np.diff(ys)).sum())
        mid = int(np.searchsorted(arc[keep] - arc[keep][0], length / 2.0))  # its middle, on the bent line
        ang = math.degrees(math.atan2(ys[-1] - ys[0], xs[-1] - xs[0])) % 180.0
        u_len = math.hypot(1.5 * 0.5, 1.0, 0.03 * length)  # the detector's: its fit, its model, a share
        pts = None
        if with_line:
            k = np.unique(np.r_[np.arange(0, xs.size, 10), xs.size - 1])
            pts = tuple((float(a), float(b)) for a, b in zip(xs[k], ys[k]))
        out.append(Defect("scratch", float(xs[mid]), float(ys[mid]), length, width_mm / s, 0.9, ang, u_len, 0.3,
                          20.0, bool(cut_lo or cut_hi), None, length * s, width_mm, length * s, u_len * s, 0.003,
                          pts))
    return out


def _sightings(scan, lines, with_line: bool = False):
    from station.inspection.surface_scan import _Sighting

    cx, cy = GEO.centre_px
    out = []
    k = 0
    for axial in scan.plan.axials_mm:
        for angle in scan.plan.angles_deg:
            for line in lines:
                for d in _seen(line, (axial, angle), with_line=with_line):
                    ax, an = scan.place((axial, angle), d.x_px, d.y_px)
                    out.append(_Sighting(d, ax, an, math.hypot(d.x_px - cx, d.y_px - cy), k, (axial, angle)))
            k += 1
    return out


def _run(gen):
    try:
        while True:
            msg = next(gen)
            raise AssertionError(f"a calibrated join asked the station for {msg}")
    except StopIteration as stop:
        return stop.value


def _looking(scan, seen) -> list[tuple[float, float]]:
    """The scan's moves and frames stubbed: each look's centre recorded (returned, filled
    as the scan looks), its frame showing ``seen(centre)``."""
    looks: list[tuple[float, float]] = []

    def move(axial, angle, forward=False):
        looks.append((axial, angle % 360.0))
        return looks[-1]
        yield  # a generator, as the station's move is

    def frame(centre):
        return None, seen(centre)
        yield

    scan.move, scan.frame = move, frame
    return looks


def _run_looks(gen):
    """A plan that may take frames of its own: it asks the station only to checkpoint
    (the stubbed moves and frames of :func:`_looking` do the rest); its value."""
    try:
        while True:
            msg = next(gen)
            assert type(msg).__name__ == "Checkpoint", msg
    except StopIteration as stop:
        return stop.value


def _truth(line: np.ndarray, r: float) -> tuple[float, float, float]:
    """The line's arc length (mm) and middle (axial mm, angle deg): where the station
    places a scratch."""
    arc = float(np.hypot(*np.diff(line, axis=0).T).sum())
    u, v = line[len(line) // 2]
    return arc, float(v), math.degrees(u / r) % 360.0


@pytest.mark.parametrize("start, orientation, length, bends", [
    ((math.radians(195.0) * 11.1, 72.0), 5.0, 20.0, (0.012, -0.01)),   # round the bore across three columns' seams
    ((math.radians(100.0) * 11.1, 68.5), 80.0, 15.0, (0.012, -0.01)),  # along it across two rings' seams
    ((math.radians(340.0) * 11.1, 64.0), 40.0, 14.0, (0.012, -0.01)),  # across a corner of four frames, and 0 deg
    ((math.radians(150.0) * 11.1, 62.5), 65.0, 24.0, (0.03, 0.03)),    # bent hard (2.5 sigma of the twin's modes)
], ids=["round", "along", "diagonal", "bent"])
@pytest.mark.parametrize("with_line", [False, True], ids=["chords", "centre lines"])
def test_a_scratch_longer_than_a_frame_is_joined_from_its_pieces(start, orientation, length, bends, with_line):
    """A bent scratch that no frame sees whole: its pieces, each a straight chord of what
    one frame shows with its cut ends read short (or, as the detector reports them, with
    their centre lines), are joined into one scratch whose length and place are the
    line's (the chords miss the bend by a few hundredths)."""
    scan = _scan()
    line = _bent_line(start, orientation, length, bends)
    sightings = _sightings(scan, [line], with_line)
    assert len({sg.frame for sg in sightings}) >= 3 and all(sg.defect.length_mm < 13.0 for sg in sightings)
    chains, rest = scan.join_scratches(sightings)
    assert len(chains) == 1 and rest == [], (len(chains), len(rest))
    assert len(chains[0]) == len(sightings)
    d = _run(scan.measure_joined(chains[0]))
    arc, axial, angle = _truth(line, GEO.bore_radius_mm)
    assert d.kind == "scratch" and d.frames == len({sg.frame for sg in sightings})
    assert abs(d.length_mm - arc) <= max(0.005 * arc, 0.03), (d.length_mm, arc)
    assert abs(d.width_mm - 0.04) <= 0.002
    err = math.hypot(d.axial_mm - axial, math.radians((d.angle_deg - angle + 180) % 360 - 180) * GEO.bore_radius_mm)
    assert err <= 0.05 and err <= d.position_u_mm, (err, d.position_u_mm)
    assert abs(d.length_mm - arc) <= d.size_u_mm
    assert not scan.notes


@pytest.mark.parametrize("with_line", [False, True], ids=["chords", "centre lines"])
def test_pieces_of_other_scratches_are_not_joined(with_line):
    """Two parallel scratches 0.4 mm apart (within what a bend may put between two pieces
    of one) and one crossing them, all across the same seams: three scratches, each from
    its own pieces."""
    scan = _scan()
    r = GEO.bore_radius_mm
    a = _bent_line((math.radians(195.0) * r, 72.0), 5.0, 20.0, bends=(0.0, 0.0))
    b = _bent_line((math.radians(195.0) * r, 72.4), 5.0, 20.0, bends=(0.0, 0.0))
    c = _bent_line((math.radians(209.0) * r, 66.0), 85.0, 12.0)
    sightings = _sightings(scan, [a, b, c], with_line)
    chains, rest = scan.join_scratches(sightings)
    assert len(chains) == 3 and rest == []
    lengths = sorted(_run(scan.measure_joined(ch)).length_mm for ch in chains)
    truths = sorted(_truth(x, r)[0] for x in (a, b, c))
    assert np.allclose(lengths, truths, atol=0.05), (lengths, truths)


def test_a_scratch_bent_in_an_s_is_joined_by_its_pieces_centre_lines():
    """A long scratch bent in an S (3.5 % of its length in the second mode, as on a fresh
    whole-surface part where it was reported as two): the pieces' chords and middles miss
    one parabola by more than the bend allows, their centre lines agree where they overlap
    and continue each other across the gaps. Joined from the lines, its length and middle
    are the line's."""
    scan = _scan()
    r = GEO.bore_radius_mm
    line = _bent_line((math.radians(300.0) * r, 70.0), 15.0, 17.0, bends=(0.004, 0.035))
    chords = _sightings(scan, [line])
    chains, rest = scan.join_scratches(chords)
    assert not (len(chains) == 1 and rest == [])  # the chords' rule does not hold it together
    sightings = _sightings(scan, [line], with_line=True)
    chains, rest = scan.join_scratches(sightings)
    assert len(chains) == 1 and rest == [], (len(chains), len(rest))
    d = _run(scan.measure_joined(chains[0]))
    arc, axial, angle = _truth(line, r)
    assert abs(d.length_mm - arc) <= max(0.005 * arc, 0.03), (d.length_mm, arc)
    err = math.hypot(d.axial_mm - axial, math.radians((d.angle_deg - angle + 180) % 360 - 180) * r)
    assert err <= 0.05, err


def test_a_scratch_one_frame_saw_whole_is_left_to_the_merge():
    """A scratch across a seam that the neighbouring frame sees whole (the frames overlap
    by 0.6 mm) is not joined: the merge takes the whole sighting, as for a pore."""
    scan = _scan()
    plan = scan.plan
    fh = GEO.height_px * GEO.mm_per_px
    top_of_first = plan.axials_mm[0] + fh / 2.0  # the first ring's frames end here
    u = math.radians(plan.angles_deg[1]) * GEO.bore_radius_mm
    line = _bent_line((u, top_of_first - 1.0), 80.0, 1.3)  # runs past the first ring's edge, inside the second's
    assert line[-1, 1] > top_of_first and line[0, 1] > plan.axials_mm[1] - fh / 2.0 + 0.1
    sightings = _sightings(scan, [line])
    assert {sg.defect.partial for sg in sightings} == {False, True}
    chains, rest = scan.join_scratches(sightings)
    assert chains == [] and len(rest) == len(sightings)


def test_a_pore_beside_a_long_scratch_is_merged_apart_from_it():
    """Sightings of one defect lie within ``merge_mm`` plus half the longer's length of
    each other; a pore and a scratch, within ``merge_mm`` plus half the shorter's. With
    the longer's, a 0.28 mm pore 2.6 mm from a 4.9 mm scratch's middle (and clear of the
    scratch) was grouped with it and measured as the scratch alone (whole-surface seed
    24405). A pore read where a short scratch was seen from the next frame is still one
    defect with it, as is one on a long scratch's line at its end (a frame's border cut
    the end: seed 24402); two sightings of the long scratch are one."""
    from station.inspection.surface_scan import _Sighting
    from station.vision.defects import Defect

    scan = _scan()

    def sighting(kind, axial, angle, length_mm, frame):
        n = length_mm / GEO.mm_per_px
        d = Defect(kind, 640.0, 512.0, n, 3.0, 0.9, 90.0, 1.0, 0.3, 20.0, False, None, length_mm, 0.03,
                   length_mm, 0.01, 0.003)
        return _Sighting(d, axial, angle, 300.0, frame, (axial, angle))

    def groups(sgs):
        return sorted(sorted((sg.defect.kind, sg.frame) for sg in g) for g in scan.merge(sgs))

    per_deg = math.radians(1.0) * GEO.bore_radius_mm
    long_a = sighting("scratch", 57.34, 221.50, 4.81, 40)
    long_b = sighting("scratch", 57.34 + 0.1, 221.50 + 0.1 / per_deg, 4.80, 41)
    pore_a = sighting("pore", 54.87, 226.44, 0.27, 34)
    pore_b = sighting("pore", 54.89, 226.43, 0.26, 40)
    assert groups([long_a, long_b, pore_a, pore_b]) == [[("pore", 34), ("pore", 40)],
                                                        [("scratch", 40), ("scratch", 41)]]
    # a frame's border cutting the long scratch's end leaves a small "pore" on its line
    end = sighting("pore", 57.34 - 2.45, 221.50 + 0.05 / per_deg, 0.18, 30)
    assert groups([long_a, pore_a, end]) == [[("pore", 30), ("scratch", 40)], [("pore", 34)]]
    short = sighting("scratch", 30.0, 100.0, 0.40, 10)
    read_as_pore = sighting("pore", 30.05, 100.0 + 0.1 / per_deg, 0.30, 11)
    assert groups([short, read_as_pore]) == [[("pore", 11), ("scratch", 10)]]


def test_a_mark_seen_only_cut_by_frames_borders_and_not_in_a_frame_centred_on_it_is_not_reported():
    """A crossing of deep grooves cut by a coverage frame's top edge at its corner read as
    a 0.33 mm pore (whole-surface part 24703, 631 px off the frame's centre), and the
    frame centred on it showed nothing there; it was reported all the same, with the
    corner frame's figures. Seen only cut by borders and not at all centred, it is the
    border's mark: not reported, and a note says so. Seen whole somewhere, or shown
    centred (even cut there), it is reported as before."""
    from station.inspection.surface_scan import _Look, _Sighting
    from station.vision.defects import Defect

    def pore(partial, x=640.0, y=512.0):
        return Defect("pore", x, y, 33.0, 15.0, 0.9, 0.0, 1.0, 1.0, 39.0, partial, None, 0.33, 0.15, 0.33, 0.01,
                      0.01)

    place = (90.0, 140.0)
    for partial, shown, reported in ((True, [], False), (False, [], True), (True, [pore(True, 640.0, 1020.0)], False),
                                     (True, [pore(True, 641.0, 513.0)], True)):
        scan = _scan(calibrated=False)
        scan.looks.append(_Look(place[0], place[1], shown))
        sg = _Sighting(pore(partial, 1019.0, 8.0), place[0], place[1], 631.0, 74, (place[0] - 5.0, place[1] - 20.0))
        out = _run(scan.measure([sg]))
        assert (len(out) == 1) == reported, (partial, shown)
        if reported:
            assert out[0].kind == "pore" and abs(out[0].axial_mm - place[0]) < 0.02
        else:
            assert out == [] and any("not reported" in n for n in scan.notes), scan.notes


def test_a_defect_seen_whole_in_several_frames_takes_its_size_from_every_reading():
    """A 0.086 mm pore of a whole-surface part (seed 25601) read 0.060 mm (significance
    8.8) in the frame nearest its centre and 0.093 mm (23.5) in the other; the scan
    reported the first. Readings that agree are pooled (inverse-variance means, the
    mean's uncertainty widened by the Birge ratio over 1). Readings that disagree beyond
    ``pool_birge_max`` are not one quantity: where one frame saw it near its centre, the
    one with the most evidence is taken as read; where every frame saw it off its centre,
    a frame centred on it is taken and its reading reported (seed 88001: a 0.95 mm scratch
    read 0.80 and 0.93 mm in two frames' corners, the shorter the more significant). The
    place stays the chosen frame's; one reading alone is reported as read."""
    from station.inspection.surface_scan import _Sighting
    from station.vision.defects import Defect

    def pore(x, y, length_mm, u_mm, width_mm=0.05, significance=10.0):
        return Defect("pore", x, y, length_mm / 0.01, width_mm / 0.01, 0.9, 45.0, u_mm / 0.01, u_mm / 0.01,
                      significance, False, None, length_mm, width_mm, length_mm, u_mm, u_mm)

    cx, cy = GEO.centre_px
    place = (60.0, 140.0)

    def measured(first, second, r_near):
        scan = _scan(calibrated=True)
        a = _Sighting(first(cx - r_near, cy), place[0], place[1], r_near, 6, (place[0], place[1] + 3.0))
        b = _Sighting(second(cx + 597.0, cy), place[0] + 0.003, place[1], 597.0, 11, (place[0], place[1] - 3.0))
        (out,) = _run(scan.measure([a, b]))
        assert abs(out.axial_mm - place[0]) < 1e-6  # the nearer reading's place
        return out

    # the bench's pore: 2.2 of the Birge ratio apart. Seen near one frame's centre: the
    # stronger reading, as read
    out = measured(lambda x, y: pore(x, y, 0.060, 0.010, significance=8.8),
                   lambda x, y: pore(x, y, 0.093, 0.011, 0.06, significance=23.5), 150.0)
    assert (out.length_mm, out.width_mm, out.size_u_mm) == pytest.approx((0.093, 0.06, 0.022))
    # ... off every frame's centre: looked at again, centred, and that reading reported
    scan = _scan(calibrated=True)
    looks = _looking(scan, lambda _centre: [pore(cx + 2.0, cy - 1.0, 0.086, 0.008, 0.055, significance=20.0)])
    a = _Sighting(pore(cx - 547.0, cy, 0.060, 0.010, significance=8.8), place[0], place[1], 547.0, 6,
                  (place[0], place[1] + 3.0))
    b = _Sighting(pore(cx + 597.0, cy, 0.093, 0.011, 0.06, significance=23.5), place[0] + 0.003, place[1], 597.0,
                  11, (place[0], place[1] - 3.0))
    (out,) = _run_looks(scan.measure([a, b]))
    assert len(looks) == 1 and scan.wall_mm(looks[0], place) < 0.01
    assert (out.length_mm, out.width_mm, out.size_u_mm) == pytest.approx((0.086, 0.055, 0.016))
    assert scan.wall_mm((out.axial_mm, out.angle_deg), place) < 0.05
    for r_near in (547.0, 150.0):  # off every frame's centre (the calibrated choice), or centred in one
        # readings that agree: the mean, its own uncertainty
        out = measured(lambda x, y: pore(x, y, 0.080, 0.010), lambda x, y: pore(x, y, 0.082, 0.010, 0.06), r_near)
        assert out.length_mm == pytest.approx(0.081) and out.width_mm == pytest.approx(0.055)
        assert out.size_u_mm == pytest.approx(2.0 * 0.010 / math.sqrt(2.0))
        # readings within the pooling's reach but scattered (Birge ratio 1.41): the mean's
        # uncertainty widened to cover them
        out = measured(lambda x, y: pore(x, y, 0.080, 0.010), lambda x, y: pore(x, y, 0.100, 0.010), r_near)
        assert out.length_mm == pytest.approx(0.090) and out.size_u_mm == pytest.approx(0.020)
    # one reading alone: as read
    a = _Sighting(pore(cx - 547.0, cy, 0.060, 0.010), place[0], place[1], 547.0, 6, place)
    (one,) = _run(_scan(calibrated=True).measure([a]))
    assert one.length_mm == pytest.approx(0.060) and one.size_u_mm == pytest.approx(0.020)


def test_a_scratch_running_out_of_the_band_is_measured_as_far_as_the_band_shows_and_says_so():
    scan = _scan()
    lo, hi = scan.plan.band_mm
    r = GEO.bore_radius_mm
    line = _bent_line((math.radians(40.0) * r, hi - 14.0), 75.0, 20.0)
    sightings = _sightings(scan, [line])
    chains, _rest = scan.join_scratches(sightings)
    assert len(chains) == 1
    d = _run(scan.measure_joined(chains[0]))
    inside = line[line[:, 1] <= hi]
    assert abs(d.length_mm - _truth(inside, r)[0]) <= 0.3
    assert any("runs out of the scanned band" in n for n in scan.notes), scan.notes


def test_the_surface_bench_draws_long_scratches_in_the_band_clear_of_the_holes_and_across_the_hatch():
    """``station bench surface --long-scratches``: scratches of 3-25 mm, wholly in the band,
    1.5 mm clear of every hole's rim and 1 mm of each other, at least 10 deg off the hatch."""
    from sim.world import STANDARD_SAMPLE
    from station.bench.surface import LONG_SCRATCH_MM, random_defects

    band = (0.0, 120.0)
    r = STANDARD_SAMPLE.bore_diameter_mm / 2.0
    drawn = [d for seed in range(6) for d in random_defects(np.random.default_rng(seed), STANDARD_SAMPLE, band, 2, 1,
                                                             n_long=4) if d.name.startswith("long_")]
    assert len(drawn) >= 20
    assert max(d.length_mm for d in drawn) > 12.8  # longer than a frame
    for d in drawn:
        assert LONG_SCRATCH_MM[0] <= d.length_mm <= LONG_SCRATCH_MM[1] and d.kind == "scratch"
        t = np.linspace(-0.5, 0.5, 201) * d.length_mm
        axial = d.axial_mm + t * math.sin(math.radians(d.orientation_deg))
        arc = t * math.cos(math.radians(d.orientation_deg))
        assert band[0] < axial.min() and axial.max() < band[1]
        for h in STANDARD_SAMPLE.holes:
            du = (math.radians((d.angle_deg - h.angle_deg + 180) % 360 - 180) * r) + arc
            assert np.hypot(axial - h.axial_mm, du).min() > 1.5 + h.diameter_mm / 2 - 0.01
        off = min(abs((d.orientation_deg - g + 90) % 180 - 90) for g in (STANDARD_SAMPLE.hatch_deg,
                                                                           180 - STANDARD_SAMPLE.hatch_deg))
        assert off >= 10.0 - 1e-9


def test_a_scratch_a_frame_lost_is_followed_from_its_cut_ends_and_joined_whole():
    """The coverage frames lose the middle of a long scratch (on the twin: a stretch bent
    along the hatch, both its ends at a frame's border). Its neighbours' pieces end at
    their borders with nothing to continue them, so the scan takes a frame centred on each
    such end (``follow_scratches``): there the scratch runs through the middle, and its
    pieces join the rest into one scratch of the line's length. Without the followed
    frames the pieces stay apart."""
    from station.inspection.surface_scan import _Sighting

    scan = _scan()
    r = GEO.bore_radius_mm
    line = _bent_line((math.radians(282.0) * r, 70.0), 6.0, 24.0, bends=(0.004, 0.02))
    sightings = _sightings(scan, [line], with_line=True)
    # the column of frames that holds its middle loses it (each ring's frame there)
    middle = min(sightings, key=lambda sg: scan.wall_mm((sg.axial_mm, sg.angle_deg), _truth(line, r)[1:]))
    lost = [sg for sg in sightings if sg.centre[1] != middle.centre[1]]
    chains, rest = scan.join_scratches(lost)
    assert len(chains) + len([sg for sg in rest if sg.defect.kind == "scratch"]) >= 2  # broken where it was lost

    looks = _looking(scan, lambda centre: _seen(line, centre, with_line=True))
    extra = _run_looks(scan.follow_scratches(lost))
    assert extra and all(isinstance(sg, _Sighting) and sg.frame < 0 for sg in extra)
    assert 1 <= len(looks) <= scan.cfg.follow_max_looks
    assert any("follow" in n for n in scan.notes)
    chains, rest = scan.join_scratches(lost + extra)
    assert len(chains) == 1 and [sg for sg in rest if sg.defect.kind == "scratch"] == []
    d = _run(scan.measure_joined(chains[0]))
    arc, axial, angle = _truth(line, r)
    assert abs(d.length_mm - arc) <= max(0.005 * arc, 0.03), (d.length_mm, arc)
    err = math.hypot(d.axial_mm - axial, math.radians((d.angle_deg - angle + 180) % 360 - 180) * r)
    assert err <= 0.05, err


def _sighting(frame: int, kind: str, x: float, y: float, length: float = 10.0, angle: float = 0.0,
              place: tuple[float, float] | None = None):
    d = SimpleNamespace(kind=kind, x_px=x, y_px=y, length_px=length, angle_deg=angle)
    axial, around = place if place is not None else (frame * 3.0, frame * 20.0)
    return _Sighting(d, axial_mm=axial, angle_deg=around, r_px=0.0, frame=frame)


def test_a_mark_at_one_place_of_the_image_in_many_frames_moves_with_the_camera_and_is_set_aside():
    """A speck on the window reads as a pore at one image place in every frame, a trapped
    column as a scratch along it whose measured length varies; the part's own defects
    land anywhere in the image, two of them by chance near each other in two frames."""
    cfg = SurfaceSettings()
    speck = [_sighting(k, "pore", 655.0 + 0.8 * (k % 3), 336.0 - 0.5 * (k % 2), 13.0) for k in range(0, 40, 3)]
    column = [_sighting(k, "scratch", 22.0 + 0.3 * (k % 2), 120.0 + 0.5 * (270 - L) / 2.0, L, 90.0 + 0.4 * (k % 3))
              for k, L in ((1, 270.0), (4, 240.0), (7, 30.0), (10, 265.0))]
    part = [_sighting(2, "pore", 100.0, 100.0), _sighting(5, "pore", 102.0, 101.0),  # two frames: chance
            _sighting(8, "scratch", 500.0, 500.0, 200.0, 30.0), _sighting(11, "scratch", 503.0, 502.0, 190.0, 75.0),
            _sighting(14, "burr", 655.0, 336.0), _sighting(17, "pore", 900.0, 200.0)]
    marks, rest = camera_marks(speck + column + part, cfg, 11.1)
    assert sorted(len(g) for g in marks) == [len(column), len(speck)]
    assert {g[0].defect.kind for g in marks} == {"pore", "scratch"}
    assert rest == part
    # a second frame's sighting of one defect is not a mark (the frames look from other poses)
    assert camera_marks(part + [_sighting(2, "pore", 100.5, 100.0)], cfg, 11.1)[0] == []


def test_a_scratch_longer_than_several_frames_crosses_them_at_one_image_place_and_stays_the_parts():
    """A furrow along the bore's axis crosses the frames of consecutive rings at one angle
    at the same image place (cut by the top and bottom borders), one round the bore the
    frames of one ring; their places on the part lie along the scratch: the part's."""
    cfg = SurfaceSettings()
    axial = [_sighting(k, "scratch", 640.0, 512.0, 1024.0, 90.0, place=(5.0 + 9.2 * k, 47.0)) for k in range(4)]
    step = math.degrees(11.5 / 11.1)  # 11.5 mm round the bore between frames
    # its pieces read 0.5 and 179.7 deg alike: one direction
    around = [_sighting(10 + k, "scratch", 640.0, 300.0, 1280.0, (0.5, 179.7)[k % 2],
                        place=(60.0, (350.0 + k * step) % 360.0)) for k in range(4)]
    marks, rest = camera_marks(axial + around, cfg, 11.1)
    assert marks == [] and rest == axial + around
    # the same image place at places of the part that do not lie along it: the camera's
    scattered = [_sighting(k, "scratch", 640.0, 512.0, 1024.0, 90.0, place=(5.0 + 9.2 * k, 47.0 + 30.0 * k))
                 for k in range(4)]
    assert [len(g) for g in camera_marks(scattered, cfg, 11.1)[0]] == [4]


def test_a_mark_cut_by_frames_borders_that_a_centred_frame_shows_as_a_scratch_passing_is_not_reported_apart():
    """A scratch longer than a frame, its end cut by a frame's left border, read there as a
    0.15 mm "pore" (whole-surface part 90103, on a 22.7 mm scratch's line; the scratch was
    measured by its chain). A frame centred on the mark shows only the scratch passing,
    cut by that frame's borders too: the mark was the scratch's, and is not reported apart
    (a note says so). A scratch's own piece seen so is still reported, and a mark that the
    centred frame shows as a pore is that pore."""
    from station.inspection.surface_scan import _Sighting
    from station.vision.defects import Defect

    cx, cy = GEO.centre_px
    place = (28.26, 326.42)

    def mark(kind, x, y, length_px, partial, angle=27.0):
        mm = length_px * 0.01
        return Defect(kind, x, y, length_px, 5.0, 0.9, angle, 2.0, 1.0, 12.0, partial, None, mm, 0.05, mm, 0.02, 0.01)

    def measured(group_kind, look_defects):
        scan = _scan(calibrated=True)
        looks = _looking(scan, lambda _centre: look_defects)
        sg = _Sighting(mark(group_kind, 4.0, 931.0, 15.0 if group_kind == "pore" else 90.0, True), place[0],
                       place[1], 761.0, 18, (32.56, 0.0))
        out = _run_looks(scan.measure([sg]))
        assert len(looks) == 1
        return out, scan.notes

    passing = [mark("scratch", cx + 300.0, cy + 150.0, 1250.0, True)]  # its line through the centre
    out, notes = measured("pore", passing)
    assert out == [] and any("scratch's stretch" in n for n in notes), notes
    # the piece's middle by chance at the mark (the bench's part): the old rule took that
    # for the mark shown, and reported the "pore" as read off centre
    out, notes = measured("pore", [mark("scratch", cx + 5.0, cy + 3.0, 1250.0, True)])
    assert out == [] and any("scratch's stretch" in n for n in notes), notes
    out, notes = measured("scratch", passing)  # a scratch's piece: as read, off centre
    assert [d.kind for d in out] == ["scratch"] and any("not seen again re-centred" in n for n in notes), notes
    out, _notes = measured("pore", passing + [mark("pore", cx + 1.0, cy - 2.0, 15.0, False)])
    assert [d.kind for d in out] == ["pore"]
    out, notes = measured("pore", [])  # nothing there: the borders' cut
    assert out == [] and any("was not seen in a frame centred on it" in n for n in notes), notes


def test_the_rim_defects_of_a_pore_read_as_a_hole_are_not_reported():
    """A 0.49 mm pore read as a hole in one frame gave a "burr" and a "chip" on its outline
    (whole-surface part 91102), at none of the part's holes, while the pore itself was
    reported: the rim defects go, with a note. A rim defect at a hole, or at none of the
    part's holes and on no pore's outline (a hole drilled where the drawing has none),
    stays; so does one beyond the pore's outline."""
    from station.inspection.surface import SurfaceDefect

    scan = _scan(calibrated=True)
    r = GEO.bore_radius_mm

    def at(kind, axial, angle, length=0.15, hole=None):
        return SurfaceDefect("", kind, axial, angle, length, 0.03, 0.02, 0.02, 0.9, hole=hole)

    pore = at("pore", 77.333, 87.372, 0.488)
    burr = at("burr", 77.065, 87.93)
    chip = at("chip", 77.265, 88.60, 0.26)
    beyond = at("chip", 77.333, 87.372 + math.degrees(0.40 / r))  # 0.40 mm from its middle
    at_hole = at("burr", 71.38, 0.2, hole="hole_1")
    stray = at("burr", 30.0, 200.0)
    kept = scan.without_pores_rims([pore, burr, chip, beyond, at_hole, stray])
    assert kept == [pore, beyond, at_hole, stray]
    assert sum("outline of the 0.49 mm pore" in n for n in scan.notes) == 2, scan.notes


@pytest.mark.parametrize("with_line", [False, True], ids=["chords", "centre lines"])
def test_pieces_on_far_sides_of_the_bore_are_not_one_scratch(with_line):
    """Whole-surface part 91101: a piece of a 23.6 mm scratch (its middle at 131.7 deg)
    and a 0.9 mm piece of another scratch half the bore away (309-313.5 deg, 3 mm further
    along the bore). Placed from the first's middle the short way round, the second's
    ends fell 34 mm either side of it, the two "overlapped" seven times the shorter's
    length, and the long scratch was reported 32.8 mm long. Each piece is now unrolled
    along itself (``wall_path``): the pieces are 31 mm apart and stay apart; pieces of
    one scratch across the 0/360 deg seam still join."""
    from station.inspection.scan import wrap_deg
    from station.inspection.surface_scan import _Piece, _Sighting

    scan = _scan(calibrated=True)

    def piece(frame, a, b, partial):
        d = SimpleNamespace(kind="scratch", partial=partial, width_mm=0.03, width_px=3.0, length_px=100.0)
        mid = ((a[0] + b[0]) / 2.0, (a[1] + (wrap_deg(b[1] - a[1]) / 2.0)) % 360.0)
        line = None
        if with_line:
            t = np.linspace(0.0, 1.0, 21)
            line = tuple((a[0] + s * (b[0] - a[0]), (a[1] + s * wrap_deg(b[1] - a[1])) % 360.0) for s in t)
        return _Piece(_Sighting(d, mid[0], mid[1], 300.0, frame, mid), (a, b), ((0, 0), (0, 0)), (partial, False),
                      line)

    long_piece = piece(-1, (34.7836, 148.4962), (34.4083, 114.9813), True)
    short = piece(23, (37.6194, 313.5437), (37.4651, 309.0083), False)
    r = scan.misfit(long_piece, short)
    assert r is None or abs(r[0]) > r[1], r
    # one scratch across the seam: pieces of two frames, 0.2 mm apart along it
    a = piece(1, (50.0, 355.0), (50.2, 359.9), True)
    b = piece(2, (50.2, 0.9), (50.4, 6.0), True)
    r = scan.misfit(a, b)
    assert r is not None and abs(r[0]) <= r[1], r
