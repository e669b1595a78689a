"""The OpenAPI document as a contract: every error status an operation can answer, declared with
the one error envelope, derived from what the operation is built of.

An operation's error responses come from three places, merged:

- its dependencies: a dependency marked with `declares(...)` (authentication, a role check, the
  login limiter, the app-wide query check, the `If-Match` reader of server/kit/etag.py: 400,
  409 `edit_conflict`, 412) adds its errors to every operation that uses it, however deeply; a
  new shared mechanism is declared once, on its dependency, and every route using it documents
  it (a status the route declares too gets one response naming both codes);
- its shape: a path parameter names a resource of the caller's organisation (404, also for one of
  another organisation); a request body may be refused as unreadable (400: not UTF-8), for its
  size (413) or its content (422);
- what only its service knows (409 name taken, a run already ended...): `errors(...)` in the
  route's `responses`.

`document_errors(app)` writes them into every route's `responses` once the routes are included;
FastAPI then renders them (and its own 422 schema is never used: ours is declared first).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Mapping
from typing import Any, TypeVar

from fastapi import FastAPI
from fastapi.dependencies.models import Dependant
from fastapi.routing import APIRoute, iter_route_contexts
from pydantic import BaseModel, Field

from server.kit.errors import AppError, BadRequest, NotFound, TooLarge, Unprocessable

F = TypeVar("F", bound=Callable[..., Any])
MARK = "__openapi_errors__"


class ErrorInfo(BaseModel):
    """What went wrong: a stable code for programs, a sentence for people, details when useful."""

    code: str = Field(
        description="stable machine-readable code; see frontend_api.md for the list",
        examples=["not_found"],
    )
    message: str = Field(
        description="a sentence for people; may change between versions",
        examples=["mission 0b6c3bb2-5f0d-4c3e-9a55-5d1c1f0e8a01 not found"],
    )
    details: Any = Field(
        default=None,
        description="structured details (e.g. for validation_error a list of "
        "{loc, msg, type}); null when there are none",
        examples=[None],
    )


class ErrorEnvelope(BaseModel):
    """The one JSON shape of every error response."""

    error: ErrorInfo


def operation_id(route: APIRoute) -> str:
    """A short, stable operationId: the endpoint function's name in camelCase (`listMissions`).
    A route that wants another sets `operation_id=` itself; uniqueness is tested."""
    head, *rest = route.name.split("_")
    return head + "".join(word.capitalize() for word in rest)


Glossary = Mapping[str, tuple[str, Any]]  # field name or "Schema.field" -> (description, example)


def install(app: FastAPI, fields: Glossary, overrides: Glossary) -> None:
    """Make the app's document the contract: error responses declared per operation, every field
    described (from `overrides`, then `fields`, unless the model describes it itself)."""
    build = app.openapi
    documented = False

    def openapi() -> dict[str, Any]:
        nonlocal documented
        schema = build()  # FastAPI's, cached on the app
        if not documented:
            document_errors(app, schema)
            describe_fields(schema, fields, overrides)
            documented = True
        return schema

    app.openapi = openapi  # type: ignore[method-assign]


def declares(*errors: type[AppError]) -> Callable[[F], F]:
    """Mark a dependency as able to raise `errors`: every operation using it declares them."""

    def mark(dependency: F) -> F:
        setattr(dependency, MARK, (*getattr(dependency, MARK, ()), *errors))
        return dependency

    return mark


def _description(errors: Iterable[type[AppError]]) -> str:
    seen: dict[str, None] = {}
    for error in errors:
        doc = (error.__doc__ or "").strip().splitlines()[0] if error.__doc__ else ""
        seen[f"{doc} (`{error.code}`)" if doc else f"`{error.code}`"] = None
    return "; ".join(seen)


def errors(*errors: type[AppError]) -> dict[int | str, dict[str, Any]]:
    """`responses` for a route: each error's status, with the envelope and the errors' meaning."""
    by_status: dict[int, list[type[AppError]]] = {}
    for error in errors:
        by_status.setdefault(error.status, []).append(error)
    return {
        status: {"model": ErrorEnvelope, "description": _description(group)}
        for status, group in sorted(by_status.items())
    }


def _dependencies(dependant: Dependant) -> Iterator[Dependant]:
    for sub in dependant.dependencies:
        yield sub
        yield from _dependencies(sub)


def api_routes(app: FastAPI) -> Iterator[APIRoute]:
    """Every documented operation's route as the app serves it (its routers' and the app's
    dependencies included)."""
    for context in iter_route_contexts(app.routes):
        if isinstance(context.original_route, APIRoute) and context.include_in_schema:
            yield context  # type: ignore[misc]  # a view of the effective APIRoute


def derived_errors(route: APIRoute) -> list[type[AppError]]:
    """The errors an operation can answer by what it is built of (see the module's docstring)."""
    found: list[type[AppError]] = [Unprocessable]  # a malformed or unknown query parameter, a NUL
    for sub in _dependencies(route.dependant):
        found.extend(getattr(sub.call, MARK, ()))
    if route.dependant.path_params:
        found.append(NotFound)
    if route.body_field is not None or "requestBody" in (route.openapi_extra or {}):
        found += [BadRequest, TooLarge]  # a body that is not text (not UTF-8); over the limit
    return found


VALIDATION_SCHEMAS = ("HTTPValidationError", "ValidationError")  # FastAPI's, never our shape


def _envelope_schemas() -> dict[str, Any]:
    schema = ErrorEnvelope.model_json_schema(ref_template="#/components/schemas/{model}")
    defs = schema.pop("$defs", {})
    return {"ErrorEnvelope": schema, **defs}


def _error_response(description: str) -> dict[str, Any]:
    return {
        "description": description,
        "content": {"application/json": {"schema": {"$ref": ENVELOPE_REF}}},
    }


ENVELOPE_REF = "#/components/schemas/ErrorEnvelope"


def _with_codes(description: str, derived: Iterable[type[AppError]], status: int) -> str:
    """A route's own description of `status`, plus the derived errors of that status it does not
    name yet."""
    missing = [e for e in derived if e.status == status and f"`{e.code}`" not in description]
    return "; ".join(part for part in (description, _description(missing)) if part)


def _is_ours(response: dict[str, Any]) -> bool:
    """A response the route declared itself with a body other than FastAPI's validation shape."""
    refs = str(response.get("content", {}))
    return "content" in response and not any(name in refs for name in VALIDATION_SCHEMAS)


def document_errors(app: FastAPI, schema: dict[str, Any]) -> dict[str, Any]:
    """Declare in `schema` (the app's generated document) each error status every operation can
    answer, with the envelope; FastAPI's own validation-error schemas are dropped."""
    components = schema.setdefault("components", {}).setdefault("schemas", {})
    components.update(_envelope_schemas())
    for route in api_routes(app):
        for method in route.methods or ():
            operation = schema["paths"][route.path_format][method.lower()]
            responses = operation.setdefault("responses", {})
            derived = derived_errors(route)
            for status, declared in errors(*derived).items():
                mine = responses.get(str(status))
                if mine is not None and _is_ours(mine):
                    # declared by the route too (409 name taken + a dependency's edit_conflict)
                    mine["description"] = _with_codes(
                        mine.get("description", ""), derived, int(status)
                    )
                    continue
                description = (mine or {}).get("description")
                if not description or description == "Validation Error":
                    description = declared["description"]
                responses[str(status)] = _error_response(description)
    text = str(schema["paths"])
    for name in VALIDATION_SCHEMAS:
        if f"/{name}'" not in text:
            components.pop(name, None)
    return schema


def describe_fields(schema: dict[str, Any], fields: Glossary, overrides: Glossary) -> None:
    """Give every property of every component schema a description and, when the glossary has
    one, an example; what the model says itself is kept."""
    for name, component in schema.get("components", {}).get("schemas", {}).items():
        for field, prop in component.get("properties", {}).items():
            found = overrides.get(f"{name}.{field}") or fields.get(field)
            if found is None:
                continue
            description, example = found
            prop.setdefault("description", description)
            if example is not None and "examples" not in prop and "$ref" not in prop:
                prop["examples"] = [example]
