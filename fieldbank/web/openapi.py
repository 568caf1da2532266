"""The OpenAPI 3.1 document of the workspace's JSON API, made from the routes themselves.

Every :class:`~fieldbank.web.routes.Route` with ``api=True`` becomes one operation: its summary,
parameters, request body schema, the permission it needs (``x-permission``) and the errors every
route may answer with. Nothing is written twice: a route that exists is documented, and a route
that is documented exists (``tests/test_workspace_api.py`` checks docs/api.md against it too).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from fieldbank.web.routes import PERMISSIONS, Route

ERROR = {"type": "object", "required": ["error"],
         "properties": {"error": {"type": "string",
                                  "description": "what went wrong, in the command line's words"}}}
ERRORS = {
    "400": "refused input, or a library error (its message)",
    "401": "no valid session or token",
    "403": "the role lacks the permission, or a change without the CSRF token",
    "404": "no such patient, model, plan or route",
    "429": "too many failed logins (Retry-After says how long to wait)",
}


def _operation(r: Route) -> dict[str, Any]:
    op: dict[str, Any] = {
        "summary": r.summary,
        "operationId": (r.method.lower() + r.path.replace("/api", "").replace("/", "_")
                        .replace("{", "").replace("}", "").replace(".", "_").replace("-", "_")),
        "tags": list(r.tags) or ["workspace"],
        "responses": {"200": {"description": "OK", "content": {"application/json": {
            "schema": dict(r.response or {"type": "object"})}}},
            **{k: {"description": v, "content": {"application/json": {
                "schema": {"$ref": "#/components/schemas/Error"}}}} for k, v in ERRORS.items()}},
    }
    if r.permission is None:
        op["security"] = []
    else:
        op["x-permission"] = r.permission
    if r.params:
        op["parameters"] = [{"name": p.name, "in": p.where, "required": p.required,
                             "description": p.description, "schema": {"type": p.type}}
                            for p in r.params]
    if r.body is not None:
        op["requestBody"] = {"required": True, "content": {"application/json": {
            "schema": dict(r.body)}}}
    return op


def openapi_document(routes: Sequence[Route]) -> dict[str, Any]:
    """The document for ``routes`` (the API ones)."""
    paths: dict[str, dict[str, Any]] = {}
    for r in routes:
        if r.api:
            paths.setdefault(r.path, {})[r.method.lower()] = _operation(r)
    return {
        "openapi": "3.1.0",
        "info": {"title": "fieldbank workspace API", "version": "1",
                 "description": "The JSON API the workspace page itself uses. Log in through "
                                "the page (a session cookie; every change then carries the "
                                "X-CSRF-Token header) or send 'Authorization: Bearer TOKEN' "
                                "with a token from 'fieldbank users token NAME'. Permissions: "
                                + "; ".join(f"{k}: {v}" for k, v in PERMISSIONS.items())
                                + ". Results are model predictions, not treatment advice."},
        "paths": dict(sorted(paths.items())),
        "components": {
            "schemas": {"Error": ERROR},
            "securitySchemes": {
                "bearer": {"type": "http", "scheme": "bearer"},
                "session": {"type": "apiKey", "in": "cookie", "name": "fb_session"}},
        },
        "security": [{"bearer": []}, {"session": []}],
    }
