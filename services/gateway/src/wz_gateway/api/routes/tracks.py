"""The tracks: ``GET /v1/tracks/live`` (the newest batch), ``GET /v1/tracks/{track_id}`` (one
track's stored trajectory) and ``GET /v1/trajectories`` (stored points by time, area, speed,
lane), as JSON, CSV, GeoJSON or Parquet (:mod:`wz_gateway.export`)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Annotated, Any

from fastapi import APIRouter, Path, Query, Request
from fastapi.responses import JSONResponse, Response
from starlette.exceptions import HTTPException

from wz_gateway import export, views
from wz_gateway.api.deps import SITE_RESPONSES, Ctx, Reader, SiteParam
from wz_gateway.api.errors import V1_RESPONSES, InputError, problem_response
from wz_gateway.api.params import (
    MAX_ID,
    BBox,
    Cursor,
    Format,
    Limit,
    OutputFormat,
    Speed,
    Stamp,
    Station,
    check_order,
    next_link,
    page_limit,
)
from wz_gateway.models import LiveTracks, PointPage, TrackPoint, Trajectory
from wz_gateway.store_types import Page, PointQuery
from wz_shared.site import AreaKind

GEOJSON = "application/geo+json"
CSV = "text/csv"
PARQUET = "application/vnd.apache.parquet"

_EXPORT_RESPONSES: dict[int | str, dict[str, Any]] = {
    200: {
        "content": {
            CSV: {"schema": {"type": "string"}},
            PARQUET: {"schema": {"type": "string", "format": "binary"}},
            GEOJSON: {"schema": export.FEATURE_COLLECTION_SCHEMA},
        },
        "description": "JSON by default; CSV, GeoJSON or GeoParquet (the CSV's columns, typed, "
        "and a WKB point geometry with GeoParquet 1.1 metadata) with `format`",
    }
}

router = APIRouter(prefix="/v1", responses=V1_RESPONSES)


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


def _points_response(
    request: Request,
    output: OutputFormat,
    page: Page,
    json_body: Callable[[list[TrackPoint]], Any],
    geojson: Callable[[list[TrackPoint]], dict[str, Any]],
    filename: str,
) -> Response:
    headers = next_link(request, page.next_cursor)
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


@router.get("/tracks/live", response_model=LiveTracks, tags=["tracks"], responses=SITE_RESPONSES)
def get_live_tracks(context: Ctx, site: SiteParam, _: Reader) -> LiveTracks:
    """The newest fused tracks (the tracker's last batch), with WGS84 positions."""
    return views.live_tracks(context.storage, site, context.clock())


@router.get(
    "/tracks/{track_id}",
    response_model=Trajectory,
    tags=["tracks"],
    responses={**_EXPORT_RESPONSES, 404: problem_response("No such track, or a site not served")},
)
def get_track(
    request: Request,
    context: Ctx,
    site: SiteParam,
    _: Reader,
    track_id: Annotated[int, Path(ge=0, le=MAX_ID, description="The tracker's track id")],
    start: Stamp = None,
    end: Stamp = None,
    smoothed: Annotated[
        bool,
        Query(
            description="The smoothed trajectory (true; stored "
            "when the track ends) or the fused one "
            "(false)"
        ),
    ] = False,
    limit: Limit = None,
    cursor: Cursor = None,
    output: Format = "json",
) -> Response:
    """One track's stored trajectory, oldest first, a page at a time."""
    check_order(start, end, "start", "end")
    site_id = site.site_id
    page = context.storage.points(
        PointQuery(
            site=site_id,
            track_id=track_id,
            start_stamp=start,
            end_stamp=end,
            smoothed=smoothed,
            limit=page_limit(limit, context),
            cursor=cursor,
        )
    )
    if not page.items and cursor is None:
        raise HTTPException(404, f"no stored point of track {track_id} matches")
    return _points_response(
        request,
        output,
        page,
        lambda points: Trajectory(
            site=site_id,
            track_id=track_id,
            count=len(points),
            next_cursor=page.next_cursor,
            points=points,
        ),
        lambda points: export.trajectory_geojson(
            site_id, track_id, points, next_cursor=page.next_cursor
        ),
        f"track-{track_id}",
    )


@router.get(
    "/trajectories",
    response_model=PointPage,
    tags=["tracks"],
    responses={**_EXPORT_RESPONSES, **SITE_RESPONSES},
)
def get_trajectories(
    request: Request,
    context: Ctx,
    site: SiteParam,
    _: Reader,
    start: Stamp = None,
    end: Stamp = None,
    track_id: Annotated[int | None, Query(ge=0, le=MAX_ID)] = None,
    area: Annotated[
        AreaKind | None, Query(description="Only points in this work-zone area (by station)")
    ] = None,
    station_min: Station = None,
    station_max: Station = None,
    bbox: BBox = None,
    lane: Annotated[
        int | None,
        Query(ge=-1, le=64, description="Lane index (0: the rightmost; -1: between lanes)"),
    ] = None,
    min_speed: Speed = None,
    max_speed: Speed = None,
    smoothed: Annotated[
        bool, Query(description="Smoothed points (true) or fused ones (false)")
    ] = False,
    limit: Limit = None,
    cursor: Cursor = None,
    output: Format = "json",
) -> Response:
    """Stored track points, oldest first, filtered by time window, area, speed and lane."""
    check_order(start, end, "start", "end")
    check_order(station_min, station_max, "station_min", "station_max")
    check_order(min_speed, max_speed, "min_speed", "max_speed")
    if area is not None:
        zone = next((a for a in site.work_zone if a.kind == area), None)
        if zone is None:
            raise InputError("query.area", f"site {site.site_id} has no {area.value} area")
        station_min = max(
            zone.start_station_m, station_min if station_min is not None else zone.start_station_m
        )
        station_max = min(
            zone.end_station_m, station_max if station_max is not None else zone.end_station_m
        )
    site_id = site.site_id
    page = context.storage.points(
        PointQuery(
            site=site_id,
            start_stamp=start,
            end_stamp=end,
            track_id=track_id,
            station_min_m=station_min,
            station_max_m=station_max,
            bbox_deg=None if bbox is None else parse_bbox(bbox),
            lane_index=lane,
            min_speed_mps=min_speed,
            max_speed_mps=max_speed,
            smoothed=smoothed,
            limit=page_limit(limit, context),
            cursor=cursor,
        )
    )
    return _points_response(
        request,
        output,
        page,
        lambda points: PointPage(
            site=site_id, count=len(points), next_cursor=page.next_cursor, points=points
        ),
        lambda points: export.points_geojson(points, next_cursor=page.next_cursor),
        "trajectories",
    )
