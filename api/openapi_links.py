"""OpenAPI links: which response feeds which next request.

A client generator, and schemathesis's stateful tests, follow them: a job order's
answer names the inspection to poll and fetch as QIF; an uploaded model or
calibration version is the one to activate; a part spec written is the one to read.
FastAPI does not write links, so they are added to its generated schema here, by
(method, path) of both ends; a link to an operation that no longer exists fails at
start-up (``KeyError``), not silently.
"""

from __future__ import annotations

from typing import Any

#: (method, path, status) of the source -> {link name: (method, path, parameters)}
LINKS: dict[tuple[str, str, str], dict[str, tuple[str, str, dict[str, str]]]] = {}


def _job_links() -> dict[str, tuple[str, str, dict[str, str]]]:
    iid = {"inspection_id": "$response.body#/id"}
    return {"GetInspection": ("get", "/api/v1/inspections/{inspection_id}", iid),
            "GetInspectionQif": ("get", "/api/v1/inspections/{inspection_id}/qif", iid)}


for _status in ("202", "200"):
    LINKS[("post", "/api/v1/job-orders", _status)] = _job_links()
# the newest inspection of a listing (newest first)
LINKS[("get", "/api/v1/inspections", "200")] = {
    "GetNewestInspection": ("get", "/api/v1/inspections/{inspection_id}", {"inspection_id": "$response.body#/items/0/id"}),
    "GetNewestInspectionQif": ("get", "/api/v1/inspections/{inspection_id}/qif",
                               {"inspection_id": "$response.body#/items/0/id"})}
LINKS[("put", "/api/v1/parts/{part_number}", "200")] = {
    "GetPart": ("get", "/api/v1/parts/{part_number}", {"part_number": "$request.path.part_number"})}
for _kind in ("models", "calibrations"):
    LINKS[("post", f"/api/v1/{_kind}", "201")] = {
        "Activate": ("post", f"/api/v1/{_kind}/{{version}}/activate", {"version": "$response.body#/version"})}
    LINKS[("post", f"/api/v1/{_kind}/{{version}}/activate", "200")] = {
        "List": ("get", f"/api/v1/{_kind}", {})}

# a check on the master: the check to poll, its master inspection
LINKS[("post", "/api/v1/checks", "202")] = {
    "GetCheck": ("get", "/api/v1/checks/{check_id}", {"check_id": "$response.body#/id"}),
    "GetCheckInspection": ("get", "/api/v1/inspections/{inspection_id}", {"inspection_id": "$response.body#/id"})}


def add_links(schema: dict[str, Any]) -> dict[str, Any]:
    """Write :data:`LINKS` into a generated OpenAPI schema (in place; returned)."""
    paths = schema["paths"]
    for (method, path, status), links in LINKS.items():
        responses = paths[path][method]["responses"]
        target = responses.setdefault(status, {"description": "OK"})
        out = target.setdefault("links", {})
        for name, (to_method, to_path, parameters) in links.items():
            op_id = paths[to_path][to_method]["operationId"]
            out[name] = {"operationId": op_id, "parameters": dict(parameters)}
    return schema


def install(app) -> None:
    """Make ``app.openapi()`` return the schema with the links."""
    generate = app.openapi

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is None:
            app.openapi_schema = add_links(generate())
        return app.openapi_schema

    app.openapi = openapi
