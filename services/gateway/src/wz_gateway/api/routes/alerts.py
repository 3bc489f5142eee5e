"""``GET /v1/alerts``: the stored alert events (start, update, clear) by type, severity,
phase, time, track and episode, of one site or of every site (``site=*``)."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, Query, Request
from fastapi.responses import JSONResponse, Response

from wz_gateway import export
from wz_gateway.api.deps import SITE_RESPONSES, Ctx, Reader, site_of
from wz_gateway.api.errors import V1_RESPONSES
from wz_gateway.api.params import MAX_ID, Cursor, Limit, Stamp, check_order, next_link, page_limit
from wz_gateway.models import AlertPage
from wz_gateway.store_types import AlertQuery
from wz_shared.messages import AlertSeverity, AlertType

router = APIRouter(prefix="/v1", responses=V1_RESPONSES)


_ALERT_EXPORTS: dict[int | str, dict[str, Any]] = {
    200: {
        "content": {
            "text/csv": {"schema": {"type": "string"}},
            "application/geo+json": {"schema": export.FEATURE_COLLECTION_SCHEMA},
        },
        "description": "JSON by default; CSV or GeoJSON (a Point where the vehicle was) with "
        "`format`",
    },
    **SITE_RESPONSES,
}


@router.get("/alerts", response_model=AlertPage, tags=["alerts"], responses=_ALERT_EXPORTS)
def get_alerts(
    request: Request,
    response: Response,
    context: Ctx,
    _: Reader,
    site: Annotated[
        str | None,
        Query(
            pattern=r"^(\*|[a-z0-9][a-z0-9_-]{0,62})$",
            description="Site id, or `*` for every site's (default: the gateway's first site)",
        ),
    ] = None,
    alert_type: Annotated[
        list[AlertType] | None, Query(alias="type", description="Repeat for several")
    ] = None,
    severity: Annotated[list[AlertSeverity] | None, Query()] = None,
    phase: Annotated[list[Literal["start", "update", "clear"]] | None, Query()] = None,
    start: Stamp = None,
    end: Stamp = None,
    track_id: Annotated[int | None, Query(ge=0, le=MAX_ID)] = None,
    episode_id: Annotated[str | None, Query(max_length=128)] = None,
    order: Annotated[Literal["newest", "oldest"], Query()] = "newest",
    limit: Limit = None,
    cursor: Cursor = None,
    output: Annotated[
        Literal["json", "csv", "geojson"],
        Query(alias="format", description="json, csv or geojson"),
    ] = "json",
) -> AlertPage | Response:
    """Alert events (start, update, clear), newest first unless ``order=oldest``; as CSV or
    GeoJSON with ``format``."""
    check_order(start, end, "start", "end")
    site_id = site if site == "*" else site_of(context, site).site_id
    page = context.storage.alerts(
        AlertQuery(
            site=None if site_id == "*" else site_id,
            alert_types=tuple(t.value for t in alert_type or ()),
            severities=tuple(s.value for s in severity or ()),
            phases=tuple(phase or ()),
            start_stamp=start,
            end_stamp=end,
            track_id=track_id,
            episode_id=episode_id,
            newest_first=order == "newest",
            limit=page_limit(limit, context, default=100),
            cursor=cursor,
        )
    )
    links = next_link(request, page.next_cursor)
    if output == "csv":
        headers = {**links, "Content-Disposition": 'attachment; filename="alerts.csv"'}
        return Response(export.alerts_csv(page.items), media_type="text/csv", headers=headers)
    if output == "geojson":
        sites = {one.site_id: one for one in context.sites}
        body = export.alerts_geojson(page.items, sites, next_cursor=page.next_cursor)
        return JSONResponse(body, media_type="application/geo+json", headers=links)
    for name, value in links.items():
        response.headers[name] = value
    return AlertPage(
        site=site_id, count=len(page.items), next_cursor=page.next_cursor, alerts=page.items
    )
