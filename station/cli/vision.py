"""``station vision ...``: measure compensating holes in a frame; find surface defects; calibrate the camera."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer
from rich.table import Table

from station.cli.common import err_console, fail, out_console, print_json

vision_app = typer.Typer(help="Vision: sub-pixel hole measurement, surface defects and camera calibration.",
                         no_args_is_help=True)


def _pattern(text: str) -> tuple[int, int]:
    try:
        cols, rows = (int(v) for v in text.lower().split("x"))
    except ValueError:
        fail(f"--pattern must look like 9x7 (inner corners), not {text!r}")
    return cols, rows


def _read_linear(image: Path, gamma: float):
    """The grey frame of ``image``, made linear in light for a camera of response ``gamma``
    (``drivers.interfaces.pixels.linearize``); a bad file or gamma ends the command."""
    from drivers.interfaces.pixels import linearize
    from station.vision.imageio import ImageReadError, read_grey

    try:
        frame = read_grey(image)
    except ImageReadError as exc:
        fail(str(exc))
    try:
        return linearize(frame, gamma)
    except ValueError as exc:
        fail(f"{image}: --gamma: {exc} (1: a linear camera)")


def _pixel_map(path: Optional[Path]):
    """The camera's pixel map from ``path`` (``station vision pixel-map``), or None; a bad
    file ends the command naming it."""
    if path is None:
        return None
    from station.vision.pixelmap import PixelMap

    try:
        return PixelMap.load(path)
    except OSError as exc:
        fail(f"{path}: cannot read the pixel map ({exc.strerror or exc})")
    except ValueError as exc:
        fail(str(exc))


def _mended(frame, pixel_map, image: Path):
    """``frame`` with the camera's flawed pixels mended (``PixelMap.repair``); a frame of
    another size than the map's ends the command."""
    if pixel_map is None:
        return frame
    try:
        return pixel_map.repair(frame)
    except ValueError as exc:
        fail(f"{image}: {exc}")


PIXEL_MAP_HELP = "the camera's flawed pixels (JSON from `station vision pixel-map`), mended before measuring"


@vision_app.command("measure")
def measure(
    image: Path = typer.Argument(..., help="frame to measure (any format OpenCV reads)"),
    mm_per_px: Optional[float] = typer.Option(None, "--mm-per-px", help="scale at the bore wall"),
    calibration: Optional[Path] = typer.Option(None, "--calibration", help="JSON from `station vision calibrate`"),
    gamma: float = typer.Option(1.0, "--gamma", help="the camera's response gamma (pixel = full x light^gamma: "
                                "sRGB-like cameras 0.45, 1 linear); frames are made linear first"),
    pixel_map: Optional[Path] = typer.Option(None, "--pixel-map", help=PIXEL_MAP_HELP),
    as_json: bool = typer.Option(False, "--json", help="one JSON object on stdout"),
) -> None:
    """Find the compensating holes in IMAGE and measure them sub-pixel."""
    from station.vision.calibration import CameraCalibration
    from station.vision.measure import measure_holes

    if mm_per_px is not None and calibration is not None:
        fail("give --mm-per-px or --calibration, not both")
    if mm_per_px is not None and not mm_per_px > 0:
        fail("--mm-per-px must be positive")
    cal = None
    if calibration is not None:
        try:
            cal = CameraCalibration.load(calibration)
        except (OSError, ValueError, KeyError, TypeError) as exc:
            fail(f"{calibration}: not a usable calibration file ({exc})")
    pmap = _pixel_map(pixel_map)
    frame = _mended(_read_linear(image, gamma), pmap, image)
    if cal is not None and tuple(cal.image_size) != (frame.shape[1], frame.shape[0]):
        fail(f"calibration is for {cal.image_size[0]}x{cal.image_size[1]} px, the image is {frame.shape[1]}x{frame.shape[0]}")
    holes = measure_holes(frame, mm_per_px=mm_per_px, calibration=cal)
    notes = []
    if mm_per_px is None and cal is None:
        from station.vision.detect import MAX_HOLE_MM, DetectConfig, oversized_discs

        limit = DetectConfig().max_diameter_px
        for d in oversized_discs(frame):
            notes.append(f"a dark disc about {2 * d.radius_px:.0f} px across at ({d.x_px:.0f}, {d.y_px:.0f}) px was "
                         f"not measured: without a scale holes are sought up to {limit:.0f} px ({MAX_HOLE_MM} mm at "
                         f"{MAX_HOLE_MM / limit:.3f} mm/px); give --mm-per-px or --calibration")
    if as_json:
        print_json({"image": str(image), "holes": [h.to_dict() for h in holes], "notes": notes})
        return
    table = Table(title=f"{image.name}: {len(holes)} hole(s)")
    for col in ("x px", "y px", "u(x, y) px", "d px", "u(d) px", "d mm", "partial", "conf", "rms px", "edge DN"):
        table.add_column(col, justify="right")
    for h in holes:
        table.add_row(
            f"{h.x_px:.3f}", f"{h.y_px:.3f}",
            "-" if h.x_u_px is None else f"{h.x_u_px:.3f}, {h.y_u_px:.3f}",
            f"{h.diameter_px:.3f}",
            "-" if h.diameter_u_px is None else f"{h.diameter_u_px:.3f}",
            "-" if h.diameter_mm is None else f"{h.diameter_mm:.4f}",
            "yes" if h.partial else "no", f"{h.confidence:.2f}", f"{h.fit_rms_px:.3f}", f"{h.edge_contrast_dn:.0f}",
        )
    out_console.print(table)
    for note in notes:
        err_console.print(f"note: {note}", highlight=False, markup=False)


@vision_app.command("defects")
def defects_cmd(
    image: Path = typer.Argument(..., help="frame of the bore wall (any format OpenCV reads)"),
    mm_per_px: float = typer.Option(..., "--mm-per-px", help="scale at the bore wall (sizes in mm; which dark "
                                                             "discs are holes)"),
    blur_px: Optional[float] = typer.Option(None, "--blur-px", help="the camera's blur (Gaussian sigma, px) if "
                                                                    "known; else read from the frame"),
    gamma: float = typer.Option(1.0, "--gamma", help="the camera's response gamma (pixel = full x light^gamma: "
                                "sRGB-like cameras 0.45, 1 linear); frames are made linear first"),
    pixel_map: Optional[Path] = typer.Option(None, "--pixel-map", help=PIXEL_MAP_HELP),
    hole_at: Optional[list[str]] = typer.Option(None, "--hole-at", help="X,Y: a hole of the part shows here (image "
                                                "px; repeat for each). Given, a dark disc of a hole's size centred "
                                                "at none of them is a mark of the wall (a large pore), not a hole"),
    no_holes: bool = typer.Option(False, "--no-holes", help="the frame shows none of the part's holes: every dark "
                                  "disc is a mark of the wall (a large pore), not a hole"),
    as_json: bool = typer.Option(False, "--json", help="one JSON object on stdout"),
) -> None:
    """Find and measure surface defects in IMAGE: pores, scratches, and burrs and chips at
    the holes' edges (docs/surface.md). Without --hole-at or --no-holes every dark disc
    of a hole's size (0.55 mm and more) is taken for a hole."""
    from station.vision.defects import detect_defects
    from station.vision.detect import MAX_HOLE_MM

    if not mm_per_px > 0:
        fail(f"{image}: --mm-per-px must be positive, not {mm_per_px}")
    if blur_px is not None and not blur_px > 0:
        fail(f"{image}: --blur-px must be positive, not {blur_px}")
    if hole_at and no_holes:
        fail(f"{image}: --hole-at and --no-holes contradict each other")
    hole_places = () if no_holes else None
    if hole_at:
        reach_px = MAX_HOLE_MM / 2.0 / mm_per_px  # from the centre given: the largest hole's radius
        hole_places = []
        for text in hole_at:
            try:
                x, y = (float(v) for v in text.split(","))
            except ValueError:
                fail(f"{image}: --hole-at {text!r}: expected X,Y in image px (two numbers)")
            hole_places.append((x, y, reach_px))
    pmap = _pixel_map(pixel_map)
    frame = _mended(_read_linear(image, gamma), pmap, image)
    if min(frame.shape) < 64:
        fail(f"{image}: {frame.shape[1]} x {frame.shape[0]} px is too small to model the wall (at least 64 x 64)")
    found = detect_defects(frame, mm_per_px, blur_px=blur_px, hole_places=hole_places)
    if as_json:
        print_json({"image": str(image), "mm_per_px": mm_per_px, "defects": [d.to_dict() for d in found]})
        return
    table = Table(title=f"{image.name}: {len(found)} defect(s)")
    for col in ("kind", "x px", "y px", "length mm", "u mm", "width mm", "u mm", "angle deg", "hole", "conf"):
        table.add_column(col, justify="right")
    for d in found:
        table.add_row(d.kind, f"{d.x_px:.1f}", f"{d.y_px:.1f}", f"{d.length_mm:.3f}", f"{d.size_u_mm:.3f}",
                      f"{d.width_mm:.3f}", f"{d.width_u_mm:.3f}", f"{d.angle_deg:.0f}",
                      "-" if d.hole is None else str(d.hole), f"{d.confidence:.2f}")
    out_console.print(table)


@vision_app.command("pixel-map")
def pixel_map_cmd(
    images: list[Path] = typer.Argument(..., help="frames of the bore wall moving under the camera (a coverage "
                                                  "scan's, or the table turning between frames): at least 12"),
    out: Path = typer.Option(..., "--out", "-o", help="the map's JSON file (for --pixel-map and the station's "
                                                     "[hardware.camera] pixel_map)"),
    gamma: float = typer.Option(1.0, "--gamma", help="the camera's response gamma; frames are made linear first"),
    as_json: bool = typer.Option(False, "--json", help="a JSON summary on stdout"),
) -> None:
    """Find the camera's flawed pixels (hot, dim, a column short below a trap) from frames
    of a moving wall: the pixels that stand out of their neighbourhood the same way in
    most frames (docs/vision.md, "The camera's flawed pixels")."""
    from rich.progress import Progress

    from station.vision.pixelmap import MIN_FRAMES, PixelMapBuilder

    if len(images) < MIN_FRAMES:
        fail(f"a pixel map needs at least {MIN_FRAMES} frames of a moving wall, got {len(images)}")
    builder = PixelMapBuilder()
    with Progress(console=err_console, transient=True) as bar:
        task = bar.add_task("reading frames", total=len(images))
        for image in images:
            try:
                builder.add(_read_linear(image, gamma))
            except ValueError as exc:
                fail(f"{image}: {exc}")
            bar.advance(task)
    pmap = builder.result(source=f"{len(images)} frames, first {images[0]}")
    try:
        pmap.save(out)
    except OSError as exc:
        fail(f"{out}: cannot write the pixel map ({exc.strerror or exc})")
    hot = sum(1 for p in pmap.pixels if p[2] == "hot")
    summary = {"map": str(out), "frames": pmap.frames, "width": pmap.width, "height": pmap.height,
               "hot": hot, "dim": len(pmap.pixels) - hot,
               "columns": [{"col": c, "first_row": a, "last_row": b, "offset_dn": round(o, 2)}
                           for c, a, b, o in pmap.columns]}
    if as_json:
        print_json(summary)
        return
    out_console.print(f"{out}: {hot} hot and {len(pmap.pixels) - hot} dim pixel(s), {len(pmap.columns)} flawed "
                      f"column stretch(es), from {pmap.frames} frames of {pmap.width} x {pmap.height} px",
                      highlight=False)
    for c in summary["columns"]:
        out_console.print(f"  column {c['col']}: rows {c['first_row']}-{c['last_row']}, {c['offset_dn']:+.1f} DN",
                          highlight=False)


@vision_app.command("calibrate")
def calibrate_cmd(
    images: list[Path] = typer.Argument(..., help="chessboard views"),
    out: Path = typer.Option(..., "--out", help="calibration JSON to write"),
    pattern: str = typer.Option("9x7", "--pattern", help="inner corners, columns x rows"),
    square_mm: float = typer.Option(0.5, "--square-mm", help="chessboard square size"),
    working_distance_mm: Optional[float] = typer.Option(
        None, "--working-distance-mm", help="distance to the bore wall: sets the mm-per-px scale"
    ),
    as_json: bool = typer.Option(False, "--json"),
) -> None:
    """Intrinsics and distortion from chessboard IMAGES, saved as JSON."""
    from station.vision.calibration import calibrate, calibration_warnings
    from station.vision.imageio import ImageReadError, read_grey

    size = _pattern(pattern)
    frames = []
    for p in images:
        try:
            frames.append(read_grey(p))
        except ImageReadError as exc:
            fail(str(exc))
    try:
        cal = calibrate(frames, size, square_mm, working_distance_mm)
    except ValueError as exc:
        fail(str(exc))
    cal.save(out)
    if as_json:
        print_json(cal.to_json())
    else:
        k = cal.camera_matrix
        out_console.print(
            f"{cal.n_views}/{len(images)} views, RMS {cal.rms_px:.3f} px; fx {k[0, 0]:.1f} fy {k[1, 1]:.1f} "
            f"cx {k[0, 2]:.1f} cy {k[1, 2]:.1f}; k1 {cal.dist_coeffs[0]:.4f} k2 {cal.dist_coeffs[1]:.4f} -> {out}"
        )
        summary = cal.map_u_summary()
        if summary is not None:
            out_console.print(
                f"the board's corners covered {cal.coverage:.0%} of the frame; the undistortion map's uncertainty "
                f"(k = 1) is at most {summary['central_80_max_px']:.3f} px over the central 80 % and "
                f"{summary['frame_max_px']:.3f} px over the whole frame"
            )
    for warning in calibration_warnings(cal):
        err_console.print(f"[yellow]warning:[/] {warning}")


def register(app: typer.Typer) -> None:
    app.add_typer(vision_app, name="vision")
