"""The ``station`` command.

Each area registers its commands from its own module (``register(app)``), so that
the CLI grows without one file that everybody edits; ``COMMANDS`` names the module of
each top-level command, which is imported only when that command runs.  This package and
``station/runtime.py`` are the only parts of ``station`` allowed to import
concrete drivers or ``sim``.
"""

from __future__ import annotations

import functools
import importlib
import sys

import typer
import typer.main
from typer.core import TyperGroup

#: every top-level command (a command or a group) and the module under station.cli that
#: adds it (its ``register(app)``), in the order ``station --help`` lists them (typer's:
#: single commands first, then groups). A command's module is imported when that command
#: runs, not at start: importing every area (the store and its migrations, statsmodels,
#: numba, the vision) took ~3 s of CPU before any command ran (``station parts list``:
#: 4.3-4.9 s, now 0.5), in every ``station`` process and in every child that
#: ``multiprocessing`` starts from one (the camera twin's render workers import the
#: parent's main script, the ``station`` console script, again)
COMMANDS = {
    "inspect": "inspect", "gauge": "gauge", "paper": "paper", "iso230": "iso230", "discover": "discover",
    "demo": "demo", "serve": "serve", "campaign": "campaign",
    "scanlog": "scanlog", "model": "model", "compensation": "compensation", "bench": "bench", "vision": "vision",
    "sim": "sim", "parts": "parts", "results": "results", "token": "token", "check": "campaign",
    "calibrate": "calibrate",
}

_SETTINGS = dict(no_args_is_help=True, add_completion=False, pretty_exceptions_show_locals=False)


@functools.cache
def load_commands(module_name: str) -> dict:
    """The click commands (and groups) that ``station.cli.<module_name>`` registers, by name
    (once per process: ``main`` and the group ask for the same module)."""
    module = importlib.import_module(f"station.cli.{module_name}")
    sub = typer.Typer(**_SETTINGS)
    module.register(sub)
    return dict(typer.main.get_group(sub).commands)


class _LazyGroup(TyperGroup):
    """The ``station`` group: a command's module is imported the first time it is asked for
    (click asks for every one only to list them, for ``--help``)."""

    def list_commands(self, ctx) -> list[str]:
        return list(COMMANDS)

    def get_command(self, ctx, cmd_name: str):
        if cmd_name not in self.commands and cmd_name in COMMANDS:
            for name, command in load_commands(COMMANDS[cmd_name]).items():
                self.commands.setdefault(name, command)
        return self.commands.get(cmd_name)


app = typer.Typer(
    name="station",
    help="Master-cylinder bore inspection station: error model, compensation, ISO 230-2, vision, twins.",
    cls=_LazyGroup,
    **_SETTINGS,
)


@app.callback()
def _station() -> None:
    # typer builds a group (ours, ``_LazyGroup``) from an app with a callback; without
    # one, an app with no command registered at import would have no command at all
    pass


#: the commands that run a station (its event loop carries the drives' 1 s heartbeats):
#: before they start, every area is imported, as it was at every start before
#: ``COMMANDS``, so that no module is imported for the first time inside a running
#: session (on a loaded PC a heavy first import there, discovery's for an axis check,
#: takes seconds). The other commands load only their own area, and so does the render
#: worker, which imports this module but never calls ``main``
RUNS_A_STATION = frozenset({"serve", "inspect", "campaign", "check", "calibrate", "demo", "gauge", "paper", "sim",
                            "bench"})


def main() -> None:
    if sys.argv[1:2] and sys.argv[1] in RUNS_A_STATION:
        for module_name in dict.fromkeys(COMMANDS.values()):
            load_commands(module_name)
    app()
