"""The API keys (admin): ``GET``/``POST /v1/admin/api-keys`` (list, make: the secret is in
the answer only) and ``DELETE /v1/admin/api-keys/{key_id}`` (revoke at once)."""

from __future__ import annotations

import logging
from typing import Annotated

from fastapi import APIRouter, Path, Query
from fastapi.responses import Response
from starlette.exceptions import HTTPException

from wz_gateway import auth
from wz_gateway.api.deps import Admin, Ctx
from wz_gateway.api.errors import V1_RESPONSES, problem_response
from wz_gateway.key_store import KeyLimitError
from wz_gateway.models import ApiKeyInfo, CreatedApiKey, NewApiKey

log = logging.getLogger(__name__)

router = APIRouter(prefix="/v1", responses=V1_RESPONSES)


@router.get("/admin/api-keys", response_model=list[ApiKeyInfo], tags=["admin"])
def list_keys(
    context: Ctx, _: Admin, include_revoked: Annotated[bool, Query()] = False
) -> list[ApiKeyInfo]:
    """Every key (without secrets)."""
    return context.key_store.all(include_revoked=include_revoked)


@router.post(
    "/admin/api-keys",
    response_model=CreatedApiKey,
    status_code=201,
    tags=["admin"],
    responses={409: problem_response("As many keys are live as max_api_keys allows")},
)
def create_key(context: Ctx, principal: Admin, request_body: NewApiKey) -> CreatedApiKey:
    """Make a key. Its secret is in this answer only; the gateway keeps its hash. A key made
    in dev mode is revoked when the gateway next starts outside dev mode."""
    secret = auth.new_secret()
    try:
        info = context.key_store.add(
            request_body.scope,
            secret,
            name=request_body.name,
            origin="api",
            now=context.clock(),
            dev_mode=context.settings.dev_mode,
            max_live=context.settings.max_api_keys,
        )
    except KeyLimitError as exc:
        raise HTTPException(409, str(exc)) from exc
    log.info("API key %s (%s, %r) made by %s", info.key_id, info.scope, info.name, principal.key_id)
    return CreatedApiKey(**info.model_dump(), secret=secret)


@router.delete(
    "/admin/api-keys/{key_id}",
    status_code=204,
    tags=["admin"],
    responses={404: problem_response("No such live key")},
)
def revoke_key(
    context: Ctx,
    principal: Admin,
    key_id: Annotated[str, Path(pattern=r"^[0-9a-f]{12}$", description="The key's key_id")],
) -> Response:
    """Revoke a key at once (its record stays, marked revoked)."""
    if not context.key_store.revoke(key_id, context.clock()):
        raise HTTPException(404, f"no live key {key_id}")
    context.keys.clear()
    log.info("API key %s revoked by %s", key_id, principal.key_id)
    return Response(status_code=204)
