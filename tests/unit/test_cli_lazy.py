"""The ``station`` command imports a command's module only when that command runs
(``station.cli.COMMANDS``): every ``station`` process, and every render worker that
``multiprocessing`` starts from one, imports the console script again."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

from typer.testing import CliRunner

import station.cli
from station.cli import COMMANDS, RUNS_A_STATION, app, load_commands

CLI_DIR = Path(station.cli.__file__).parent


def test_every_command_module_is_named_with_the_commands_it_adds():
    modules = sorted(p.stem for p in CLI_DIR.glob("*.py") if "\ndef register(" in p.read_text(encoding="utf-8"))
    assert sorted(set(COMMANDS.values())) == modules
    assert RUNS_A_STATION <= set(COMMANDS)
    for module in modules:
        added = set(load_commands(module))
        assert added == {name for name, m in COMMANDS.items() if m == module}, module


def test_importing_the_cli_imports_no_area():
    code = ("import sys, station.cli\n"
            "heavy = ('station.store', 'station.discovery', 'station.vision', 'station.inspection', 'sqlalchemy',"
            " 'statsmodels', 'numba', 'scipy', 'cv2', 'sim', 'drivers')\n"
            "print(sorted(m for m in sys.modules if any(m == h or m.startswith(h + '.') for h in heavy)))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert out.stdout.strip() == "[]", out.stdout


def test_help_lists_every_command_and_a_command_runs():
    runner = CliRunner()
    result = runner.invoke(app, ["--help"], terminal_width=200)
    assert result.exit_code == 0, result.output
    # a command's row starts with its name; its help's second line starts with spaces
    listed = [m.group(1) for m in (re.match(r"│ ([a-z0-9-]+) ", line) for line in result.output.splitlines()) if m]
    assert [name for name in listed if name != "--help"] == list(COMMANDS)
    result = runner.invoke(app, ["parts", "list"])
    assert result.exit_code == 0 and "ZDZG-22.2-12.3851" in result.output, result.output
    result = runner.invoke(app, ["no-such-command"])
    assert result.exit_code != 0 and "No such command" in result.output


def _areas_loaded_by(args: list[str]) -> list[bool]:
    code = ("import sys\n"
            f"sys.argv = ['station', *{args!r}]\n"
            "from station.cli import main\n"
            "try:\n    main()\nexcept SystemExit:\n    pass\n"
            "import json\n"
            "print(json.dumps([m in sys.modules for m in ('station.discovery', 'station.exports.qif',"
            " 'station.bench.vision')]))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_a_command_that_runs_a_station_imports_every_area_before_it_starts():
    # no module is imported for the first time inside a running session, where the
    # drives' heartbeats ride the station's loop; a command that runs none stays light
    assert _areas_loaded_by(["inspect", "--help"]) == [True, True, True]
    assert _areas_loaded_by(["parts", "list"]) == [False, False, False]
