"""``station sim ...``: the simulated twins as standalone servers.

``station sim up`` starts every twin server of a scenario (Modbus TCP per drive, the
grating encoder on a pty) and prints where each listens, then serves until Ctrl-C --
so the real drivers (or any Modbus tool) can be pointed at them from another process.
"""

from __future__ import annotations

import asyncio
import contextlib
import signal
from pathlib import Path
from typing import Optional

import typer

from station.cli.common import err_console, fail, print_json

sim_app = typer.Typer(help="Simulated twins: protocol-level servers for the drives and the encoder.", no_args_is_help=True)


@sim_app.command("up")
def up(
    scenario: Optional[Path] = typer.Option(None, "--scenario", "-s", help="scenario TOML (default: sim/scenarios/default.toml)"),
    json_out: bool = typer.Option(False, "--json", help="print the endpoints as one JSON document on stdout"),
) -> None:
    """Start all twin servers and serve until Ctrl-C."""
    from sim.twins import ScenarioError, TwinStation, load_scenario
    from sim.world import load_world
    from station.kinematics.model import ModelConfigError

    try:
        sc = load_scenario(scenario)
        world = load_world(scenario)
    except (ScenarioError, ModelConfigError, ValueError) as exc:
        fail(str(exc))

    async def serve() -> None:
        station = TwinStation(sc)
        # the drives' carriages and the grating err as the scenario's error model says
        world.attach(station)
        try:
            endpoints = await station.start()
        except OSError as exc:
            fail(f"cannot start the twins: {exc}")
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            with contextlib.suppress(NotImplementedError, RuntimeError):
                loop.add_signal_handler(sig, stop.set)
        try:
            if json_out:
                print_json(endpoints)
            else:
                err_console.print(f"twins of [bold]{sc.source}[/] (time scale {sc.time_scale}):")
                for name, ep in endpoints.items():
                    if "port" in ep:
                        print(f"{name}: modbus-tcp {ep['host']}:{ep['port']} device_id={ep['device_id']} "
                              f"unit_per_count={ep['unit_per_count']} ({ep['kind']})"
                              + (f"; modbus-rtu {ep['rtu_path']} baud={ep['rtu_baudrate']}" if "rtu_path" in ep else ""),
                              flush=True)
                    else:
                        print(f"{name}: serial {ep['path']} baud={ep['baudrate']} "
                              f"resolution_um={ep['resolution_um']} (axis {ep['axis']})", flush=True)
                err_console.print("serving; Ctrl-C to stop")
            await stop.wait()
        finally:
            await station.stop()

    asyncio.run(serve())


@sim_app.command("camera-calibration")
def camera_calibration(
    out: Path = typer.Option(..., "--out", help="calibration JSON to write (station.vision.calibration)"),
    views: int = typer.Option(12, "--views", min=4, help="chessboard views round the frame"),
    seed: int = typer.Option(0, "--seed", help="the views' poses and noise"),
) -> None:
    """Calibrate the camera twin's endoscope as a plant calibrates a real one: chessboard
    views rendered through its lens, solved by the station's own calibration. The
    simulated station ships the result (station/data/camera/endoscope-twin.json)."""
    from sim.camera.target import calibrate_lens
    from sim.camera.twin import ENDOSCOPE_LENS
    from station.vision.calibration import calibration_warnings

    cal = calibrate_lens(ENDOSCOPE_LENS, n_views=views, seed=seed)
    out.parent.mkdir(parents=True, exist_ok=True)
    cal.save(out)
    err_console.print(f"{out}: {cal.n_views} views, RMS {cal.rms_px:.3f} px, coverage {cal.coverage:.2f}")
    for w in calibration_warnings(cal):
        err_console.print(f"[yellow]warning:[/] {w}")


def register(app: typer.Typer) -> None:
    app.add_typer(sim_app, name="sim")
