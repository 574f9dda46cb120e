"""Reading part spec files: from a path, or built in by part number.

Built-in specs live in ``station/data/parts/<part number>.toml`` and are read through
:mod:`importlib.resources`, so they are found the same way from a checkout, an
editable install or a wheel. Every problem of a file is reported at once, each with
the file, the line where the offending key (or its table) is written, and the field
in the path notation a person reads (``holes[1].position.tol``; list indexes count
from 0, as in the file's order).
"""

from __future__ import annotations

import re
import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Sequence

from pydantic import ValidationError

from station.parts.spec import PartSpec, SpecProblems, is_part_number

#: where the built-in part specs live inside the ``station`` package
_BUILTIN_DIR = ("data", "parts")


@dataclass(frozen=True)
class Problem:
    """One thing wrong with a spec file."""

    source: str
    line: int | None
    field: str
    message: str

    def __str__(self) -> str:
        where = self.source + (f", line {self.line}" if self.line is not None else "")
        return f"{where}: {self.field}: {self.message}" if self.field else f"{where}: {self.message}"


class PartSpecError(ValueError):
    """A part spec that cannot be used. ``problems`` lists every one found; the
    message is one line per problem."""

    def __init__(self, problems: list[Problem]):
        self.problems = problems
        super().__init__("\n".join(str(p) for p in problems))


def field_path(loc: tuple) -> str:
    """Pydantic's loc as a person writes it: ``('holes', 1, 'position', 'tol')`` ->
    ``holes[1].position.tol``."""
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + str(part)
    return out


_TABLE_ARRAY = re.compile(r"^\s*\[\[\s*([^\[\]]+?)\s*\]\]")
_TABLE = re.compile(r"^\s*\[\s*([^\[\]]+?)\s*\]")
_KEY = re.compile(r"^\s*([A-Za-z0-9_.\-\s\"']+?)\s*=")


def _split_key(key: str) -> tuple[str, ...]:
    return tuple(p.strip().strip("\"'") for p in key.split("."))


def line_of(text: str, loc: tuple) -> int | None:
    """Best-effort line number where ``loc`` (a pydantic loc) is written in TOML text.

    A small line scanner, not a TOML parser: it follows ``[table]`` and ``[[array]]``
    headers and ``key =`` lines and returns the line of the longest prefix of ``loc``
    it sees (the key itself, else the table that lacks it). Multi-line strings or
    arrays may mislead it; then the message still names file and field.
    """
    arrays: dict[tuple, int] = {}  # array-of-tables path (as written) -> current index
    current: tuple = ()
    best_depth, best_line = 0, None

    def expand(path: tuple[str, ...]) -> tuple:
        out: tuple = ()
        for i in range(len(path)):
            out += (path[i],)
            if path[: i + 1] in arrays:
                out += (arrays[path[: i + 1]],)
        return out

    def consider(path: tuple, lineno: int) -> None:
        nonlocal best_depth, best_line
        n = len(path)
        if n > best_depth and tuple(loc[:n]) == path:
            best_depth, best_line = n, lineno

    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0] if '"' not in raw and "'" not in raw else raw
        if m := _TABLE_ARRAY.match(line):
            path = _split_key(m.group(1))
            arrays[path] = arrays.get(path, -1) + 1
            current = expand(path)
            consider(current, lineno)
        elif m := _TABLE.match(line):
            current = expand(_split_key(m.group(1)))
            consider(current, lineno)
        elif m := _KEY.match(line):
            consider(current + _split_key(m.group(1)), lineno)
    return best_line


def validation_problems(exc: ValidationError, text: str, source: str) -> list[Problem]:
    problems = []
    for err in exc.errors():
        cause = (err.get("ctx") or {}).get("error")
        if isinstance(cause, SpecProblems):
            for loc, msg in cause.problems:
                full = tuple(err["loc"]) + tuple(loc)
                problems.append(Problem(source, line_of(text, full), field_path(full), msg))
            continue
        loc = tuple(err["loc"])
        msg = err["msg"]
        if err["type"] == "value_error":
            msg = msg.removeprefix("Value error, ")
        elif err["type"] == "extra_forbidden":
            msg = "unknown key (misspelt?)"
        elif err["type"] == "missing":
            msg = "required key is missing"
        problems.append(Problem(source, line_of(text, loc), field_path(loc), msg))
    # in file order, so a reader fixes the file top to bottom
    return sorted(problems, key=lambda p: (p.line is None, p.line or 0))


def parse_toml_as(model_cls, text: str, source: str = "<text>"):
    """Validate TOML text as ``model_cls`` (a pydantic model: a part spec, a master's
    certificate); :class:`PartSpecError` lists every problem with its line and field.
    A UTF-8 byte-order mark (a file saved by a spreadsheet or Notepad) is dropped."""
    text = text.removeprefix("\ufeff")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        m = re.search(r"line (\d+)", str(exc))
        raise PartSpecError([Problem(source, int(m.group(1)) if m else None, "", f"not valid TOML: {exc}")]) from None
    try:
        return model_cls.model_validate(data)
    except ValidationError as exc:
        raise PartSpecError(validation_problems(exc, text, source)) from None


def builtin_names(folder: Sequence[str]) -> list[str]:
    """The ids of the ``.toml`` files in a folder of the ``station`` package, sorted."""
    d = resources.files("station").joinpath(*folder)
    return sorted(f.name.removesuffix(".toml") for f in d.iterdir() if f.name.endswith(".toml")) if d.is_dir() else []


def load_certificate(id_or_path: str | Path, parse, folder: Sequence[str], kind: str, id_field: str):
    """A certificate (a master's, an artefact's) by built-in id, or from a file by path
    (``.toml`` or a path separator), read with ``parse(text, source)``. A built-in
    file's id field must equal its name. Every failure is a :class:`PartSpecError`
    naming the file and key."""
    arg = str(id_or_path)
    if isinstance(id_or_path, Path) or arg.endswith(".toml") or "/" in arg or "\\" in arg:
        p = Path(arg)
        try:
            text = p.read_text(encoding="utf-8-sig")
        except OSError as exc:
            raise PartSpecError([Problem(str(p), None, "", f"cannot read: {exc.strerror or exc}")]) from None
        return parse(text, str(p))
    known = builtin_names(folder)
    if arg not in known:
        raise PartSpecError([Problem(repr(arg), None, "", f"no built-in {kind} of that id, and not a .toml path "
                                                          f"(built in: {', '.join(known) or 'none'})")])
    src = "station/" + "/".join(folder) + f"/{arg}.toml"
    cert = parse(resources.files("station").joinpath(*folder, f"{arg}.toml").read_text(encoding="utf-8-sig"), src)
    if getattr(cert, id_field) != arg:
        raise PartSpecError([Problem(src, None, id_field, f"{getattr(cert, id_field)!r} differs from the file name")])
    return cert


def parse_part(text: str, source: str = "<text>") -> PartSpec:
    """Validate TOML text as a part spec; :class:`PartSpecError` lists every problem."""
    return parse_toml_as(PartSpec, text, source)


def read_part_file(path: str | Path) -> PartSpec:
    """Read and validate a spec file at a path."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise PartSpecError([Problem(str(p), None, "", f"cannot read: {exc.strerror or exc}")]) from None
    except UnicodeDecodeError as exc:
        raise PartSpecError([Problem(str(p), None, "", f"not UTF-8 text: {exc.reason}")]) from None
    return parse_part(text, str(p))


def _builtin_dir():
    return resources.files("station").joinpath(*_BUILTIN_DIR)


def builtin_part_numbers() -> list[str]:
    """Part numbers of the built-in specs (file names), sorted."""
    d = _builtin_dir()
    if not d.is_dir():
        return []
    return sorted(f.name.removesuffix(".toml") for f in d.iterdir() if f.name.endswith(".toml"))


def _read_builtin(part_number: str) -> PartSpec:
    f = _builtin_dir().joinpath(f"{part_number}.toml")
    source = f"station/data/parts/{part_number}.toml"
    spec = parse_part(f.read_text(encoding="utf-8-sig"), source)
    if spec.part_number != part_number:
        # the file name is the look-up key: a mismatch would load the wrong part
        raise PartSpecError([Problem(source, line_of(f.read_text(encoding="utf-8-sig"), ("part_number",)),
                                     "part_number", f"{spec.part_number!r} differs from the file name")])
    return spec


def _in_search_path(part_number: str, search_path) -> Path | None:
    """The first ``<dir>/<part number>.toml`` of the search path that exists."""
    for d in search_path:
        f = Path(d) / f"{part_number}.toml"
        if f.is_file():
            return f
    return None


def load_part(part_number_or_path: str | Path, search_path: Sequence[str | Path] = ()) -> PartSpec:
    """A spec by part number (from ``search_path``'s folders first, in order, then the
    built-ins), or a spec file by path.

    A :class:`~pathlib.Path`, or a string that ends in ``.toml`` or contains a path
    separator, is read as a file; anything else is a part number. An unknown part
    number raises :class:`PartSpecError` naming the known ones. The search path lets
    a station keep its own specs (the REST API stores them in ``<data>/parts``).
    """
    arg = part_number_or_path
    if isinstance(arg, Path) or arg.endswith(".toml") or "/" in arg or "\\" in arg:
        return read_part_file(arg)
    if is_part_number(arg) and (found := _in_search_path(arg, search_path)) is not None:
        spec = read_part_file(found)
        if spec.part_number != arg:
            # the file name is the look-up key: a mismatch would load the wrong part
            raise PartSpecError([Problem(str(found), None, "part_number",
                                         f"{spec.part_number!r} differs from the file name")])
        return spec
    known = builtin_part_numbers()
    if not is_part_number(arg) or arg not in known:
        raise PartSpecError([Problem(
            repr(arg), None, "",
            "no built-in part spec of that number, and not a .toml path (built in: "
            + (", ".join(known) or "none") + ")",
        )])
    return _read_builtin(arg)


def list_parts(search_path: Sequence[str | Path] = ()) -> list[PartSpec]:
    """Every built-in part spec and every ``*.toml`` spec of ``search_path``, sorted by
    part number; a search-path spec hides a built-in of the same number (raises if
    one is broken: a spec that does not load is a bug to fix, not something to skip)."""
    numbers = set(builtin_part_numbers())
    for d in search_path:
        if Path(d).is_dir():
            numbers.update(f.stem for f in Path(d).glob("*.toml") if is_part_number(f.stem))
    return [load_part(pn, search_path) for pn in sorted(numbers)]
