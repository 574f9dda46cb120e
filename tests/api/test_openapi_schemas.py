"""Every JSON answer of the API is described in ``/openapi.json`` by a named model.

A client generator, schemathesis and a reader of ``/docs`` learn the answers' shapes
only from the schema; FastAPI writes a bare ``{"type": "object"}`` for a route typed
``-> dict`` and nothing for a response declared without a model. So: every 2xx
response of every operation declares its content, a JSON one by a model of
:mod:`api.schemas` (a ``$ref`` to a component with properties), and every route of
:mod:`api.routes` that answers JSON declares a pydantic ``response_model``. The app's
schema is built without starting the station (no lifespan runs).
"""

from __future__ import annotations

import importlib
import pkgutil
import typing
from typing import Any

import pytest
from fastapi.datastructures import DefaultPlaceholder
from fastapi.responses import JSONResponse
from fastapi.routing import APIRoute
from pydantic import BaseModel

import api.routes
from api.app import create_app
from api.settings import Settings

JSON = "application/json"
REF_PREFIX = "#/components/schemas/"


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    return create_app(Settings(data_dir=tmp_path_factory.mktemp("openapi-data")))


@pytest.fixture(scope="module")
def schema(app) -> dict[str, Any]:
    return app.openapi()


def _operations(schema: dict[str, Any]):
    for path, item in schema["paths"].items():
        for method, op in item.items():
            yield f"{method.upper()} {path}", op


def _component(schema: dict[str, Any], ref: str) -> dict[str, Any]:
    assert ref.startswith(REF_PREFIX), ref
    return schema["components"]["schemas"][ref[len(REF_PREFIX):]]


def _json_schema_problem(schema: dict[str, Any], body: dict[str, Any] | None) -> str | None:
    """Why a JSON response's schema is not a named model's (None when it is one)."""
    if not body:
        return "no schema"
    if body.get("type") == "array":  # a list of a model
        return _json_schema_problem(schema, body.get("items"))
    ref = body.get("$ref")
    if ref is None:
        return f"an anonymous schema {body}, not a model of api.schemas"
    if not _component(schema, ref).get("properties"):
        return f"{ref} describes no properties"
    return None


def test_every_2xx_response_declares_its_content(schema):
    """A success without content is undocumented: a JSON one needs its model, any other
    its media type (QIF XML, PNG, the streams, the metrics text)."""
    problems = []
    for name, op in _operations(schema):
        for status, response in op["responses"].items():
            if not status.startswith("2") or status == "204":
                continue
            content = response.get("content")
            if not content:
                problems.append(f"{name} {status}: no content declared")
            elif JSON in content:
                why = _json_schema_problem(schema, content[JSON].get("schema"))
                if why:
                    problems.append(f"{name} {status}: {why}")
    assert not problems, "\n".join(problems)


def _response_class(route: APIRoute) -> type:
    rc = route.response_class
    return rc.value if isinstance(rc, DefaultPlaceholder) else rc


def _api_routes() -> list[APIRoute]:
    """The routes of every router module of :mod:`api.routes`, read from the routers
    themselves (the app keeps an included router as one entry of its own)."""
    routes = []
    for info in pkgutil.iter_modules(api.routes.__path__):
        module = importlib.import_module(f"api.routes.{info.name}")
        router = getattr(module, "router", None)
        if router is not None:
            routes += [r for r in router.routes if isinstance(r, APIRoute)]
    return routes


def test_every_json_route_declares_a_response_model():
    """The route's own declaration, not only the schema: a route answering JSON without
    a pydantic response model (``-> dict``) would answer whatever its dict holds."""
    routes = _api_routes()
    assert len(routes) >= 30, [r.path for r in routes]  # the routers were found
    problems = []
    for route in routes:
        if not issubclass(_response_class(route), JSONResponse):
            continue  # QIF, PNG, the streams, the metrics: their media type is declared in responses=
        model = route.response_model
        if not (isinstance(model, type) and issubclass(model, BaseModel)):
            problems.append(f"{sorted(route.methods)} {route.path}: response_model {model!r}")
    assert not problems, "\n".join(problems)


def _may_lack_keys(model: Any, seen: set | None = None) -> list[str]:
    """The fields, anywhere in a response model, that have a default: keys the dict it
    describes leaves out in some answers (docs of :mod:`api.schemas.common`)."""
    seen = set() if seen is None else seen
    if isinstance(model, type) and issubclass(model, BaseModel):
        if model in seen:
            return []
        seen.add(model)
        out = [f"{model.__name__}.{name}" for name, f in model.model_fields.items() if not f.is_required()]
        for f in model.model_fields.values():
            out += _may_lack_keys(f.annotation, seen)
        return out
    return [name for arg in typing.get_args(model) for name in _may_lack_keys(arg, seen)]


def test_a_key_absent_from_the_dict_stays_absent_from_the_answer():
    """A route whose model has fields with a default answers with
    ``response_model_exclude_unset``: otherwise a key its dict leaves out (a list item's
    characteristics, a silent drive's position) would come out as a new ``null``."""
    problems = []
    for route in _api_routes():
        optional = _may_lack_keys(route.response_model)
        if optional and not route.response_model_exclude_unset:
            problems.append(f"{sorted(route.methods)} {route.path}: {', '.join(optional[:4])} ...")
    assert not problems, "\n".join(problems)


def test_every_route_of_other_media_declares_it(schema):
    """A route answering other than JSON says so in its responses, with no JSON schema."""
    for route in _api_routes():
        if issubclass(_response_class(route), JSONResponse):
            continue
        for method in route.methods:
            responses = schema["paths"][route.path][method.lower()]["responses"]
            ok = [s for s in responses if s.startswith("2")]
            assert ok, f"{method} {route.path}: no success response"
            for status in ok:
                content = responses[status].get("content") or {}
                assert content and JSON not in content, f"{method} {route.path} {status}: {content}"


def test_the_models_say_what_their_fields_are(schema):
    """Spot checks that the schema is the models' (names as the API spells them)."""
    comps = schema["components"]["schemas"]
    assert "pass" in comps["Characteristic"]["properties"]  # the alias, not the Python name
    assert comps["Characteristic"]["properties"]["nominal"]["type"] == "number"
    assert {"characteristics", "images", "findings"} <= set(comps["Inspection"]["required"])
    assert "characteristics" not in comps["InspectionSummary"]["properties"]
    # a retried job order (200) is the same inspection as the new one (202)
    job = schema["paths"]["/api/v1/job-orders"]["post"]["responses"]
    assert job["200"]["content"][JSON]["schema"] == job["202"]["content"][JSON]["schema"]
