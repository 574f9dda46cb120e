"""A synthetic whole-surface result (station.inspection.surface) with defects at known
places, for the store's, the API's and the panel's tests of the surface: a honed wall
(a cross-hatch and grain) with a dark mark painted at each defect's place, so a
picture shown with its markers can be checked against the places themselves.

The picture starts at 350 deg (the wall runs round through 0 to 350 again): defects at
355, 10 and 345 deg test the angle's wrap (x = ((angle - angle_from) mod 360) /
deg_per_px)."""

from __future__ import annotations

import math

import cv2
import numpy as np

from station.inspection.surface import SurfaceDefect, SurfacePicture, SurfaceResult

MM_PER_PX = 0.05
AXIAL_FROM_MM = 60.0
AXIAL_TO_MM = 100.0
ANGLE_FROM_DEG = 350.0
BORE_RADIUS_MM = 11.1
#: grey level of the painted defects (the wall is brighter: about 100..180)
DEFECT_GREY = 20

#: (id, kind, axial mm, angle deg, length mm, width mm, hole, zone, rejects)
DEFECTS = [
    ("d1", "pore", 65.000, 10.00, 0.30, 0.28, None, "seal_1", "pore over 0.2 mm in sealing zone seal_1"),
    ("d2", "pore", 72.500, 120.00, 0.15, 0.14, None, None, None),
    ("d3", "scratch", 80.000, 200.00, 2.00, 0.06, None, None, None),
    ("d4", "burr", 71.030, 12.00, 0.25, 0.08, "hole_1", None, "burr at compensating hole hole_1"),
    ("d5", "chip", 85.080, 192.00, 0.20, 0.10, "hole_2", None, None),
    ("d6", "pore", 95.000, 355.00, 0.10, 0.10, None, None, None),
    ("d7", "pore", 90.000, 345.00, 0.12, 0.12, None, None, None),
]


_BORE = """
[bore]
diameter_mm = 22.2
depth_mm = 120.0
[placement]
axial_mm = 0.5
angular_datum = "hole_1"
[[holes]]
id = "hole_1"
angle_deg = 0.0
diameter = { nominal = 0.7, tol = 0.125 }
position = { nominal = 71.03, tol = 0.1 }
"""

#: a part spec without [surface]: its surface has no criteria to judge (a job order or
#: the panel's job form asking for a surface scan of it is refused)
NO_SURFACE_SPEC = 'part_number = "NOSURF-1"' + _BORE


def band_spec(part_number: str, every_part: bool = False) -> str:
    """A part spec with both compensating holes and [surface] criteria over their band
    (62-92 mm: 4 rings of 6 frames), a seal zone at 63-70 mm with a 0.2 mm pore limit;
    ``every_part``: every part's surface is scanned (else only when a job order asks)."""
    return (f'part_number = "{part_number}"' + _BORE + """[[holes]]
id = "hole_2"
angle_deg = 0.0
diameter = { nominal = 0.7, tol = 0.125 }
position = { nominal = 85.19, tol = 0.1 }
[surface]
""" + ("every_part = true\n" if every_part else "") + """axial_from_mm = 62.0
axial_to_mm = 92.0
max_pore_mm = 0.4
max_scratch_mm = 2.0
max_burr_mm = 0.05
max_chip_mm = 0.1
[[surface.zones]]
id = "seal"
axial_from_mm = 63.0
axial_to_mm = 70.0
max_pore_mm = 0.2
""")


def synthetic_picture(seed: int = 7) -> SurfacePicture:
    width = round(2 * math.pi * BORE_RADIUS_MM / MM_PER_PX)
    height = round((AXIAL_TO_MM - AXIAL_FROM_MM) / MM_PER_PX)
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:height, 0:width].astype(np.float32)
    wall = 140 + 14 * np.sin((x + y) * 0.35) + 14 * np.sin((x - y) * 0.35) + rng.normal(0, 5, (height, width))
    image = np.clip(wall, 0, 255).astype(np.uint8)
    pic = SurfacePicture(image, MM_PER_PX, AXIAL_FROM_MM, ANGLE_FROM_DEG, BORE_RADIUS_MM)
    for _id, kind, axial, angle, length, width_mm, *_ in DEFECTS:
        px, py = pic.px_of(axial, angle)  # centres at integers
        c = (int(round(px * 16)), int(round(py * 16)))  # cv2's sub-pixel drawing: 4 fractional bits
        if kind == "scratch":  # a thin line across the honing, along the bore
            half = int(round(length / 2 / MM_PER_PX * 16))
            cv2.line(image, (c[0], c[1] - half), (c[0], c[1] + half), DEFECT_GREY,
                     max(1, round(width_mm / MM_PER_PX)), cv2.LINE_AA, shift=4)
        else:
            r = max(1.5, length / 2 / MM_PER_PX)
            cv2.circle(image, c, int(round(r * 16)), DEFECT_GREY, -1, cv2.LINE_AA, shift=4)
    return pic


def synthetic_surface(seed: int = 7, *, with_picture: bool = True) -> SurfaceResult:
    defects = [SurfaceDefect(i, kind, axial, angle, length, width, size_u_mm=0.02, position_u_mm=0.01,
                             confidence=0.97, hole=hole, zone=zone, frames=2, rejects=rejects,
                             truth={"kind": kind, "axial_mm": axial, "angle_deg": angle, "length_mm": length})
               for i, kind, axial, angle, length, width, hole, zone, rejects in DEFECTS]
    return SurfaceResult(defects, synthetic_picture(seed) if with_picture else None, frames=48, recentred=3,
                         axial_from_mm=AXIAL_FROM_MM, axial_to_mm=AXIAL_TO_MM, coverage=0.996,
                         notes=["frame 17 (z 82.5 mm, c 140 deg): glare, analysed in its neighbours' overlap"],
                         blur_px=1.21)


def store_surface_record(store, serial: str, surface: SurfaceResult | None, *, part: str = "ZDZG-22.2-12.3851",
                         result: str = "fail") -> str:
    """A complete inspection with one characteristic and the given surface, written as
    the StoreWriter writes one (the document with the truth, the picture as an image of
    the record, subject "surface", in the finish's commit); its id."""
    from station.inspection.writers import surface_fields
    from station.parts import load_part
    from station.store import Measurement

    spec = load_part(part)
    c = spec.characteristic("hole_1.diameter")
    iid = store.begin_inspection(part, serial=serial)
    store.finish(iid, "complete", result, "surface defects reject the part" if result == "fail" else None,
                 measurements=[Measurement.of(c, c.nominal, passed=True, uncertainty_k2=0.004)],
                 **surface_fields(surface))
    return iid
