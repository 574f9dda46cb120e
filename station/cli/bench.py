"""``station bench ...``: benchmarks of speed and accuracy (medians, JSON on request).

Each benchmark lives in ``station/bench/<name>.py`` and defines ``register(bench_app)``.
"""

from __future__ import annotations

import importlib

import typer

bench_app = typer.Typer(help="Benchmarks: speed and accuracy, medians over repeats.", no_args_is_help=True)

_BENCHES = ("kinematics", "vision", "vision_bound", "drivers", "discovery", "inspect", "reliability", "api", "soak",
            "calibration", "defects", "surface", "pixelmap")


def register(app: typer.Typer) -> None:
    for name in _BENCHES:
        try:
            module = importlib.import_module(f"station.bench.{name}")
        except ModuleNotFoundError as exc:
            if exc.name == f"station.bench.{name}":
                continue
            raise
        module.register(bench_app)
    app.add_typer(bench_app, name="bench")
