"""``GET /healthz`` (the process answers) and ``GET /readyz`` (the database answers at the
expected schema, and the node's own checks such as the bus); no key needed."""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.responses import JSONResponse

from wz_gateway.api.deps import Ctx
from wz_gateway.models import Health, Readiness
from wz_gateway.tables import SCHEMA_VERSION

router = APIRouter()


@router.get("/healthz", response_model=Health, tags=["operations"])
def healthz() -> Health:
    """The process answers."""
    return Health(status="ok")


@router.get(
    "/readyz",
    response_model=Readiness,
    tags=["operations"],
    responses={503: {"model": Readiness, "description": "Not ready"}},
)
def readyz(context: Ctx) -> JSONResponse:
    """Ready to serve: the database answers at the expected schema (and the bus is up)."""
    checks: dict[str, str] = {}
    try:
        version = context.storage.current_schema_version()
        checks["database"] = (
            "ok"
            if version == SCHEMA_VERSION
            else f"schema version {version}, expected {SCHEMA_VERSION}"
        )
    except Exception as exc:  # any failure means not ready; say which
        checks["database"] = f"unreachable: {type(exc).__name__}"
    if context.readiness is not None:
        checks.update(context.readiness())
    ready = all(value == "ok" for value in checks.values())
    body = Readiness(status="ready" if ready else "not_ready", checks=checks)
    return JSONResponse(body.model_dump(), status_code=200 if ready else 503)
