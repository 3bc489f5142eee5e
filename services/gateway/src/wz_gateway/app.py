"""The gateway's HTTP API (FastAPI): build it with :func:`create_app`; nothing at import time.

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
    ...    /v1/webhooks                  signed webhook subscriptions (admin; webhook_routes.py)
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

import hashlib
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from http import HTTPStatus
from typing import Annotated, Any, Literal

from fastapi import APIRouter, Depends, FastAPI, Path, Query, Request, Security
from fastapi.exceptions import RequestValidationError
from fastapi.middleware.cors import CORSMiddleware
from fastapi.responses import JSONResponse, Response
from fastapi.security import APIKeyHeader, HTTPAuthorizationCredentials, HTTPBearer
from prometheus_client import CONTENT_TYPE_LATEST, generate_latest
from sqlalchemy.exc import OperationalError
from starlette.exceptions import HTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from wz_gateway import auth, export, views
from wz_gateway.live import Broadcaster, broadcaster_for
from wz_gateway.live_routes import page_router, static_files, stream_router
from wz_gateway.metrics import GatewayMetrics
from wz_gateway.models import (
    AlertPage,
    ApiKeyInfo,
    CreatedApiKey,
    Health,
    LiveTracks,
    NewApiKey,
    PointPage,
    Problem,
    ProblemField,
    Readiness,
    SiteSummary,
    TrackPoint,
    Trajectory,
)
from wz_gateway.settings import GatewaySettings
from wz_gateway.sites import Sites, load_sites
from wz_gateway.storage import AlertQuery, CursorError, Page, PointQuery, Storage
from wz_gateway.tables import SCHEMA_VERSION
from wz_gateway.webhook_routes import webhook_router
from wz_shared.messages import AlertSeverity, AlertType
from wz_shared.site import AreaKind, Site

log = logging.getLogger(__name__)

PROBLEM_JSON = "application/problem+json"
GEOJSON = "application/geo+json"
CSV = "text/csv"
PARQUET = "application/vnd.apache.parquet"
OutputFormat = Literal["json", "csv", "geojson", "parquet"]
_KEY_CACHE_S = 30.0
#: Largest track id, stamp and station a query may name: beyond any real value, and inside
#: what every database's integers and JSON numbers hold exactly.
_MAX_ID = 2**53
_MAX_STAMP_S = 1e11
_MAX_STATION_M = 1e7


# --- errors -------------------------------------------------------------------------------


class InputError(Exception):
    """Input that parsed but makes no sense (``start`` after ``end``...): a 422 problem."""

    def __init__(self, location: str, message: str) -> None:
        super().__init__(f"{location}: {message}")
        self.location = location
        self.message = message


def _problem(status: int, detail: str, *, instance: str | None = None,
             errors: list[ProblemField] | None = None,
             headers: dict[str, str] | None = None) -> JSONResponse:  # fmt: skip
    body = Problem(title=HTTPStatus(status).phrase, status=status, detail=detail,
                   instance=instance, errors=errors)  # fmt: skip
    return JSONResponse(body.model_dump(mode="json", exclude_none=True), status_code=status,
                        media_type=PROBLEM_JSON, headers=headers)  # fmt: skip


def _location(loc: tuple[Any, ...]) -> str:
    kind = str(loc[0]) if loc else "request"
    rest = ".".join(str(part) for part in loc[1:])
    return f"{kind}.{rest}" if rest else kind


def _describe(location: str) -> str:
    kind, _, name = location.partition(".")
    words = {"query": "query parameter", "path": "path parameter", "header": "header",
             "body": "body field"}  # fmt: skip
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
    return _problem(422, detail, instance=request.url.path, errors=errors)


async def _on_input_error(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, InputError)
    return _problem(422, f"{_describe(exc.location)}: {exc.message}", instance=request.url.path,
                    errors=[ProblemField(location=exc.location, message=exc.message)])  # fmt: skip


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
    return _problem(exc.status_code, detail, instance=request.url.path,
                    headers=dict(exc.headers or {}))  # fmt: skip


async def _on_database_error(request: Request, exc: Exception) -> JSONResponse:
    log.warning("database error on %s: %s", request.url.path, exc)
    return _problem(503, "the database is busy or unavailable; try again shortly",
                    instance=request.url.path, headers={"Retry-After": "5"})  # fmt: skip


async def _on_unexpected(request: Request, exc: Exception) -> JSONResponse:
    log.error("unexpected error on %s %s", request.method, request.url.path, exc_info=exc)
    return _problem(500, "internal error in the gateway; its log has the details",
                    instance=request.url.path)  # fmt: skip


def _problem_response(description: str) -> dict[str, Any]:
    return {"description": description, "model": Problem,
            "content": {PROBLEM_JSON: {"schema": {"$ref": "#/components/schemas/Problem"}}}}  # fmt: skip


_V1_RESPONSES: dict[int | str, dict[str, Any]] = {
    400: _problem_response("A body that cannot be read (not UTF-8 JSON)"),
    401: _problem_response("No API key, or one that is not valid"),
    403: _problem_response("The key's scope does not allow this"),
    413: _problem_response("Request body too large"),
    422: _problem_response("Invalid input: `errors` names each field"),
    429: _problem_response("Too many requests: retry after `Retry-After` seconds"),
    503: _problem_response("Database busy or unavailable"),
}


# --- middleware ---------------------------------------------------------------------------


class BodySizeLimit:
    """Refuse request bodies over ``max_bytes`` with 413, whether announced or streamed."""

    def __init__(self, app: ASGIApp, max_bytes: int) -> None:
        self.app = app
        self.max_bytes = max_bytes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        announced = dict(scope.get("headers", [])).get(b"content-length")
        too_large = f"the request body is over the limit of {self.max_bytes} bytes"
        if announced is not None:
            try:
                length = int(announced)
            except ValueError:
                length = -1
            if length < 0:
                await _problem(400, "Content-Length is not a number")(scope, receive, send)
                return
            if length > self.max_bytes:
                await _problem(413, too_large)(scope, receive, send)
                return
        seen = 0

        async def counted() -> Message:
            nonlocal seen
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > self.max_bytes:
                    raise HTTPException(413, too_large)  # the body reader passes it on
            return message

        await self.app(scope, counted, send)


class HttpMetrics:
    """Count requests by route template (not raw path: ids would explode the labels)."""

    def __init__(self, app: ASGIApp, metrics: GatewayMetrics) -> None:
        self.app = app
        self.metrics = metrics

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        started = time.perf_counter()
        status = [500]

        async def watched(message: Message) -> None:
            if message["type"] == "http.response.start":
                status[0] = int(message["status"])
            await send(message)

        try:
            await self.app(scope, receive, watched)
        finally:
            route = scope.get("route")
            template = getattr(route, "path", None) or "unmatched"
            self.metrics.http_requests.labels(template, scope.get("method", ""),
                                              str(status[0])).inc()  # fmt: skip
            self.metrics.http_latency.labels(template).observe(time.perf_counter() - started)


# --- the app's state and its dependencies ------------------------------------------------


@dataclass(frozen=True)
class Principal:
    """Who is asking: a stored key, or anyone (dev mode reads)."""

    key_id: str
    scope: auth.Scope


@dataclass
class KeyCache:
    """Verified keys for ``ttl_s`` (scrypt is slow on purpose); cleared when a key is revoked."""

    storage: Storage
    ttl_s: float = _KEY_CACHE_S
    clock: Callable[[], float] = time.monotonic
    _entries: dict[str, tuple[ApiKeyInfo, float]] = field(default_factory=dict)
    _lock: threading.Lock = field(default_factory=threading.Lock)

    def verify(self, secret: str) -> ApiKeyInfo | None:
        digest = hashlib.sha256(secret.encode()).hexdigest()
        now = self.clock()
        with self._lock:
            cached = self._entries.get(digest)
        if cached is not None and cached[1] > now:
            return cached[0]
        info = self.storage.find_api_key(secret)
        with self._lock:
            if info is None:
                self._entries.pop(digest, None)
            else:
                if len(self._entries) > 10_000:
                    self._entries.clear()
                self._entries[digest] = (info, now + self.ttl_s)
        return info

    def clear(self) -> None:
        with self._lock:
            self._entries.clear()


@dataclass
class GatewayContext:
    """What every route needs, built once by :func:`create_app`."""

    settings: GatewaySettings
    storage: Storage
    sites: Sites
    metrics: GatewayMetrics
    keys: KeyCache
    limiter: auth.TokenBuckets
    readiness: Callable[[], dict[str, str]] | None
    clock: Callable[[], float]

    @property
    def site(self) -> Site:
        """The default site (the first served)."""
        return self.sites.default


def _context(request: Request) -> GatewayContext:
    context: GatewayContext = request.app.state.gateway
    return context


Ctx = Annotated[GatewayContext, Depends(_context)]

_SITE_PATTERN = r"^[a-z0-9][a-z0-9_-]{0,62}$"


def _site(
    context: Ctx,
    site: Annotated[str | None, Query(pattern=_SITE_PATTERN, description="Site id (a central "
                                      "gateway serves several; default: its first)")] = None,
) -> Site:  # fmt: skip
    if site is None:
        return context.sites.default
    found = context.sites.get(site)
    if found is None:
        raise HTTPException(404, f"this gateway does not serve site {site!r}; it serves "
                            f"{', '.join(context.sites.ids)} (GET /v1/sites)")  # fmt: skip
    return found


SiteParam = Annotated[Site, Depends(_site)]

_api_key_header = APIKeyHeader(
    name="X-API-Key", auto_error=False, scheme_name="ApiKey",
    description="An API key: `read` for reads, `admin` for /v1/admin",
)  # fmt: skip
_bearer = HTTPBearer(auto_error=False, scheme_name="Bearer",
                     description="The same API key as `Authorization: Bearer <key>`")  # fmt: skip


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
                429, f"too many requests from {identity.split(':')[0]}; retry in {wait_s:.1f} s",
                headers={"Retry-After": auth.TokenBuckets.retry_after_header(wait_s)},
            )  # fmt: skip
        challenge = {"WWW-Authenticate": 'Bearer realm="wz-gateway"'}
        if secret and info is None:
            context.metrics.auth_failures.labels("invalid").inc()
            raise HTTPException(401, "the API key is not valid (unknown or revoked)",
                                headers=challenge)  # fmt: skip
        if info is None:
            if context.settings.dev_mode and needed == "read":
                return Principal("anonymous", "read")
            context.metrics.auth_failures.labels("missing").inc()
            raise HTTPException(
                401, "an API key is needed: send it as the X-API-Key header or as "
                "Authorization: Bearer <key>", headers=challenge,
            )  # fmt: skip
        if not auth.scope_allows(info.scope, needed):
            context.metrics.auth_failures.labels("scope").inc()
            raise HTTPException(403, f"this key has scope {info.scope!r}; {needed!r} is needed")
        return Principal(info.key_id, info.scope)

    return dependency


Reader = Annotated[Principal, Depends(require("read"))]
Admin = Annotated[Principal, Depends(require("admin"))]

# --- query parameters ---------------------------------------------------------------------

Stamp = Annotated[float | None, Query(ge=0.0, le=_MAX_STAMP_S, allow_inf_nan=False,
                                      description="Capture time [s], inclusive")]  # fmt: skip
Limit = Annotated[int | None, Query(ge=1, le=100_000, description="Items per page (default "
                                    "1000 points or 100 alerts, at most max_page_size)")]
Cursor = Annotated[str | None, Query(max_length=200, description="`next_cursor` of the previous page")]  # fmt: skip
Format = Annotated[OutputFormat, Query(alias="format",
                                        description="json, csv, geojson or parquet")]
Speed = Annotated[float | None, Query(ge=0.0, le=200.0, allow_inf_nan=False,
                                      description="Speed bound [m/s], inclusive")]  # fmt: skip
Station = Annotated[float | None, Query(ge=-_MAX_STATION_M, le=_MAX_STATION_M,
                                        allow_inf_nan=False,
                                        description="Station bound [m], inclusive")]  # fmt: skip

_EXPORT_RESPONSES: dict[int | str, dict[str, Any]] = {
    200: {
        "content": {
            CSV: {"schema": {"type": "string"}},
            PARQUET: {"schema": {"type": "string", "format": "binary"}},
            GEOJSON: {"schema": {"type": "object", "required": ["type", "features"],
                                 "properties": {"type": {"const": "FeatureCollection"},
                                                "features": {"type": "array"}}}},
        },
        "description": "JSON by default; CSV, GeoJSON or Parquet (the CSV's columns, typed) "
                       "with `format`",
    }
}  # fmt: skip


def _check_order(low: float | None, high: float | None, low_name: str, high_name: str) -> None:
    if low is not None and high is not None and low > high:
        raise InputError(f"query.{low_name}", f"{low_name} ({low}) is greater than {high_name} ({high})")  # fmt: skip


def _limit(limit: int | None, context: GatewayContext, default: int = 1000) -> int:
    if limit is None:
        return min(default, context.settings.max_page_size)
    if limit > context.settings.max_page_size:
        raise InputError("query.limit", f"at most {context.settings.max_page_size} per page")
    return limit


def parse_bbox(text: str) -> tuple[float, float, float, float]:
    """``minLon,minLat,maxLon,maxLat`` [deg] (GeoJSON's order); :class:`InputError` if not."""
    parts = text.split(",")
    try:
        values = [float(part) for part in parts]
    except ValueError:
        values = []
    if len(values) != 4 or not all(abs(v) < float("inf") for v in values):
        raise InputError("query.bbox", "give four numbers: minLon,minLat,maxLon,maxLat (degrees)")
    lon_min, lat_min, lon_max, lat_max = values
    if not (-180 <= lon_min <= lon_max <= 180 and -90 <= lat_min <= lat_max <= 90):
        raise InputError(
            "query.bbox", "need -180 <= minLon <= maxLon <= 180 and -90 <= minLat <= maxLat <= 90"
        )
    return lon_min, lat_min, lon_max, lat_max


def _next_link(request: Request, cursor: str | None) -> dict[str, str]:
    if cursor is None:
        return {}
    url = request.url.include_query_params(cursor=cursor)
    return {"Link": f'<{url}>; rel="next"', "X-Next-Cursor": cursor}


def _points_response(request: Request, output: OutputFormat, page: Page,
                     json_body: Callable[[list[TrackPoint]], Any],
                     geojson: Callable[[list[TrackPoint]], dict[str, Any]],
                     filename: str) -> Response:  # fmt: skip
    headers = _next_link(request, page.next_cursor)
    points: list[TrackPoint] = page.items
    if output == "parquet":
        headers["Content-Disposition"] = f'attachment; filename="{filename}.parquet"'
        return Response(export.points_parquet(points), media_type=PARQUET, headers=headers)
    if output == "csv":
        headers["Content-Disposition"] = f'attachment; filename="{filename}.csv"'
        return Response(export.points_csv(points), media_type=CSV, headers=headers)
    if output == "geojson":
        return JSONResponse(geojson(points), media_type=GEOJSON, headers=headers)
    body = json_body(points)
    return JSONResponse(body.model_dump(mode="json"), headers=headers)


# --- the app ------------------------------------------------------------------------------


def _v1_router() -> APIRouter:
    router = APIRouter(prefix="/v1", responses=_V1_RESPONSES)

    @router.get("/sites", response_model=list[SiteSummary], tags=["site"])
    def get_sites(context: Ctx, _: Reader) -> list[SiteSummary]:
        """The sites this gateway serves; the first is the default ``site`` of every route."""
        return [SiteSummary(site_id=site.site_id, name=site.name, default=index == 0)
                for index, site in enumerate(context.sites)]  # fmt: skip

    _site_responses: dict[int | str, dict[str, Any]] = {
        404: _problem_response("The gateway does not serve this site")}

    @router.get("/site", response_model=Site, tags=["site"], responses=_site_responses)
    def get_site(site: SiteParam, _: Reader) -> Site:
        """The site: road geometry, lanes, work-zone areas, limits, sensors, alert thresholds."""
        return site

    @router.get("/tracks/live", response_model=LiveTracks, tags=["tracks"],
                responses=_site_responses)  # fmt: skip
    def get_live_tracks(context: Ctx, site: SiteParam, _: Reader) -> LiveTracks:
        """The newest fused tracks (the tracker's last batch), with WGS84 positions."""
        return views.live_tracks(context.storage, site, context.clock())

    @router.get("/tracks/{track_id}", response_model=Trajectory, tags=["tracks"],
                responses={**_EXPORT_RESPONSES,
                           404: _problem_response("No such track, or a site not served")})  # fmt: skip
    def get_track(
        request: Request,
        context: Ctx,
        site: SiteParam,
        _: Reader,
        track_id: Annotated[int, Path(ge=0, le=_MAX_ID, description="The tracker's track id")],
        start: Stamp = None,
        end: Stamp = None,
        smoothed: Annotated[bool, Query(description="The smoothed trajectory (true; stored "
                                                    "when the track ends) or the fused one "
                                                    "(false)")] = False,
        limit: Limit = None,
        cursor: Cursor = None,
        output: Format = "json",
    ) -> Response:  # fmt: skip
        """One track's stored trajectory, oldest first, a page at a time."""
        _check_order(start, end, "start", "end")
        site_id = site.site_id
        page = context.storage.points(PointQuery(
            site=site_id, track_id=track_id, start_stamp=start, end_stamp=end,
            smoothed=smoothed, limit=_limit(limit, context), cursor=cursor,
        ))  # fmt: skip
        if not page.items and cursor is None:
            raise HTTPException(404, f"no stored point of track {track_id} matches")
        return _points_response(
            request, output, page,
            lambda points: Trajectory(site=site_id, track_id=track_id, count=len(points),
                                      next_cursor=page.next_cursor, points=points),
            lambda points: export.trajectory_geojson(site_id, track_id, points,
                                                     next_cursor=page.next_cursor),
            f"track-{track_id}",
        )  # fmt: skip

    @router.get("/trajectories", response_model=PointPage, tags=["tracks"],
                responses={**_EXPORT_RESPONSES, **_site_responses})  # fmt: skip
    def get_trajectories(
        request: Request,
        context: Ctx,
        site: SiteParam,
        _: Reader,
        start: Stamp = None,
        end: Stamp = None,
        track_id: Annotated[int | None, Query(ge=0, le=_MAX_ID)] = None,
        area: Annotated[AreaKind | None, Query(description="Only points in this work-zone "
                                                           "area (by station)")] = None,
        station_min: Station = None,
        station_max: Station = None,
        bbox: Annotated[str | None, Query(max_length=200, description="minLon,minLat,maxLon,"
                                          "maxLat [deg]")] = None,
        lane: Annotated[int | None, Query(ge=-1, le=64, description="Lane index (0: the "
                                          "rightmost; -1: between lanes)")] = None,
        min_speed: Speed = None,
        max_speed: Speed = None,
        smoothed: Annotated[bool, Query(description="Smoothed points (true) or fused ones "
                                                    "(false)")] = False,
        limit: Limit = None,
        cursor: Cursor = None,
        output: Format = "json",
    ) -> Response:  # fmt: skip
        """Stored track points, oldest first, filtered by time window, area, speed and lane."""
        _check_order(start, end, "start", "end")
        _check_order(station_min, station_max, "station_min", "station_max")
        _check_order(min_speed, max_speed, "min_speed", "max_speed")
        if area is not None:
            zone = next((a for a in site.work_zone if a.kind == area), None)
            if zone is None:
                raise InputError("query.area", f"site {site.site_id} has no {area.value} area")
            station_min = max(zone.start_station_m, station_min if station_min is not None
                              else zone.start_station_m)  # fmt: skip
            station_max = min(zone.end_station_m, station_max if station_max is not None
                              else zone.end_station_m)  # fmt: skip
        site_id = site.site_id
        page = context.storage.points(PointQuery(
            site=site_id, start_stamp=start, end_stamp=end, track_id=track_id,
            station_min_m=station_min, station_max_m=station_max,
            bbox_deg=None if bbox is None else parse_bbox(bbox), lane_index=lane,
            min_speed_mps=min_speed, max_speed_mps=max_speed, smoothed=smoothed,
            limit=_limit(limit, context), cursor=cursor,
        ))  # fmt: skip
        return _points_response(
            request, output, page,
            lambda points: PointPage(site=site_id, count=len(points),
                                     next_cursor=page.next_cursor, points=points),
            lambda points: export.points_geojson(points, next_cursor=page.next_cursor),
            "trajectories",
        )  # fmt: skip

    @router.get("/alerts", response_model=AlertPage, tags=["alerts"], responses=_site_responses)
    def get_alerts(
        request: Request,
        response: Response,
        context: Ctx,
        _: Reader,
        site: Annotated[str | None, Query(pattern=r"^(\*|[a-z0-9][a-z0-9_-]{0,62})$",
                                          description="Site id, or `*` for every site's "
                                          "(default: the gateway's first site)")] = None,
        alert_type: Annotated[list[AlertType] | None, Query(alias="type", description="Repeat "
                                                            "for several")] = None,
        severity: Annotated[list[AlertSeverity] | None, Query()] = None,
        phase: Annotated[list[Literal["start", "update", "clear"]] | None, Query()] = None,
        start: Stamp = None,
        end: Stamp = None,
        track_id: Annotated[int | None, Query(ge=0, le=_MAX_ID)] = None,
        episode_id: Annotated[str | None, Query(max_length=128)] = None,
        order: Annotated[Literal["newest", "oldest"], Query()] = "newest",
        limit: Limit = None,
        cursor: Cursor = None,
    ) -> AlertPage:  # fmt: skip
        """Alert events (start, update, clear), newest first unless ``order=oldest``."""
        _check_order(start, end, "start", "end")
        site_id = site if site == "*" else _site(context, site).site_id
        page = context.storage.alerts(AlertQuery(
            site=None if site_id == "*" else site_id,
            alert_types=tuple(t.value for t in alert_type or ()),
            severities=tuple(s.value for s in severity or ()),
            phases=tuple(phase or ()), start_stamp=start, end_stamp=end, track_id=track_id,
            episode_id=episode_id, newest_first=order == "newest",
            limit=_limit(limit, context, default=100), cursor=cursor,
        ))  # fmt: skip
        for name, value in _next_link(request, page.next_cursor).items():
            response.headers[name] = value
        return AlertPage(site=site_id, count=len(page.items),
                         next_cursor=page.next_cursor, alerts=page.items)  # fmt: skip

    @router.get("/wzdx/device-feed", tags=["wzdx"],
                responses={200: {"description": "A WZDx 4.2 DeviceFeed (GeoJSON)",
                                 "content": {"application/json": {"schema": {
                                     "type": "object",
                                     "required": ["feed_info", "type", "features"]}}}},
                            **_site_responses})  # fmt: skip
    def get_device_feed(
        context: Ctx,
        _: Reader,
        site: Annotated[str | None, Query(pattern=_SITE_PATTERN, description="Only this site's "
                                          "devices (default: every site's)")] = None,
    ) -> JSONResponse:  # fmt: skip
        """The WZDx 4.2 DeviceFeed: traffic sensor (per-lane volumes, speeds, occupancy over the
        newest collection interval), cameras, flashing beacon and message sign, with status."""
        settings = context.settings
        served = [_site(context, site)] if site is not None else list(context.sites)
        feeds = [views.device_feed_of(
            context.storage, one, now=context.clock(), publisher=settings.publisher,
            stale_after_s=settings.stale_after_s, traffic_interval_s=settings.traffic_interval_s,
            detector_station_override_m=settings.traffic_detector_station_m,
            contact_email=settings.contact_email,
        ) for one in served]  # fmt: skip
        return JSONResponse(views.merge_device_feeds(feeds))

    @router.get("/admin/api-keys", response_model=list[ApiKeyInfo], tags=["admin"])
    def list_keys(
        context: Ctx, _: Admin, include_revoked: Annotated[bool, Query()] = False
    ) -> list[ApiKeyInfo]:
        """Every key (without secrets)."""
        return context.storage.api_keys(include_revoked=include_revoked)

    @router.post("/admin/api-keys", response_model=CreatedApiKey, status_code=201,
                 tags=["admin"])  # fmt: skip
    def create_key(context: Ctx, principal: Admin, request_body: NewApiKey) -> CreatedApiKey:
        """Make a key. Its secret is in this answer only; the gateway keeps its hash."""
        secret = auth.new_secret()
        info = context.storage.add_api_key(request_body.scope, secret, name=request_body.name,
                                           origin="api", now=context.clock())  # fmt: skip
        log.info("API key %s (%s, %r) made by %s", info.key_id, info.scope, info.name,
                 principal.key_id)  # fmt: skip
        return CreatedApiKey(**info.model_dump(), secret=secret)

    @router.delete("/admin/api-keys/{key_id}", status_code=204, tags=["admin"],
                   responses={404: _problem_response("No such live key")})  # fmt: skip
    def revoke_key(
        context: Ctx,
        principal: Admin,
        key_id: Annotated[str, Path(pattern=r"^[0-9a-f]{12}$", description="The key's key_id")],
    ) -> Response:
        """Revoke a key at once (its record stays, marked revoked)."""
        if not context.storage.revoke_api_key(key_id, context.clock()):
            raise HTTPException(404, f"no live key {key_id}")
        context.keys.clear()
        log.info("API key %s revoked by %s", key_id, principal.key_id)
        return Response(status_code=204)

    return router


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
    sites = Sites.of(site) if site is not None else load_sites(settings.site_entries)
    metrics = metrics if metrics is not None else GatewayMetrics()
    app = FastAPI(
        title="Work-zone gateway",
        version="1.0.0",
        summary="Fused vehicle trajectories, alerts and roadside devices of a highway work "
        "zone, and its WZDx 4.2 device feed",
        docs_url="/docs",
        redoc_url=None,
    )
    app.state.gateway = GatewayContext(
        settings=settings, storage=storage, sites=sites, metrics=metrics,
        keys=KeyCache(storage), limiter=auth.TokenBuckets(settings.rate_limit_per_s,
                                                          settings.rate_limit_burst),
        readiness=readiness, clock=clock,
    )  # fmt: skip
    app.add_exception_handler(RequestValidationError, _on_validation_error)
    app.add_exception_handler(InputError, _on_input_error)
    app.add_exception_handler(CursorError, _on_cursor_error)
    app.add_exception_handler(HTTPException, _on_http_error)
    app.add_exception_handler(OperationalError, _on_database_error)
    app.add_exception_handler(Exception, _on_unexpected)
    app.include_router(_v1_router())
    app.include_router(webhook_router(admin_access=Depends(require("admin")),
                                      responses=_V1_RESPONSES))  # fmt: skip
    live = live if live is not None else broadcaster_for(settings, metrics.registry)
    app.include_router(stream_router(
        live, heartbeat_s=settings.stream_heartbeat_s, retry_ms=2000,
        read_access=Depends(require("read")), responses=_V1_RESPONSES,
    ))  # fmt: skip
    app.include_router(page_router())
    app.mount("/static", static_files(), name="static")

    @app.get("/healthz", response_model=Health, tags=["operations"])
    def healthz() -> Health:
        """The process answers."""
        return Health(status="ok")

    @app.get("/readyz", response_model=Readiness, tags=["operations"],
             responses={503: {"model": Readiness, "description": "Not ready"}})  # fmt: skip
    def readyz(context: Ctx) -> JSONResponse:
        """Ready to serve: the database answers at the expected schema (and the bus is up)."""
        checks: dict[str, str] = {}
        try:
            version = context.storage.current_schema_version()
            checks["database"] = ("ok" if version == SCHEMA_VERSION
                                  else f"schema version {version}, expected {SCHEMA_VERSION}")  # fmt: skip
        except Exception as exc:  # any failure means not ready; say which
            checks["database"] = f"unreachable: {type(exc).__name__}"
        if context.readiness is not None:
            checks.update(context.readiness())
        ready = all(value == "ok" for value in checks.values())
        body = Readiness(status="ready" if ready else "not_ready", checks=checks)
        return JSONResponse(body.model_dump(), status_code=200 if ready else 503)

    @app.get("/metrics", tags=["operations"], response_class=Response,
             responses={200: {"content": {"text/plain": {"schema": {"type": "string"}}},
                              "description": "Prometheus text format"}})  # fmt: skip
    def prometheus(context: Ctx) -> Response:
        """Prometheus metrics: HTTP, ingestion, bus, queue, retention."""
        return Response(generate_latest(context.metrics.registry), media_type=CONTENT_TYPE_LATEST)

    # Each one added wraps the ones before: CORS outermost (its headers on every answer),
    # then the metrics (which count the 413s too), then the body size limit.
    app.add_middleware(BodySizeLimit, max_bytes=settings.max_body_bytes)
    app.add_middleware(HttpMetrics, metrics=metrics)
    if settings.cors_origins:
        app.add_middleware(
            CORSMiddleware, allow_origins=settings.cors_origins, allow_methods=["GET", "POST",
            "DELETE"], allow_headers=["Authorization", "X-API-Key", "Content-Type"],
            expose_headers=["Link", "X-Next-Cursor", "Retry-After"], max_age=600,
        )  # fmt: skip
    return app
