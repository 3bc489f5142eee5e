"""What a route asks for, as ``Annotated[..., Depends(...)]`` aliases:

- :data:`Ctx`: the :class:`GatewayContext` (settings, storage, sites, keys...), built once by
  :func:`wz_gateway.app.create_app`;
- :data:`SiteParam`: the site of the ``site`` query parameter (default: the first served;
  404 for one not served);
- :data:`Reader`, :data:`Admin`: the caller's key must allow ``read`` (``admin``); either also
  applies the rate limit. In dev mode reads need no key;
- :data:`Webhooks`: the webhook subscriptions' store.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Annotated, Any

from fastapi import Depends, Query, Request, Security
from fastapi.security import APIKeyHeader, HTTPAuthorizationCredentials, HTTPBearer
from starlette.exceptions import HTTPException

from wz_gateway import auth
from wz_gateway.api.errors import problem_response
from wz_gateway.key_store import KeyCache, KeyStore
from wz_gateway.live import Broadcaster
from wz_gateway.metrics import GatewayMetrics
from wz_gateway.settings import GatewaySettings
from wz_gateway.sites import Sites
from wz_gateway.storage import Storage
from wz_gateway.webhook_store import WebhookStore
from wz_shared.site import Site

SITE_PATTERN = r"^[a-z0-9][a-z0-9_-]{0,62}$"
#: The answer of a route that takes ``site``, for one the gateway does not serve.
SITE_RESPONSES: dict[int | str, dict[str, Any]] = {
    404: problem_response("The gateway does not serve this site")
}


@dataclass
class GatewayContext:
    """What every route needs, built once by :func:`wz_gateway.app.create_app`."""

    settings: GatewaySettings
    storage: Storage
    sites: Sites
    metrics: GatewayMetrics
    key_store: KeyStore
    keys: KeyCache
    limiter: auth.TokenBuckets
    live: Broadcaster
    readiness: Callable[[], dict[str, str]] | None
    clock: Callable[[], float]
    #: When this gateway began serving [Unix s] (the WorkZoneFeed's start date of a site
    #: without a ``schedule``).
    started_at: float = field(default_factory=time.time)

    @property
    def site(self) -> Site:
        """The default site (the first served)."""
        return self.sites.default


def _context(request: Request) -> GatewayContext:
    context: GatewayContext = request.app.state.gateway
    return context


Ctx = Annotated[GatewayContext, Depends(_context)]


def site_of(context: GatewayContext, site: str | None) -> Site:
    """The served site of this id (the default for None); 404 for one not served."""
    if site is None:
        return context.sites.default
    found = context.sites.get(site)
    if found is None:
        raise HTTPException(
            404,
            f"this gateway does not serve site {site!r}; it serves "
            f"{', '.join(context.sites.ids)} (GET /v1/sites)",
        )
    return found


def _site(
    context: Ctx,
    site: Annotated[
        str | None,
        Query(
            pattern=SITE_PATTERN,
            description="Site id (a central gateway serves several; default: its first)",
        ),
    ] = None,
) -> Site:
    return site_of(context, site)


SiteParam = Annotated[Site, Depends(_site)]


@dataclass(frozen=True)
class Principal:
    """Who is asking: a stored key, or anyone (dev mode reads)."""

    key_id: str
    scope: auth.Scope


_api_key_header = APIKeyHeader(
    name="X-API-Key",
    auto_error=False,
    scheme_name="ApiKey",
    description="An API key: `read` for reads, `admin` for /v1/admin",
)
_bearer = HTTPBearer(
    auto_error=False,
    scheme_name="Bearer",
    description="The same API key as `Authorization: Bearer <key>`",
)


def require(needed: auth.Scope) -> Callable[..., Principal]:
    """A dependency: the caller's key must allow ``needed``; also applies the rate limit."""

    def dependency(
        request: Request,
        context: Ctx,
        api_key: Annotated[str | None, Security(_api_key_header)] = None,
        bearer: Annotated[HTTPAuthorizationCredentials | None, Security(_bearer)] = None,
    ) -> Principal:
        secret = api_key or (bearer.credentials if bearer is not None else None)
        address = request.client.host if request.client is not None else "unknown"
        info = context.keys.verify(secret) if secret else None
        identity = f"key:{info.key_id}" if info is not None else f"addr:{address}"
        wait_s = context.limiter.take(identity)
        if wait_s > 0.0:
            context.metrics.rate_limited.inc()
            raise HTTPException(
                429,
                f"too many requests from {identity.split(':')[0]}; retry in {wait_s:.1f} s",
                headers={"Retry-After": auth.TokenBuckets.retry_after_header(wait_s)},
            )
        challenge = {"WWW-Authenticate": 'Bearer realm="wz-gateway"'}
        if secret and info is None:
            context.metrics.auth_failures.labels("invalid").inc()
            raise HTTPException(
                401, "the API key is not valid (unknown or revoked)", headers=challenge
            )
        if info is None:
            if context.settings.dev_mode and needed == "read":
                return Principal("anonymous", "read")
            context.metrics.auth_failures.labels("missing").inc()
            raise HTTPException(
                401,
                "an API key is needed: send it as the X-API-Key header or as "
                "Authorization: Bearer <key>",
                headers=challenge,
            )
        if not auth.scope_allows(info.scope, needed):
            context.metrics.auth_failures.labels("scope").inc()
            raise HTTPException(403, f"this key has scope {info.scope!r}; {needed!r} is needed")
        return Principal(info.key_id, info.scope)

    return dependency


require_read = require("read")
require_admin = require("admin")
Reader = Annotated[Principal, Depends(require_read)]
Admin = Annotated[Principal, Depends(require_admin)]


def _webhook_store(context: Ctx) -> WebhookStore:
    return WebhookStore(context.storage.engine)


Webhooks = Annotated[WebhookStore, Depends(_webhook_store)]
