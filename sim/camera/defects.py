"""Surface defects of the honed bore wall, as the camera twin renders them (issue 23).

Why: a surface inspection can only be judged against frames whose defects are known
to the micrometre. Each defect here is a geometric outline in *ideal* pixel
coordinates (the same coordinates as the holes of ``sim.camera.render``) plus a
reflectance; ``render.render_frame`` paints it into the wall's radiance before the
lens blur, the vignetting and the sensor noise are applied, exactly as it paints the
holes. So every effect that hides or distorts a hole's edge hides or distorts a
defect's too, and the truth given here is the outline's own, not a detector's view
of it.

The four kinds and what light does to them (a side-view endoscope with a ring light,
nearly coaxial with the camera):

* **pore**: a cavity of the casting opened by the honing. Its floor is in shadow:
  dark, like a hole's far side, reflectance 0.15-0.6 of the wall (contrast 40-85 %,
  the holes' range). Gas pores are roundish, shrinkage pores ragged: an ellipse of
  aspect 1-1.6 with harmonics 3-8 of random phase (a star-shaped outline).
  ``length`` is the largest dimension (the greatest Feret diameter, what porosity
  specifications limit: "no pore over 0.2 mm"), ``width`` the extent across it.
* **scratch**: a furrow ploughed across the honing pattern (a chip dragged by the
  tool's retraction, an assembly mishap). Its floor is smooth (the cross-hatch is cut
  away) and its flanks shade it: the local wall's smooth level times a reflectance of
  0.4-0.8. A gently bent centre line (1-2 % of its length), a width that varies by
  about 15 % along it, square ends. ``length`` is the centre line's arc length,
  ``width`` the mean width.
* **burr**: metal pushed over a hole's edge by the drill's exit, standing into the
  hole's dark disc. It is the wall's metal, torn rather than honed (no cross-hatch:
  the wall's smooth level), facing the light a little differently: reflectance
  0.9-1.15 of the wall's level. A ragged
  intrusion: its height (radial, into the hole) varies by about 30 % along the rim on a
  scale of 1.5 px. ``length`` is its arc length along the rim, ``width`` its mean
  height, ``height_max`` its greatest.
* **chip**: a bit of the rim broken out, a notch in the wall at the hole's edge. The
  broken face slopes down into the hole and is in shadow: the hole's own level, or a
  little above it. ``length`` along the rim, ``width`` the mean depth of the notch.

Each defect's irregular shape comes from its own ``shape_seed`` (never from the
frame's random stream), so a frame rendered with defects has the very same wall, hole
levels, blur and noise as the frame rendered without them: their difference is the
defects alone, and a frame without defects is byte-identical to what the renderer
gave before defects existed.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np
from scipy.ndimage import gaussian_filter1d

KINDS = ("pore", "scratch", "burr", "chip")
#: kinds that sit on a hole's rim and need the hole they belong to
RIM_KINDS = ("burr", "chip")

#: harmonics of a pore's outline beyond the ellipse, and their RMS relative amplitude
#: at harmonic 3 (falling as 3/k): enough to make shrinkage-like ragged outlines (the
#: largest dimension differs from an ellipse's by up to ~10 %), mild enough to keep the
#: outline star-shaped round its centroid
PORE_HARMONICS = range(3, 9)
PORE_IRREGULARITY = 0.05
#: a scratch's centre line bends by this share of its length (RMS of the two modes);
#: a dragged chip's path is nearly straight over a few millimetres
SCRATCH_BEND = 0.012
#: a scratch's width varies along it by this share (RMS), on this scale (px)
SCRATCH_WIDTH_VARIATION, SCRATCH_WIDTH_SCALE_PX = 0.15, 8.0
#: a rim defect's height varies along the rim by this share (RMS), on this scale (px):
#: a burr is ragged (torn metal), a chip's fracture a little less so
RIM_ROUGHNESS = {"burr": 0.3, "chip": 0.2}
RIM_ROUGHNESS_SCALE_PX = 1.5
#: the default reflectances (share of the wall's level) when a scenario names none:
#: the middle of the ranges above; a chip's default is its hole's own level
DEFAULT_REFLECTANCE = {"pore": 0.35, "scratch": 0.65, "burr": 1.0, "chip": None}


@dataclass(frozen=True)
class DefectSpec:
    """One defect to render, in ideal pixel coordinates.

    ``kind``: pore | scratch | burr | chip.
    Pore and scratch: ``x_px``, ``y_px`` the centroid of its area, ``angle_deg`` the
    direction of its length (from +x towards +y, the image's sense), ``length_px`` and
    ``width_px`` as the module says (a pore's width is approximate: its outline is
    scaled so that its largest dimension is exactly ``length_px``).
    Burr and chip: ``hole`` the index of its hole in the frame's hole list,
    ``angle_deg`` where round the hole its middle is (image sense, from the hole's
    centre), ``length_px`` its arc along the rim, ``width_px`` its mean height (depth);
    ``x_px``/``y_px`` are not used.
    ``reflectance``: the defect's radiance as a share of the wall's (None: the kind's
    default). ``shape_seed``: its irregular outline.
    """

    kind: str
    x_px: float = 0.0
    y_px: float = 0.0
    length_px: float = 20.0
    width_px: float = 20.0
    angle_deg: float = 0.0
    reflectance: float | None = None
    hole: int | None = None
    shape_seed: int = 0

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"defect kind {self.kind!r}: one of {', '.join(KINDS)}")
        if not (self.length_px > 0 and self.width_px > 0):
            raise ValueError(f"{self.kind}: length and width must be positive")
        if self.kind in RIM_KINDS and self.hole is None:
            raise ValueError(f"a {self.kind} sits on a hole's rim: give its hole")


@dataclass(frozen=True)
class DefectTruth:
    """Ground truth of one rendered defect (ideal pixel coordinates, as ``HoleTruth``).

    ``x_px``/``y_px``: the centroid of its area (a rim defect's: the middle of its arc,
    half its mean height into the hole for a burr, out of it for a chip); ``image_*``
    where the lens puts that point on the sensor; ``length_px``/``width_px`` as the
    module defines them per kind; ``angle_deg`` the direction of the length (a rim
    defect's: where round its hole); ``height_max_px`` a rim defect's greatest height;
    ``area_px2`` the area of its outline; ``partial`` when it is cut by the frame's
    border. The millimetre and part-frame fields are filled by whoever knows the
    scale and where the camera looked (``random_defect_frame``, the camera twin).
    """

    kind: str
    x_px: float
    y_px: float
    length_px: float
    width_px: float
    angle_deg: float
    area_px2: float
    image_x_px: float = 0.0
    image_y_px: float = 0.0
    hole: int | None = None
    height_max_px: float | None = None
    partial: bool = False
    length_mm: float | None = None
    width_mm: float | None = None
    name: str | None = None
    axial_mm: float | None = None
    part_angle_deg: float | None = None

    def with_scale(self, mm_per_px: float) -> "DefectTruth":
        return replace(self, length_mm=self.length_px * mm_per_px, width_mm=self.width_px * mm_per_px)


def _smooth_noise(rng: np.random.Generator, n: int, scale_samples: float) -> np.ndarray:
    """Unit-RMS Gaussian noise correlated over ``scale_samples`` (periodic if wrapped)."""
    z = gaussian_filter1d(rng.standard_normal(n), max(scale_samples, 0.5), mode="wrap")
    return z / max(float(z.std()), 1e-9)


def feret(x: np.ndarray, y: np.ndarray, step_deg: float = 0.25) -> tuple[float, float, float]:
    """Greatest Feret diameter of a point set, its direction (deg) and the extent across it."""
    a = np.deg2rad(np.arange(0.0, 180.0, step_deg))
    proj = np.cos(a)[:, None] * x[None, :] + np.sin(a)[:, None] * y[None, :]
    ext = proj.max(axis=1) - proj.min(axis=1)
    i = int(np.argmax(ext))
    across = -np.sin(a[i]) * x + np.cos(a[i]) * y
    return float(ext[i]), float(np.rad2deg(a[i])), float(across.max() - across.min())


@dataclass
class DefectGeometry:
    """A defect's outline: which ideal points lie inside it, where its box is, its truth.

    ``inside(xu, yu)`` is vectorised over any array shape; ``near(xu, yu)`` marks the
    points within ``margin`` px of the outline (where a pixel may be cut by it, so the
    renderer supersamples there).
    """

    spec: DefectSpec
    hole_xy_r: tuple[float, float, float, float, float] | None = None  # cx, cy, a, b, angle_deg

    # ------------------------------------------------------------ shapes
    @cached_property
    def _pore(self):
        s = self.spec
        rng = np.random.default_rng(s.shape_seed)
        th = np.linspace(0.0, 2 * np.pi, 720, endpoint=False)
        a, b = s.length_px / 2.0, min(s.width_px, s.length_px) / 2.0
        r = a * b / np.sqrt((b * np.cos(th)) ** 2 + (a * np.sin(th)) ** 2)
        rel = np.zeros_like(th)
        for k in PORE_HARMONICS:
            amp = PORE_IRREGULARITY * 3.0 / k
            rel += rng.normal(0.0, amp) * np.cos(k * th) + rng.normal(0.0, amp) * np.sin(k * th)
        r = r * np.clip(1.0 + rel, 0.6, 1.4)
        x, y = r * np.cos(th), r * np.sin(th)
        length, direction, _ = feret(x, y)
        scale = s.length_px / length
        r, x, y = r * scale, x * scale, y * scale
        # the centroid of the polygon's area (shoelace), which is placed at (x_px, y_px)
        x2, y2 = np.roll(x, -1), np.roll(y, -1)
        cross = x * y2 - x2 * y
        area = cross.sum() / 2.0
        gx, gy = ((x + x2) * cross).sum() / (6 * area), ((y + y2) * cross).sum() / (6 * area)
        t = np.deg2rad(s.angle_deg)
        # the outline in the frame: rotated by the spec's angle, centroid on the spec's centre
        ox = s.x_px - (gx * np.cos(t) - gy * np.sin(t))
        oy = s.y_px - (gx * np.sin(t) + gy * np.cos(t))
        fx, fy = ox + x * np.cos(t) - y * np.sin(t), oy + x * np.sin(t) + y * np.cos(t)
        length, direction, width = feret(fx - s.x_px, fy - s.y_px)
        return dict(th=th, r=r, ox=ox, oy=oy, t=t, area=area, length=length, width=width, direction=direction,
                     outline=(fx, fy))

    def scratch_middle_px(self) -> tuple[float, float]:
        """A scratch's centre line's middle, as it is bent (ideal px)."""
        g = self._scratch
        i = len(g["sg"]) // 2
        tx, ty, nx, ny = g["t"]
        return (float(g["ox"] + g["sg"][i] * tx + g["bend"][i] * nx),
                float(g["oy"] + g["sg"][i] * ty + g["bend"][i] * ny))

    def scratch_ends_px(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """A scratch's centre line's two ends (ideal px)."""
        g = self._scratch
        tx, ty, nx, ny = g["t"]
        return tuple((float(g["ox"] + g["sg"][i] * tx + g["bend"][i] * nx),
                      float(g["oy"] + g["sg"][i] * ty + g["bend"][i] * ny)) for i in (0, -1))

    @cached_property
    def _scratch(self):
        s = self.spec
        rng = np.random.default_rng(s.shape_seed)
        step = 0.5
        n = int(np.ceil(s.length_px / step)) + 1
        sg = np.linspace(-s.length_px / 2, s.length_px / 2, n)
        u = sg / s.length_px + 0.5  # 0..1 along
        c1, c2 = rng.normal(0.0, SCRATCH_BEND, 2)
        bend = s.length_px * (c1 * np.sin(np.pi * u) + c2 * np.sin(2 * np.pi * u))
        variation = SCRATCH_WIDTH_VARIATION * _smooth_noise(rng, n, SCRATCH_WIDTH_SCALE_PX / step)
        width = s.width_px * np.clip(1.0 + variation, 0.5, 1.5)
        width *= s.width_px / width.mean()  # the spec's width is the mean width
        t = np.deg2rad(s.angle_deg)
        tx, ty, nx, ny = np.cos(t), np.sin(t), -np.sin(t), np.cos(t)
        # the point that goes to (x_px, y_px) is the centroid of the area (weight = width)
        cb = float((width * bend).sum() / width.sum())
        ox, oy = s.x_px - cb * nx, s.y_px - cb * ny
        px, py = ox + sg * tx + bend * nx, oy + sg * ty + bend * ny
        arc = float(np.hypot(np.diff(px), np.diff(py)).sum())
        area = float(np.trapezoid(width, sg))
        return dict(sg=sg, bend=bend, width=width, ox=ox, oy=oy, t=(tx, ty, nx, ny), arc=arc, area=area)

    @cached_property
    def _rim(self):
        s = self.spec
        cx, cy, a, b, hang = self.hole_xy_r
        rng = np.random.default_rng(s.shape_seed)
        r_mean = (a + b) / 2.0
        half = s.length_px / (2.0 * r_mean)  # half the arc, rad
        step = 0.25  # px along the rim
        n = int(np.ceil(2 * half * r_mean / step)) + 1
        phi = np.deg2rad(s.angle_deg) + np.linspace(-half, half, n)
        rough = RIM_ROUGHNESS[s.kind]
        h = np.clip(1.0 + rough * _smooth_noise(rng, n, RIM_ROUGHNESS_SCALE_PX / step), 0.25, 2.0)
        h *= s.width_px / h.mean()
        rim = self._hole_radius(phi)
        return dict(phi=phi, h=h, half=half, rim=rim, r_mean=r_mean, dphi=phi[1] - phi[0] if n > 1 else 1.0)

    def _hole_radius(self, phi: np.ndarray) -> np.ndarray:
        """Distance from the hole's centre to its rim in direction ``phi`` (rad, image sense)."""
        cx, cy, a, b, hang = self.hole_xy_r
        d = phi - np.deg2rad(hang)
        return 1.0 / np.sqrt((np.cos(d) / a) ** 2 + (np.sin(d) / b) ** 2)

    # ------------------------------------------------------------ geometry
    def _local(self, xu, yu):
        """Per kind: (signed distance-like coordinate, inside mask) at ideal points."""
        k = self.spec.kind
        if k == "pore":
            p = self._pore
            dx, dy = xu - p["ox"], yu - p["oy"]
            xl = dx * np.cos(p["t"]) + dy * np.sin(p["t"])
            yl = -dx * np.sin(p["t"]) + dy * np.cos(p["t"])
            rho = np.hypot(xl, yl)
            th = np.mod(np.arctan2(yl, xl), 2 * np.pi)
            r = np.interp(th, p["th"], p["r"], period=2 * np.pi)
            return rho - r, rho < r
        if k == "scratch":
            p = self._scratch
            tx, ty, nx, ny = p["t"]
            dx, dy = xu - p["ox"], yu - p["oy"]
            sv = dx * tx + dy * ty
            bend = np.interp(sv, p["sg"], p["bend"])
            w = np.interp(sv, p["sg"], p["width"])
            d = np.abs(dx * nx + dy * ny - bend) - w / 2.0
            along = np.abs(sv) - self.spec.length_px / 2.0
            dist = np.maximum(d, along)
            return dist, dist < 0
        p = self._rim
        cx, cy = self.hole_xy_r[0], self.hole_xy_r[1]
        dx, dy = xu - cx, yu - cy
        rho = np.hypot(dx, dy)
        phi0 = np.deg2rad(self.spec.angle_deg)
        dphi = np.mod(np.arctan2(dy, dx) - phi0 + np.pi, 2 * np.pi) - np.pi
        rim = self._hole_radius(phi0 + dphi)
        h = np.interp(dphi, p["phi"] - phi0, p["h"], left=0.0, right=0.0)
        out_of_arc = (np.abs(dphi) - p["half"]) * rim  # px along the rim beyond its ends
        if k == "burr":
            radial = np.maximum(rim - h - rho, rho - rim)  # < 0 between the ragged inner edge and the rim
        else:
            radial = np.maximum(rho - rim - h, rim - rho)
        dist = np.maximum(radial, out_of_arc)
        inside = (dist < 0) & (h > 0)
        return dist, inside

    def inside(self, xu, yu) -> np.ndarray:
        return self._local(xu, yu)[1]

    def near(self, xu, yu, margin: float) -> np.ndarray:
        d, _ = self._local(xu, yu)
        return np.abs(d) < margin

    def bbox_ideal(self, margin: float = 2.0) -> tuple[float, float, float, float]:
        """(x0, y0, x1, y1) of the outline in ideal px, widened by ``margin``."""
        k = self.spec.kind
        if k == "pore":
            fx, fy = self._pore["outline"]
        elif k == "scratch":
            p = self._scratch
            tx, ty, nx, ny = p["t"]
            w = p["width"].max() / 2
            px, py = p["ox"] + p["sg"] * tx + p["bend"] * nx, p["oy"] + p["sg"] * ty + p["bend"] * ny
            fx, fy = np.concatenate([px + w * nx, px - w * nx]), np.concatenate([py + w * ny, py - w * ny])
        else:
            p = self._rim
            cx, cy = self.hole_xy_r[0], self.hole_xy_r[1]
            r_in = p["rim"] - (p["h"] if k == "burr" else 0.0)
            r_out = p["rim"] + (p["h"] if k == "chip" else 0.0)
            fx = cx + np.concatenate([r_in, r_out]) * np.cos(np.concatenate([p["phi"], p["phi"]]))
            fy = cy + np.concatenate([r_in, r_out]) * np.sin(np.concatenate([p["phi"], p["phi"]]))
        return float(fx.min() - margin), float(fy.min() - margin), float(fx.max() + margin), float(fy.max() + margin)

    def outline_points(self) -> tuple[np.ndarray, np.ndarray]:
        """Points of the outline (ideal px), to find where the lens puts the defect."""
        x0, y0, x1, y1 = self.bbox_ideal(0.0)
        if self.spec.kind == "pore":
            return self._pore["outline"]
        return np.array([x0, x1, x1, x0]), np.array([y0, y0, y1, y1])

    def truth(self) -> DefectTruth:
        s = self.spec
        if s.kind == "pore":
            p = self._pore
            return DefectTruth("pore", s.x_px, s.y_px, p["length"], p["width"], p["direction"], float(p["area"]))
        if s.kind == "scratch":
            p = self._scratch
            return DefectTruth("scratch", s.x_px, s.y_px, p["arc"], s.width_px, s.angle_deg % 180.0, p["area"])
        p = self._rim
        cx, cy = self.hole_xy_r[0], self.hole_xy_r[1]
        phi0 = np.deg2rad(s.angle_deg)
        rim0 = float(self._hole_radius(np.array([phi0]))[0])
        mean_h = float(p["h"].mean())
        r_c = rim0 - mean_h / 2 if s.kind == "burr" else rim0 + mean_h / 2
        # the area between the rim and the ragged edge, integrated in polar coordinates
        r_edge = p["rim"] - p["h"] if s.kind == "burr" else p["rim"] + p["h"]
        area = float(abs(np.trapezoid((p["rim"] ** 2 - r_edge**2) / 2.0, p["phi"])))
        return DefectTruth(s.kind, cx + r_c * np.cos(phi0), cy + r_c * np.sin(phi0), s.length_px, mean_h,
                           s.angle_deg % 360.0, area, hole=s.hole, height_max_px=float(p["h"].max()))


def geometry(spec: DefectSpec, holes: list) -> DefectGeometry:
    """The outline of ``spec``; rim defects take their hole from ``holes`` (``HoleSpec``)."""
    if spec.kind in RIM_KINDS:
        if not (0 <= spec.hole < len(holes)):
            raise ValueError(f"{spec.kind}: hole {spec.hole} is not one of the frame's {len(holes)} holes")
        h = holes[spec.hole]
        a, b = h.semi_axes_px
        return DefectGeometry(spec, (h.x_px, h.y_px, a, b, h.angle_deg))
    return DefectGeometry(spec)


# ---------------------------------------------------------------- random defects
#: what the random frames draw from (mm at the wall; the twin's scale is 0.01 mm/px).
#: Pores 0.05-0.5 mm (issue 23); scratches 0.1-2 mm long and 0.015-0.06 mm wide (a
#: dragged chip's furrow: a few hundredths of a millimetre); burrs and chips 0.03-0.3 mm
#: along the rim and 0.01-0.08 mm high (deep): a drill's exit burr on a 0.7 mm hole
#: is of that order. Sizes are uniform, so a fair share lies above each limit.
RANDOM_SIZES_MM = {
    "pore": dict(length=(0.05, 0.5), aspect=(1.0, 1.6)),
    "scratch": dict(length=(0.1, 2.0), width=(0.015, 0.06)),
    "burr": dict(length=(0.03, 0.3), width=(0.01, 0.08)),
    "chip": dict(length=(0.03, 0.3), width=(0.01, 0.08)),
}
#: a scratch is at least this many times as long as it is wide (a short, wide mark is a
#: pore or a dent, not a furrow)
SCRATCH_MIN_ELONGATION = 5.0
#: reflectance ranges (share of the wall's level), the module's docstring says why
RANDOM_REFLECTANCE = {"pore": (0.15, 0.6), "scratch": (0.4, 0.8), "burr": (0.9, 1.15)}
#: a chip's floor: its hole's level plus up to this share of the wall-to-hole step
CHIP_LIFT = 0.15
#: a scratch crosses the honing pattern: by default its direction keeps this far from the
#: grooves' (a random draw's; 0 draws any direction, as a real part may have one along the
#: hatch: ``station bench defects --scratch-clearance-deg 0``)
HONING_CLEARANCE_DEG = 10.0


def random_scratch_angle(rng: np.random.Generator, honing_angle_deg: float = 30.0,
                         clearance_deg: float = HONING_CLEARANCE_DEG, within_deg: float | None = None) -> float:
    """A direction (deg, 0-180) at least ``clearance_deg`` from both groove families; or,
    with ``within_deg``, at most that far from one of them (a scratch along the hatch)."""
    if within_deg is not None:
        if not 0.0 < within_deg <= 45.0:
            raise ValueError(f"within_deg must lie in (0, 45] deg, got {within_deg}")
        family = honing_angle_deg if rng.uniform() < 0.5 else 180.0 - honing_angle_deg
        return float((family + rng.uniform(-within_deg, within_deg)) % 180.0)
    if not 0.0 <= clearance_deg < 45.0:
        raise ValueError(f"clearance_deg must lie in [0, 45) deg, got {clearance_deg}")
    while True:
        a = float(rng.uniform(0.0, 180.0))
        if all(abs((a - g + 90.0) % 180.0 - 90.0) >= clearance_deg for g in (honing_angle_deg,
                                                                             180.0 - honing_angle_deg)):
            return a


def random_defects(rng: np.random.Generator, params, holes: list, kinds: dict[str, int], mm_per_px: float,
                   border_px: float = 8.0, clearance_px: float = 12.0,
                   scratch_clearance_deg: float = HONING_CLEARANCE_DEG,
                   scratch_within_deg: float | None = None, pores_on_scratches: float = 0.0) -> list[DefectSpec]:
    """Defects drawn across ``RANDOM_SIZES_MM``: ``kinds`` maps a kind to how many.

    Pores and scratches lie wholly in the frame, clear of the holes and of each other
    by ``clearance_px``; burrs and chips go on the rims of whole holes, apart from each
    other along the rim. What does not fit after a few hundred tries is left out.
    ``pores_on_scratches``: the chance that a pore lies on a scratch's line instead (its
    centre on the line's middle 70 %, painted over it), when the frame has a scratch: a
    scratch that runs through a pore of the casting; the scratches are then drawn first.
    0 (the default) draws every frame as before.
    """
    if not 0.0 <= pores_on_scratches <= 1.0:
        raise ValueError(f"pores_on_scratches must be in [0, 1], not {pores_on_scratches}")
    if pores_on_scratches > 0.0 and "scratch" in kinds:
        kinds = {"scratch": kinds["scratch"], **{k: v for k, v in kinds.items() if k != "scratch"}}
    w, h = params.width_px, params.height_px
    out: list[DefectSpec] = []
    boxes: list[tuple[float, float, float, float]] = []
    placed: list[DefectSpec] = []  # the pores and scratches, box by box
    rim_used: dict[int, list[tuple[float, float]]] = {}
    # rim defects go on holes whose rim and defects stay clear of the frame's border
    keep = border_px + 12.0
    whole = [i for i, hole in enumerate(holes)
             if keep < hole.x_px - hole.diameter_px / 2 and hole.x_px + hole.diameter_px / 2 < w - keep
             and keep < hole.y_px - hole.diameter_px / 2 and hole.y_px + hole.diameter_px / 2 < h - keep]
    hole_boxes = [(ho.x_px - ho.diameter_px / 2, ho.y_px - ho.diameter_px / 2, ho.x_px + ho.diameter_px / 2,
                   ho.y_px + ho.diameter_px / 2) for ho in holes]

    def clear(box, others) -> bool:
        x0, y0, x1, y1 = box
        return all(x1 + clearance_px < o[0] or o[2] + clearance_px < x0 or y1 + clearance_px < o[1]
                   or o[3] + clearance_px < y0 for o in others)

    for kind, count in kinds.items():
        sizes = RANDOM_SIZES_MM[kind]
        for _ in range(count):
            for _attempt in range(300):
                seed = int(rng.integers(2**31))
                if kind == "pore":
                    length = rng.uniform(*sizes["length"]) / mm_per_px
                    width = length / rng.uniform(*sizes["aspect"])
                    angle = float(rng.uniform(0.0, 180.0))
                elif kind == "scratch":
                    length = rng.uniform(*sizes["length"]) / mm_per_px
                    # a furrow is long and thin: at least SCRATCH_MIN_ELONGATION times its width
                    width = min(rng.uniform(*sizes["width"]) / mm_per_px, length / SCRATCH_MIN_ELONGATION)
                    angle = random_scratch_angle(rng, params.hatch_deg, scratch_clearance_deg, scratch_within_deg)
                else:
                    length = rng.uniform(*sizes["length"]) / mm_per_px
                    width = rng.uniform(*sizes["width"]) / mm_per_px
                    angle = float(rng.uniform(0.0, 360.0))
                if kind in RIM_KINDS:
                    if not whole:
                        break
                    hi = int(rng.choice(whole))
                    hole = holes[hi]
                    r = hole.diameter_px / 2
                    half_deg = np.rad2deg(length / (2 * r))
                    if half_deg > 60.0:
                        continue
                    used = rim_used.setdefault(hi, [])
                    gap_deg = np.rad2deg(clearance_px / r)
                    if any(abs((angle - a + 180.0) % 360.0 - 180.0) < half_deg + hw + gap_deg for a, hw in used):
                        continue
                    refl = None
                    if kind == "burr":
                        refl = float(rng.uniform(*RANDOM_REFLECTANCE["burr"]))
                    else:
                        hole_ratio = params.hole_level_dn / params.wall_level_dn
                        refl = float(hole_ratio + rng.uniform(0.0, CHIP_LIFT) * (1.0 - hole_ratio))
                    spec = DefectSpec(kind, 0.0, 0.0, float(length), float(width), angle, refl, hi, seed)
                    used.append((angle, half_deg))
                    out.append(spec)
                    break
                margin = border_px + length / 2 + 6
                if w - 2 * margin <= 1 or h - 2 * margin <= 1:
                    continue  # longer than the frame has room for
                x = float(rng.uniform(margin, w - 1 - margin))
                y = float(rng.uniform(margin, h - 1 - margin))
                on = None  # the scratch a pore lies on, whose box it may overlap
                scratches = [o for o in out if o.kind == "scratch"]
                if kind == "pore" and pores_on_scratches > 0.0 and scratches and rng.uniform() < pores_on_scratches:
                    on = scratches[int(rng.integers(len(scratches)))]
                    t = float(rng.uniform(-0.35, 0.35)) * on.length_px
                    x = on.x_px + t * float(np.cos(np.deg2rad(on.angle_deg)))
                    y = on.y_px + t * float(np.sin(np.deg2rad(on.angle_deg)))
                refl = float(rng.uniform(*RANDOM_REFLECTANCE[kind]))
                spec = DefectSpec(kind, x, y, float(length), float(width), angle, refl, None, seed)
                box = DefectGeometry(spec).bbox_ideal(0.0)
                if box[0] < border_px or box[1] < border_px or box[2] > w - 1 - border_px or box[3] > h - 1 - border_px:
                    continue
                others = boxes if on is None else [b for b, o in zip(boxes, placed) if o is not on]
                if not clear(box, others + hole_boxes):
                    continue
                placed.append(spec)
                boxes.append(box)
                out.append(spec)
                break
    return out


def random_defect_frame(seed: int, kinds: dict[str, int] | None = None, *, mm_per_px: float = 0.010,
                        n_holes: int | None = None, hole_diameter_mm: tuple[float, float] = (0.6, 1.0),
                        envelope: str = "station", scratch_clearance_deg: float = HONING_CLEARANCE_DEG,
                        scratch_within_deg: float | None = None, pores_on_scratches: float = 0.0, **overrides):
    """A random frame with random defects from one seed (the defect bench's and tests'
    unit of work), its truth in px and mm.

    The frame's condition is ``render.random_params``'s envelope. Holes are the
    station's compensating holes, 0.6-1.0 mm (the spec's 0.7 mm +/- 0.125 and more; the
    largest pore is 0.5 mm, so a dark disc's size tells a hole from a pore). ``kinds``:
    how many of each kind (None: 0-2 pores, 0-2 scratches, and 0-2 burrs and 0-2 chips
    when there are holes; ``{}``: a clean frame). ``scratch_clearance_deg``: how far the
    scratches' directions keep from the hatch's (0: any direction); ``scratch_within_deg``:
    instead, at most that far from a groove family (scratches along the hatch);
    ``pores_on_scratches``: the chance that a pore lies on a scratch (``random_defects``).
    """
    from sim.camera.render import random_holes, random_params, render_frame

    rng = np.random.default_rng(seed)
    params = random_params(rng, envelope, **overrides)
    if n_holes is None:
        n_holes = int(rng.integers(0, 3))
    lo, hi = (d / mm_per_px for d in hole_diameter_mm)
    holes = random_holes(rng, params, n_holes, 0, diameter_range_px=(lo, hi), border_clearance_px=40.0)
    if kinds is None:
        kinds = {"pore": int(rng.integers(0, 3)), "scratch": int(rng.integers(0, 3))}
        if holes:
            kinds.update(burr=int(rng.integers(0, 3)), chip=int(rng.integers(0, 3)))
    defects = random_defects(rng, params, holes, kinds, mm_per_px, scratch_clearance_deg=scratch_clearance_deg,
                             scratch_within_deg=scratch_within_deg, pores_on_scratches=pores_on_scratches)
    frame = render_frame(params, holes, seed=int(rng.integers(2**31)), defects=defects)
    frame.defects = [d.with_scale(mm_per_px) for d in frame.defects]
    return frame
