"""The gateway's HTTP API (FastAPI): build it with :func:`create_app`; nothing at import time.
The routes live in :mod:`wz_gateway.api.routes` (one module per resource), what they ask for
in :mod:`wz_gateway.api.deps`, the errors in :mod:`wz_gateway.api.errors`.

Routes (OpenAPI at ``/openapi.json``, docs at ``/docs``)::

    GET    /v1/sites                     the sites served (several at a central gateway)
    GET    /v1/site                      the site description
    GET    /v1/tracks/live               the newest fused tracks (WGS84 positions added)
    GET    /v1/tracks/{track_id}         one track's stored trajectory  (json|csv|geojson|parquet)
    GET    /v1/trajectories              stored points by time, area, speed (...|parquet)
    GET    /v1/alerts                    alert events by type, severity, phase, time
    GET    /v1/wzdx/device-feed          the WZDx 4.2 DeviceFeed
    GET    /v1/stream                    live tracks and alerts (Server-Sent Events)
    GET    /v1/admin/api-keys            the keys (admin)
    POST   /v1/admin/api-keys            make a key; its secret is shown once (admin)
    DELETE /v1/admin/api-keys/{key_id}   revoke a key (admin)
    ...    /v1/webhooks                  signed webhook subscriptions (admin)
    GET    /healthz  /readyz  /metrics   liveness, readiness, Prometheus (no key)

Every ``/v1`` route needs a key (header ``X-API-Key``, or ``Authorization: Bearer``) of scope
``read`` (``admin`` for ``/v1/admin``); in dev mode reads need none. Each key (or address,
without a key) has a token bucket; past it, 429 with ``Retry-After``. Bodies above
``max_body_bytes`` get 413. Every error is ``application/problem+json`` (RFC 9457) with a
``detail`` a person can act on and, for bad input, ``errors`` naming each field.

A central gateway serves several sites (:mod:`wz_gateway.sites`): every route that reads a
site's data takes ``site=<site id>`` (default: the first site; an unknown one is 404);
``/v1/alerts`` also takes ``site=*`` (every site's) and the device feed without ``site`` lists
every site's devices.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from fastapi import FastAPI

from wz_gateway import auth
from wz_gateway.api.deps import GatewayContext
from wz_gateway.api.errors import add_exception_handlers
from wz_gateway.api.main import api_router, static_files
from wz_gateway.api.middleware import add_middleware
from wz_gateway.key_store import KeyCache, KeyStore
from wz_gateway.live import Broadcaster, broadcaster_for
from wz_gateway.metrics import GatewayMetrics
from wz_gateway.settings import GatewaySettings
from wz_gateway.sites import Sites, load_sites
from wz_gateway.storage import Storage
from wz_shared.site import Site


def create_app(
    settings: GatewaySettings,
    storage: Storage,
    *,
    site: Site | Sites | None = None,
    metrics: GatewayMetrics | None = None,
    readiness: Callable[[], dict[str, str]] | None = None,
    clock: Callable[[], float] = time.time,
    live: Broadcaster | None = None,
) -> FastAPI:
    """The gateway's ASGI app.

    Parameters
    ----------
    settings : GatewaySettings
        Limits, CORS, dev mode, feed options.
    storage : Storage
        The data layer (already migrated).
    site : Site or Sites, optional
        The site(s) served; by default read from ``settings.site_entries``.
    metrics : GatewayMetrics, optional
        Shared with the node so ``/metrics`` shows ingestion too; a new one by default.
    readiness : callable, optional
        Extra readiness checks, ``{name: "ok" or what is wrong}`` (the node adds the bus).
    clock : callable
        Wall clock [Unix s]: ages, key times and the feed's dates.
    live : Broadcaster, optional
        What the writer stored, for ``/v1/stream`` (the node's); an idle one by default.
    """
    served = Sites.of(site) if site is not None else load_sites(settings.site_entries)
    metrics = metrics if metrics is not None else GatewayMetrics()
    app = FastAPI(
        title="Work-zone gateway",
        version="1.0.0",
        summary="Fused vehicle trajectories, alerts and roadside devices of a highway work "
        "zone, and its WZDx 4.2 device feed",
        docs_url="/docs",
        redoc_url=None,
    )
    key_store = KeyStore(storage.engine)
    app.state.gateway = GatewayContext(
        settings=settings,
        storage=storage,
        sites=served,
        metrics=metrics,
        key_store=key_store,
        keys=KeyCache(key_store),
        limiter=auth.TokenBuckets(settings.rate_limit_per_s, settings.rate_limit_burst),
        live=live if live is not None else broadcaster_for(settings, metrics.registry),
        readiness=readiness,
        clock=clock,
    )
    add_exception_handlers(app)
    app.include_router(api_router)
    app.mount("/static", static_files(), name="static")
    add_middleware(app, settings, metrics)
    return app
