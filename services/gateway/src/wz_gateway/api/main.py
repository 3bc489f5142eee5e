"""Every router of the API, in the order they are matched (and listed in the OpenAPI document),
and the live page's files."""

from __future__ import annotations

from fastapi import APIRouter

from wz_gateway.api.routes import (
    alerts,
    calibration,
    conflicts,
    health,
    keys,
    live,
    metrics,
    queue,
    sites,
    tracks,
    webhooks,
    wzdx,
)

api_router = APIRouter()
for _router in (
    sites.router,
    tracks.router,
    conflicts.router,
    alerts.router,
    queue.router,
    calibration.router,
    wzdx.router,
    keys.router,
    webhooks.router,
    live.router,
    live.page_router,
    health.router,
    metrics.router,
):
    api_router.include_router(_router)

static_files = live.static_files
