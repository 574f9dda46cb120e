"""The camera twin: what the side-view endoscope sees at the true pose.

It implements the camera interface of ``drivers`` in-process (a V4L2 device cannot
be faked over a socket the way Modbus can). At every grab it asks the drives'
physics where the motors are, asks the world where that puts the detection point
on the part (the full error model), and renders the patch of bore wall around it
with the holes that fall in view, through ``sim.camera.render`` (honed texture,
blur, noise, vignetting, lens distortion). The ground truth of the last frame is
kept for tests and for the simulated inspection's report.

Image axes: x to the right is the tangential direction of increasing part angle,
y down is decreasing axial position (the bore's axis points up in the image).
Faults: dropped connection, delay, black frames, frozen frames (``sim.faults``).

The wall: a camera that stays put sees the same patch of wall again (only the
sensor's noise changes from frame to frame), as a real one does; the patch is kept
per view position (rounded to the pixel) and drawn from a seed of that position and
of the part (``PartTruth.texture_seed``), so a return to a place shows the same
texture and another part at that place its own. Known simplification: a camera that
moves sees a new patch (its statistics are the wall's, but its grooves do not
travel with the move); the holes and their positions, which are what is measured,
are exact.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections import OrderedDict
from dataclasses import dataclass, field, replace

import numpy as np

from drivers.interfaces import CommunicationLost, DeviceTimeout, Frame
from drivers.interfaces import Camera, CameraTiming
from sim.camera.lens import BrownLens
from sim.camera.defects import DefectSpec
from sim.camera.defects import geometry as defect_geometry
from sim.camera.render import FrameParams, HoleSpec
from sim.camera.renderer import RendererLost, RendererProcess, render_image
from sim.faults import CAMERA_FAULTS, FaultKind, FaultSwitch
from sim.world import World

log = logging.getLogger("sim.camera")


@dataclass(frozen=True)
class ViewTruth:
    """Ground truth of one frame: where the camera looked and which holes and surface
    defects it saw."""

    axial_mm: float
    angle_deg: float
    z_motor_mm: float
    c_motor_deg: float
    holes: tuple = ()  # (name, x_px, y_px, diameter_px, diameter_mm, partial)
    #: ``sim.camera.defects.DefectTruth`` with name, mm and the part frame filled
    defects: tuple = ()


@dataclass
class CameraOptics:
    """Scale and frame of the endoscope camera at the bore wall."""

    #: 10 um per pixel: a 0.7 mm hole is 70 px across, inside the 20-100 px the vision
    #: stage is specified for, and the 1280 x 1024 frame sees 12.8 x 10.2 mm of wall
    mm_per_px: float = 0.010
    params: FrameParams = field(default_factory=lambda: FrameParams(lens=ENDOSCOPE_LENS))
    #: the sensor the twin stands for: an 8 ms exposure (an endoscope's LED light at the
    #: aperture the depth of field needs) and a 1280 x 1024 global-shutter readout at
    #: 40 frames/s (25 ms); the machine's time per frame, not the renderer's
    timing: CameraTiming = field(default_factory=lambda: CameraTiming(exposure_s=0.008, readout_s=0.025))


#: a side-view endoscope's lens: moderate barrel distortion (-2.7 % at the frame's
#: corner), as wide-angle borescope optics have; the station measures each hole after
#: re-centring it on the optical axis, where the distortion vanishes
ENDOSCOPE_LENS = BrownLens(fx_px=1400.0, fy_px=1400.0, cx_px=639.5, cy_px=511.5, k1=-0.08, k2=0.01)


class CameraTwin(Camera):
    name = "camera-twin"

    def __init__(self, world: World, z_physics, c_physics, optics: CameraOptics | None = None,
                 *, seed: int = 0, grab_timeout_s: float = 1.0, render_process: bool = False):
        self.world = world
        self.z = z_physics
        self.c = c_physics
        self.optics = optics or CameraOptics()
        self.timing = self.optics.timing
        self.faults = FaultSwitch(CAMERA_FAULTS, name="camera")
        self.grab_timeout_s = grab_timeout_s
        self._rng = np.random.default_rng(seed)
        self._seed = seed
        self._walls: OrderedDict[tuple[int, ...], np.ndarray] = OrderedDict()
        self._render_process = render_process
        self._renderer: RendererProcess | None = None
        self._sequence = 0
        self._connected = False
        self._last: Frame | None = None
        self.last_truth: ViewTruth | None = None

    @property
    def frames_delivered(self) -> int:
        """Frames ``grab`` has returned since the twin was made (frozen ones included):
        the sequence number of the last frame. Read-only, for benches that count what
        an inspection grabbed."""
        return self._sequence

    async def connect(self) -> None:
        if self.faults.is_active(FaultKind.DROP_CONNECTION):
            raise CommunicationLost("camera does not answer", self.name)
        if self._render_process and self._renderer is None:
            self._renderer = RendererProcess()
            try:
                await self._renderer.start()
            except RendererLost as exc:
                log.warning("camera twin: %s; rendering in a thread", exc)
                self._renderer = None
        self._connected = True

    async def close(self) -> None:
        self._connected = False
        self._stop_renderer()

    def _stop_renderer(self) -> None:
        if self._renderer is not None:
            self._renderer.stop()
            self._renderer = None

    def view(self) -> tuple[list[HoleSpec], ViewTruth]:
        """The holes in view at the drives' present positions, in ideal pixels."""
        specs, _defects, truth = self.scene()
        return specs, truth

    def scene(self) -> tuple[list[HoleSpec], list[DefectSpec], ViewTruth]:
        """The holes and the surface defects in view at the drives' present positions,
        in ideal pixels, and the frame's truth."""
        t = self.z.now()
        z_motor = self.z.motor_position(t)
        c_motor = self.c.motor_position(self.c.now())
        point = self.world.true_point(z_motor, c_motor, self.z.direction, self.c.direction, t)
        p = self.optics.params
        s = self.optics.mm_per_px
        cx, cy = (p.width_px - 1) / 2.0, (p.height_px - 1) / 2.0
        specs, truth, names = [], [], []
        for hole, du_mm, dv_mm in self.world.holes_near(point, p.width_px * s / 2, p.height_px * s / 2):
            x, y, d = cx + du_mm / s, cy - dv_mm / s, hole.diameter_mm / s
            specs.append(HoleSpec(x, y, d))
            names.append(hole.name)
            r = d / 2
            partial = x - r < -0.5 or y - r < -0.5 or x + r > p.width_px - 0.5 or y + r > p.height_px - 0.5
            truth.append((hole.name, x, y, d, hole.diameter_mm, partial))
        defect_specs, defect_truths = self._defects_in_view(point, specs, names)
        return specs, defect_specs, ViewTruth(point.axial_mm, point.angle_deg, z_motor, c_motor, tuple(truth),
                                              tuple(defect_truths))

    def _defects_in_view(self, point, holes: list[HoleSpec], names: list[str]):
        """The part's surface defects in view, as the renderer's specs (image axes: x
        along increasing angle, y along decreasing axial position, so a direction on the
        unrolled wall turns the other way in the image) and their truths in px, mm and
        the part's frame (a rim defect's part position from its rendered centre)."""
        p = self.optics.params
        s = self.optics.mm_per_px
        cx, cy = (p.width_px - 1) / 2.0, (p.height_px - 1) / 2.0
        specs, named = [], []
        for d, du_mm, dv_mm in self.world.defects_near(point, p.width_px * s / 2, p.height_px * s / 2):
            specs.append(DefectSpec(d.kind, cx + du_mm / s, cy - dv_mm / s, d.length_mm / s, d.width_mm / s,
                                    -d.orientation_deg, d.reflectance, None, d.seed))
            named.append(d)
        for d in self.world.part.defects:
            if d.hole is not None and d.hole in names:
                specs.append(DefectSpec(d.kind, 0.0, 0.0, d.length_mm / s, d.width_mm / s, -d.at_deg, d.reflectance,
                                        names.index(d.hole), d.seed))
                named.append(d)
        radius_mm = self.world.part.bore_diameter_mm / 2.0
        part_holes = {h.name: h for h in self.world.part.holes}
        truths = []
        for spec, d in zip(specs, named):
            t = defect_geometry(spec, holes).truth().with_scale(s)
            if d.hole is None:
                axial, angle = d.axial_mm, d.angle_deg  # the world's own place
            else:
                # the rendered centre's offset from its hole, on the part
                hole_px, hole = holes[spec.hole], part_holes[d.hole]
                axial = hole.axial_mm + (hole_px.y_px - t.y_px) * s
                angle = hole.angle_deg + float(np.rad2deg((t.x_px - hole_px.x_px) * s / radius_mm))
            truths.append(replace(t, name=d.name, axial_mm=float(axial), part_angle_deg=float(angle) % 360.0))
        return specs, truths

    async def grab(self) -> Frame:
        if not self._connected:
            # the next call reconnects (the drivers' contract, docs/drivers.md): a camera
            # whose link came back delivers again without a restart of the station
            await self.connect()
        if self.faults.is_active(FaultKind.DROP_CONNECTION):
            self._connected = False
            raise CommunicationLost("camera stopped delivering frames (link lost)", self.name)
        delay = self.faults.get(FaultKind.DELAY)
        if delay is not None:
            if delay.delay_s >= self.grab_timeout_s:
                await asyncio.sleep(self.grab_timeout_s)
                raise DeviceTimeout(f"no frame within {self.grab_timeout_s:.2f} s", self.name)
            await asyncio.sleep(delay.delay_s)
        if self.faults.is_active(FaultKind.FROZEN_FRAME):
            if self._last is None:
                # a sensor that hung before its first frame has no image to repeat: the
                # capture waits for a buffer that never fills
                await asyncio.sleep(self.grab_timeout_s)
                raise DeviceTimeout(f"no frame within {self.grab_timeout_s:.2f} s (the sensor has not "
                                    "delivered its first frame)", self.name)
            # the driver sees the same image again under a new number: a hung sensor
            self._sequence += 1
            return Frame(self._last.image, time.time(), self._sequence)
        p = self.optics.params
        if self.faults.is_active(FaultKind.BLACK_FRAME):
            image = np.zeros((p.height_px, p.width_px), dtype=np.uint8)
            self.last_truth = None
        else:
            specs, defects, truth = self.scene()
            seed = int(self._rng.integers(0, 2**31))
            if self.world.part.hatch_deg != p.hatch_deg:
                p = replace(p, hatch_deg=self.world.part.hatch_deg)  # the part's honing
            # rendering a frame takes tens of ms: off the event loop (and, with a
            # renderer process, off this interpreter's GIL, as a real camera's pixels are)
            image = await self._render(p, specs, seed, truth, defects)
            self.last_truth = truth
        self._sequence += 1
        out = Frame(image, time.time(), self._sequence)
        self._last = out
        return out

    def render_here(self) -> None:
        """Render in this process (a thread) from now on: for benchmarks that time the
        twin's rendering apart from the station's own work."""
        self._render_process = False
        self._stop_renderer()

    def _wall_key(self, truth: ViewTruth) -> tuple[int, ...]:
        """The patch of wall in view: its place (px, rounded), and on another part than
        the scenario's first (``PartTruth.texture_seed``) that part too: a part put on
        the table shows its own honing where another was scanned alike; and a part
        honed at another angle than the optics' (``PartTruth.hatch_deg``, in
        thousandths of a degree) its angle."""
        s = self.optics.mm_per_px
        place = (round(truth.axial_mm / s),
                 round(np.deg2rad(truth.angle_deg) * self.world.part.bore_diameter_mm / 2.0 / s))
        texture = self.world.part.texture_seed
        hatch = self.world.part.hatch_deg
        if hatch != self.optics.params.hatch_deg:
            return (texture, round(hatch * 1000.0), *place)
        return place if texture == 0 else (texture, *place)

    async def _render(self, p: FrameParams, specs: list[HoleSpec], seed: int, truth: ViewTruth,
                      defects: list[DefectSpec] = ()) -> np.ndarray:
        """The frame's pixels: in the renderer process when there is one, else in a thread."""
        key = self._wall_key(truth)
        wall_seed = hash((self._seed, key)) & 0x7FFFFFFF
        extra = {"defects": list(defects)} if defects else {}
        if self._renderer is not None:
            try:
                return await self._renderer.render(p, specs, seed, key, wall_seed, **extra)
            except RendererLost as exc:
                # the twin's own machinery failed, not the camera: render here from now on
                log.warning("camera twin: %s; rendering in a thread from now on", exc)
                self._stop_renderer()
        return await asyncio.to_thread(render_image, p, specs, seed, key, wall_seed, self._walls, **extra)


def small_optics(width_px: int = 320, height_px: int = 256, mm_per_px: float = 0.01) -> CameraOptics:
    """A smaller frame for fast tests (same scale)."""
    return CameraOptics(mm_per_px, replace(FrameParams(), width_px=width_px, height_px=height_px))
