"""The live stream (``GET /v1/stream``, Server-Sent Events) and the live page (``/live``).

The page is static (HTML, vanilla JavaScript, a canvas; ``static/`` beside this file): it
reads ``/v1/site``, ``/v1/alerts`` and ``/v1/calibration`` once, then follows the stream. It
is served without a key (it holds no data); what it reads needs one, as every ``/v1`` route
does, except in dev mode. Browsers' ``EventSource`` cannot send a header, so the page reads the stream with
``fetch`` and sends its key as ``X-API-Key``.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Annotated

from fastapi import APIRouter, Depends, Header, Query
from fastapi.responses import FileResponse, RedirectResponse, StreamingResponse
from starlette.exceptions import HTTPException
from starlette.staticfiles import StaticFiles

from wz_gateway.api.deps import Ctx, require_read
from wz_gateway.api.errors import V1_RESPONSES
from wz_gateway.live import EVENT_KINDS, Broadcaster, EventKind, Subscription, TooManyClientsError

log = logging.getLogger(__name__)

STATIC_DIR = Path(__file__).resolve().parents[2] / "static"
#: The page loads its own script, style and icon, and talks to this gateway only.
PAGE_SECURITY_POLICY = (
    "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data:; "
    "connect-src 'self'; object-src 'none'; base-uri 'none'; frame-ancestors 'none'"
)
EVENT_STREAM = "text/event-stream"
#: How long a client waits before it reconnects [ms] (the stream's ``retry`` hint).
RETRY_MS = 2000

router = APIRouter(prefix="/v1", dependencies=[Depends(require_read)], responses=V1_RESPONSES)
page_router = APIRouter(include_in_schema=False)


async def _event_stream(
    subscription: Subscription, broadcaster: Broadcaster, heartbeat_s: float, retry_ms: int
) -> AsyncIterator[str]:
    try:
        yield f"retry: {retry_ms}\n: stream of {', '.join(sorted(subscription.kinds))}\n\n"
        while True:
            try:
                event = await asyncio.wait_for(subscription.get(), timeout=heartbeat_s)
            except TimeoutError:
                yield ": keep-alive\n\n"  # a comment: keeps proxies and the client's timer happy
                continue
            if event is None:
                return
            yield event.sse()
    finally:
        broadcaster.unsubscribe(subscription)
        if subscription.dropped or subscription.decimated:
            log.info(
                "stream client left: %d events dropped (slow reader), %d track batches decimated",
                subscription.dropped,
                subscription.decimated,
            )


@router.get(
    "/stream",
    tags=["tracks"],
    response_class=StreamingResponse,
    responses={
        200: {
            "description": "An endless text/event-stream: events `tracks`, `alert` and "
            "`calibration`, `: keep-alive` comments in between",
            "content": {EVENT_STREAM: {"schema": {"type": "string"}}},
        },
        503: {
            **V1_RESPONSES[503],
            "description": "Database unavailable, or the "
            "stream has all the clients it takes (`stream_max_clients`): retry later",
        },
    },
)
async def get_stream(
    context: Ctx,
    event: Annotated[
        list[EventKind] | None,
        Query(description="Events to send (repeat for several); default: all"),
    ] = None,
    last_event_id: Annotated[
        str | None,
        Header(
            max_length=64,
            description="Sent by a reconnecting client: the alerts it missed come first",
        ),
    ] = None,
) -> StreamingResponse:
    """Live events as Server-Sent Events: ``tracks`` (the newest track batch, compact, at
    most ``stream_max_hz`` a second), ``alert`` (each alert as it is stored) and
    ``calibration`` (each sensor's self-calibration as it is stored; each sensor's newest
    first on connecting), each with an ``id``; a ``retry`` hint first and a comment every ``stream_heartbeat_s``. A client
    that reads too slowly loses its oldest events, never holds up the gateway."""
    kinds = frozenset(event or EVENT_KINDS)
    try:
        subscription = context.live.subscribe(kinds, last_event_id)
    except TooManyClientsError as exc:
        raise HTTPException(503, f"{exc}; retry later", headers={"Retry-After": "10"}) from exc
    return StreamingResponse(
        _event_stream(subscription, context.live, context.settings.stream_heartbeat_s, RETRY_MS),
        media_type=EVENT_STREAM,
        headers={"Cache-Control": "no-cache", "X-Accel-Buffering": "no"},
    )


@page_router.get("/")
def root() -> RedirectResponse:
    return RedirectResponse("/live", status_code=307)


@page_router.get("/live")
def live_page() -> FileResponse:
    return FileResponse(
        STATIC_DIR / "live.html",
        media_type="text/html",
        headers={"Content-Security-Policy": PAGE_SECURITY_POLICY, "Cache-Control": "no-cache"},
    )


def static_files() -> StaticFiles:
    """The page's script, style and icon (mounted at ``/static``)."""
    return StaticFiles(directory=STATIC_DIR)
