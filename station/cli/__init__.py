"""The ``station`` command.

Each area registers its commands from its own module (``register(app)``), so that
the CLI grows without one file that everybody edits.  This package and
``station/runtime.py`` are the only parts of ``station`` allowed to import
concrete drivers or ``sim``.
"""

from __future__ import annotations

import importlib

import typer

app = typer.Typer(
    name="station",
    help="Master-cylinder bore inspection station: error model, compensation, ISO 230-2, vision, twins.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_show_locals=False,
)

#: modules under station.cli that add commands; each defines register(app)
_COMMAND_MODULES = ("inspect", "gauge", "paper", "scanlog", "model", "iso230", "compensation", "bench", "vision", "sim", "discover", "demo", "parts", "results", "serve", "token", "campaign", "calibrate")


def _register_all() -> None:
    for name in _COMMAND_MODULES:
        try:
            module = importlib.import_module(f"station.cli.{name}")
        except ModuleNotFoundError as exc:
            if exc.name == f"station.cli.{name}":
                continue  # that area is not built yet
            raise
        module.register(app)


_register_all()


def main() -> None:
    app()
