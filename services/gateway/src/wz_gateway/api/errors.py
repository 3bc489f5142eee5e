"""Every error the API answers, as ``application/problem+json`` (RFC 9457): a ``detail`` a
person can act on and, for bad input, ``errors`` naming each field.

:class:`InputError` is input that parsed but makes no sense (``start`` after ``end``); the
handlers turn it, FastAPI's validation errors, ``HTTPException``, a bad cursor, a busy
database and anything unexpected into problems; :func:`add_exception_handlers` registers them.
:data:`V1_RESPONSES` documents the problems every ``/v1`` route may answer.
"""

from __future__ import annotations

import logging
from http import HTTPStatus
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from sqlalchemy.exc import OperationalError
from starlette.exceptions import HTTPException

from wz_gateway.models import Problem, ProblemField
from wz_gateway.store_types import CursorError

log = logging.getLogger(__name__)

PROBLEM_JSON = "application/problem+json"


class InputError(Exception):
    """Input that parsed but makes no sense (``start`` after ``end``...): a 422 problem."""

    def __init__(self, location: str, message: str) -> None:
        super().__init__(f"{location}: {message}")
        self.location = location
        self.message = message


def problem(
    status: int,
    detail: str,
    *,
    instance: str | None = None,
    errors: list[ProblemField] | None = None,
    headers: dict[str, str] | None = None,
) -> JSONResponse:
    """A problem answer with this status and ``detail``."""
    body = Problem(
        title=HTTPStatus(status).phrase,
        status=status,
        detail=detail,
        instance=instance,
        errors=errors,
    )
    return JSONResponse(
        body.model_dump(mode="json", exclude_none=True),
        status_code=status,
        media_type=PROBLEM_JSON,
        headers=headers,
    )


def problem_response(description: str) -> dict[str, Any]:
    """The OpenAPI description of a problem answer (for a route's ``responses``)."""
    return {
        "description": description,
        "model": Problem,
        "content": {PROBLEM_JSON: {"schema": {"$ref": "#/components/schemas/Problem"}}},
    }


V1_RESPONSES: dict[int | str, dict[str, Any]] = {
    400: problem_response("A body that cannot be read (not UTF-8 JSON)"),
    401: problem_response("No API key, or one that is not valid"),
    403: problem_response("The key's scope does not allow this"),
    413: problem_response("Request body too large"),
    422: problem_response("Invalid input: `errors` names each field"),
    429: problem_response("Too many requests: retry after `Retry-After` seconds"),
    503: problem_response("Database busy or unavailable"),
}


def _location(loc: tuple[Any, ...]) -> str:
    kind = str(loc[0]) if loc else "request"
    rest = ".".join(str(part) for part in loc[1:])
    return f"{kind}.{rest}" if rest else kind


def _describe(location: str) -> str:
    kind, _, name = location.partition(".")
    words = {
        "query": "query parameter",
        "path": "path parameter",
        "header": "header",
        "body": "body field",
    }
    if kind == "body" and not name:
        return "the request body"
    return f"{words.get(kind, kind)} {name!r}" if name else kind


def _field_problem(error: Any) -> ProblemField:
    loc = tuple(error.get("loc", ()))
    if error.get("type") == "json_invalid":  # loc is ("body", character position)
        reason = (error.get("ctx") or {}).get("error", "invalid")
        at = f" at character {loc[1]}" if len(loc) > 1 else ""
        return ProblemField(location="body", message=f"not valid JSON ({reason}{at})")
    return ProblemField(location=_location(loc), message=str(error.get("msg")))


async def _on_validation_error(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, RequestValidationError)
    errors = [_field_problem(e) for e in exc.errors()]
    first = errors[0] if errors else ProblemField(location="request", message="invalid")
    more = f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""
    detail = f"{_describe(first.location)}: {first.message}{more}"
    return problem(422, detail, instance=request.url.path, errors=errors)


async def _on_input_error(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, InputError)
    return problem(
        422,
        f"{_describe(exc.location)}: {exc.message}",
        instance=request.url.path,
        errors=[ProblemField(location=exc.location, message=exc.message)],
    )


async def _on_cursor_error(request: Request, exc: Exception) -> JSONResponse:
    return await _on_input_error(request, InputError("query.cursor", str(exc)))


async def _on_http_error(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, HTTPException)
    detail = exc.detail if isinstance(exc.detail, str) else HTTPStatus(exc.status_code).description
    if exc.status_code == 404 and detail == "Not Found":
        detail = f"no such resource: {request.url.path} (see /docs for the routes)"
    elif exc.status_code == 400 and detail == "There was an error parsing the body":
        detail = "the request body could not be read: send UTF-8 JSON"
    elif exc.status_code == 405:
        detail = f"{request.method} is not allowed on {request.url.path}"
    return problem(
        exc.status_code, detail, instance=request.url.path, headers=dict(exc.headers or {})
    )


async def _on_database_error(request: Request, exc: Exception) -> JSONResponse:
    log.warning("database error on %s: %s", request.url.path, exc)
    return problem(
        503,
        "the database is busy or unavailable; try again shortly",
        instance=request.url.path,
        headers={"Retry-After": "5"},
    )


async def _on_unexpected(request: Request, exc: Exception) -> JSONResponse:
    log.error("unexpected error on %s %s", request.method, request.url.path, exc_info=exc)
    return problem(
        500, "internal error in the gateway; its log has the details", instance=request.url.path
    )


def add_exception_handlers(app: FastAPI) -> None:
    """Answer every error as a problem."""
    app.add_exception_handler(RequestValidationError, _on_validation_error)
    app.add_exception_handler(InputError, _on_input_error)
    app.add_exception_handler(CursorError, _on_cursor_error)
    app.add_exception_handler(HTTPException, _on_http_error)
    app.add_exception_handler(OperationalError, _on_database_error)
    app.add_exception_handler(Exception, _on_unexpected)
