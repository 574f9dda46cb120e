"""Part specs: the built-in ones and the station's own (``<data>/parts/*.toml``).

``PUT`` takes the spec as JSON, validates it with the same pydantic models as a spec
file (every problem reported with its field), and stores it as TOML where
``load_part`` finds it, so a job order can use it at once.
"""

from __future__ import annotations

import os
from pathlib import Path

from fastapi import APIRouter, Body, HTTPException, status
from pydantic import ValidationError

from api.deps import EngineerDep, ReaderDep, RuntimeDep
from api.routes.common import blocking
from api.schemas.parts import PartList, PartSpecDoc
from api.toml_write import dumps
from station.parts import PartSpecError, list_parts, load_part
from station.parts.loader import Problem, validation_problems
from station.parts.spec import PartSpec, is_part_number

router = APIRouter(prefix="/api/v1", tags=["part specs"])


def is_plain_part_number(text: str) -> bool:
    """A part number from a request that ``load_part`` takes as a number, never as a
    file: it reads a string ending in ``.toml`` as a path (from the server's working
    directory), which a request must not reach."""
    return is_part_number(text) and not text.endswith(".toml")


def load_by_number(part_number: str, parts_dir: Path) -> PartSpec:
    """The spec of a part number from a request: ``<data>/parts`` first, then the
    built-ins; never a file named by the request (:func:`is_plain_part_number`)."""
    if not is_plain_part_number(part_number):
        raise PartSpecError([Problem(repr(part_number), None, "",
                                     "not a part number (letters, digits, '.', '_', '-'; not ending in .toml)")])
    return load_part(part_number, [parts_dir])


def _check_number(part_number: str) -> None:
    if not is_plain_part_number(part_number):
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"{part_number!r} is not a part number")


@router.get("/parts", response_model=PartList, response_model_exclude_unset=True)
async def get_parts(rt: RuntimeDep, who: ReaderDep) -> dict:
    try:
        specs = await blocking(list_parts, [rt.settings.parts_dir])
    except PartSpecError as exc:
        raise HTTPException(status.HTTP_500_INTERNAL_SERVER_ERROR, f"a stored part spec is broken: {exc}") from None
    return {"items": [s.to_json() for s in specs]}


@router.get("/parts/{part_number}", response_model=PartSpecDoc, response_model_exclude_unset=True,
            responses={404: {"description": "no such part spec, or not a part number"}})
async def get_part(part_number: str, rt: RuntimeDep, who: ReaderDep) -> dict:
    _check_number(part_number)
    try:
        spec = await blocking(load_by_number, part_number, rt.settings.parts_dir)
    except PartSpecError as exc:
        raise HTTPException(status.HTTP_404_NOT_FOUND, str(exc)) from None
    return spec.to_json()


def _write_atomically(path: Path, text: str) -> None:
    """Write beside, then rename: a reader sees the old spec or the new, never half."""
    tmp = path.with_suffix(".toml.tmp")
    with open(tmp, "w", encoding="utf-8") as f:
        f.write(text)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


@router.put("/parts/{part_number}", response_model=PartSpecDoc, response_model_exclude_unset=True,
            responses={422: {"description": "the spec is not valid (every problem listed)"}})
async def put_part(part_number: str, rt: RuntimeDep, who: EngineerDep,
                   body: dict = Body(..., description="the part spec as JSON "
                   "(the TOML file's structure, docs/part-specs.md)")) -> dict:
    _check_number(part_number)
    body = {k: v for k, v in body.items() if k != "characteristics"}  # derived, as GET shows them
    try:
        spec = PartSpec.model_validate(body)
    except ValidationError as exc:
        problems = validation_problems(exc, "", "request body")
        raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT,
                            [{"field": p.field, "message": p.message} for p in problems]) from None
    if spec.part_number != part_number:
        raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT,
                            f"the body's part_number {spec.part_number!r} differs from the URL's {part_number!r}")
    path = rt.settings.parts_dir / f"{part_number}.toml"
    existed = path.exists()
    text = dumps(spec.model_dump(mode="json", exclude_none=True),
                 header=f"part spec stored through the REST API by {who.name}")
    await blocking(_write_atomically, path, text)
    stored = await blocking(load_by_number, part_number, rt.settings.parts_dir)  # it must read back as sent
    await blocking(rt.audit, who.who, f"{'replaced' if existed else 'created'} part spec {part_number}")
    return stored.to_json()
