"""Helpers shared by CLI commands: errors to stderr with a non-zero exit, JSON to stdout."""

from __future__ import annotations

import json
import sys
from typing import Any, NoReturn

import numpy as np
import typer
from rich.console import Console

#: width when the output is not a terminal (a log, a pipe, CI): tables are not squeezed
#: to the 80 columns rich assumes, which would cut figures off
_PIPE_WIDTH = 132

#: human-readable output goes to stderr when stdout carries JSON
err_console = Console(stderr=True, soft_wrap=True, width=None if sys.stderr.isatty() else _PIPE_WIDTH)
out_console = Console(width=None if sys.stdout.isatty() else _PIPE_WIDTH)


def fail(message: str, code: int = 2) -> NoReturn:
    """Print a clear error (no traceback) and exit non-zero."""
    err_console.print(f"[bold red]error:[/] {message}", highlight=False, markup=True)
    raise typer.Exit(code)


def json_default(o: Any):
    """``json.dumps``' default for numpy scalars and arrays (the CLI's JSON and files)."""
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def print_json(obj: Any) -> None:
    """Exactly one JSON document on stdout."""
    sys.stdout.write(json.dumps(obj, indent=2, default=json_default, allow_nan=False) + "\n")
    sys.stdout.flush()
