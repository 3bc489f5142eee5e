"""``GET /metrics``: Prometheus metrics (HTTP, ingestion, bus, queue, retention); no key."""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.responses import Response
from prometheus_client import CONTENT_TYPE_LATEST, generate_latest

from wz_gateway.api.deps import Ctx

router = APIRouter()


@router.get(
    "/metrics",
    tags=["operations"],
    response_class=Response,
    responses={
        200: {
            "content": {"text/plain": {"schema": {"type": "string"}}},
            "description": "Prometheus text format",
        }
    },
)
def prometheus(context: Ctx) -> Response:
    """Prometheus metrics: HTTP, ingestion, bus, queue, retention."""
    return Response(generate_latest(context.metrics.registry), media_type=CONTENT_TYPE_LATEST)
