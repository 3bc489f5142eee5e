from http import HTTPStatus
from typing import Any, cast
from urllib.parse import quote

import httpx

from ...client import AuthenticatedClient, Client
from ...types import Response, UNSET
from ... import errors

from ...models.area_kind import AreaKind
from ...models.get_trajectories_v1_trajectories_get_format import (
    GetTrajectoriesV1TrajectoriesGetFormat,
)
from ...models.point_page import PointPage
from ...models.problem import Problem
from ...types import UNSET, Unset
from typing import cast


def _get_kwargs(
    *,
    start: float | None | Unset = UNSET,
    end: float | None | Unset = UNSET,
    track_id: int | None | Unset = UNSET,
    area: AreaKind | None | Unset = UNSET,
    station_min: float | None | Unset = UNSET,
    station_max: float | None | Unset = UNSET,
    bbox: None | str | Unset = UNSET,
    lane: int | None | Unset = UNSET,
    min_speed: float | None | Unset = UNSET,
    max_speed: float | None | Unset = UNSET,
    smoothed: bool | Unset = False,
    limit: int | None | Unset = UNSET,
    cursor: None | str | Unset = UNSET,
    format_: GetTrajectoriesV1TrajectoriesGetFormat
    | Unset = GetTrajectoriesV1TrajectoriesGetFormat.JSON,
    site: None | str | Unset = UNSET,
) -> dict[str, Any]:

    params: dict[str, Any] = {}

    json_start: float | None | Unset
    if isinstance(start, Unset):
        json_start = UNSET
    else:
        json_start = start
    params["start"] = json_start

    json_end: float | None | Unset
    if isinstance(end, Unset):
        json_end = UNSET
    else:
        json_end = end
    params["end"] = json_end

    json_track_id: int | None | Unset
    if isinstance(track_id, Unset):
        json_track_id = UNSET
    else:
        json_track_id = track_id
    params["track_id"] = json_track_id

    json_area: None | str | Unset
    if isinstance(area, Unset):
        json_area = UNSET
    elif isinstance(area, AreaKind):
        json_area = area.value
    else:
        json_area = area
    params["area"] = json_area

    json_station_min: float | None | Unset
    if isinstance(station_min, Unset):
        json_station_min = UNSET
    else:
        json_station_min = station_min
    params["station_min"] = json_station_min

    json_station_max: float | None | Unset
    if isinstance(station_max, Unset):
        json_station_max = UNSET
    else:
        json_station_max = station_max
    params["station_max"] = json_station_max

    json_bbox: None | str | Unset
    if isinstance(bbox, Unset):
        json_bbox = UNSET
    else:
        json_bbox = bbox
    params["bbox"] = json_bbox

    json_lane: int | None | Unset
    if isinstance(lane, Unset):
        json_lane = UNSET
    else:
        json_lane = lane
    params["lane"] = json_lane

    json_min_speed: float | None | Unset
    if isinstance(min_speed, Unset):
        json_min_speed = UNSET
    else:
        json_min_speed = min_speed
    params["min_speed"] = json_min_speed

    json_max_speed: float | None | Unset
    if isinstance(max_speed, Unset):
        json_max_speed = UNSET
    else:
        json_max_speed = max_speed
    params["max_speed"] = json_max_speed

    params["smoothed"] = smoothed

    json_limit: int | None | Unset
    if isinstance(limit, Unset):
        json_limit = UNSET
    else:
        json_limit = limit
    params["limit"] = json_limit

    json_cursor: None | str | Unset
    if isinstance(cursor, Unset):
        json_cursor = UNSET
    else:
        json_cursor = cursor
    params["cursor"] = json_cursor

    json_format_: str | Unset = UNSET
    if not isinstance(format_, Unset):
        json_format_ = format_.value

    params["format"] = json_format_

    json_site: None | str | Unset
    if isinstance(site, Unset):
        json_site = UNSET
    else:
        json_site = site
    params["site"] = json_site

    params = {k: v for k, v in params.items() if v is not UNSET and v is not None}

    _kwargs: dict[str, Any] = {
        "method": "get",
        "url": "/v1/trajectories",
        "params": params,
    }

    return _kwargs


def _parse_response(
    *, client: AuthenticatedClient | Client, response: httpx.Response
) -> PointPage | Problem | None:
    if response.status_code == 200:
        response_200 = PointPage.from_dict(response.json())

        return response_200

    if response.status_code == 400:
        response_400 = Problem.from_dict(response.json())

        return response_400

    if response.status_code == 401:
        response_401 = Problem.from_dict(response.json())

        return response_401

    if response.status_code == 403:
        response_403 = Problem.from_dict(response.json())

        return response_403

    if response.status_code == 404:
        response_404 = Problem.from_dict(response.json())

        return response_404

    if response.status_code == 413:
        response_413 = Problem.from_dict(response.json())

        return response_413

    if response.status_code == 422:
        response_422 = Problem.from_dict(response.json())

        return response_422

    if response.status_code == 429:
        response_429 = Problem.from_dict(response.json())

        return response_429

    if response.status_code == 503:
        response_503 = Problem.from_dict(response.json())

        return response_503

    if client.raise_on_unexpected_status:
        raise errors.UnexpectedStatus(response.status_code, response.content)
    else:
        return None


def _build_response(
    *, client: AuthenticatedClient | Client, response: httpx.Response
) -> Response[PointPage | Problem]:
    return Response(
        status_code=HTTPStatus(response.status_code),
        content=response.content,
        headers=response.headers,
        parsed=_parse_response(client=client, response=response),
    )


def sync_detailed(
    *,
    client: AuthenticatedClient,
    start: float | None | Unset = UNSET,
    end: float | None | Unset = UNSET,
    track_id: int | None | Unset = UNSET,
    area: AreaKind | None | Unset = UNSET,
    station_min: float | None | Unset = UNSET,
    station_max: float | None | Unset = UNSET,
    bbox: None | str | Unset = UNSET,
    lane: int | None | Unset = UNSET,
    min_speed: float | None | Unset = UNSET,
    max_speed: float | None | Unset = UNSET,
    smoothed: bool | Unset = False,
    limit: int | None | Unset = UNSET,
    cursor: None | str | Unset = UNSET,
    format_: GetTrajectoriesV1TrajectoriesGetFormat
    | Unset = GetTrajectoriesV1TrajectoriesGetFormat.JSON,
    site: None | str | Unset = UNSET,
) -> Response[PointPage | Problem]:
    """Get Trajectories

     Stored track points, oldest first, filtered by time window, area, speed and lane.

    Args:
        start (float | None | Unset): Capture time [s], inclusive
        end (float | None | Unset): Capture time [s], inclusive
        track_id (int | None | Unset):
        area (AreaKind | None | Unset): Only points in this work-zone area (by station)
        station_min (float | None | Unset): Station bound [m], inclusive
        station_max (float | None | Unset): Station bound [m], inclusive
        bbox (None | str | Unset): minLon,minLat,maxLon,maxLat [deg], e.g.
            `-84.40,33.74,-84.38,33.76`
        lane (int | None | Unset): Lane index (0: the rightmost; -1: between lanes)
        min_speed (float | None | Unset): Speed bound [m/s], inclusive
        max_speed (float | None | Unset): Speed bound [m/s], inclusive
        smoothed (bool | Unset): Smoothed points (true) or fused ones (false) Default: False.
        limit (int | None | Unset): Items per page (default 1000 points or 100 alerts, at most
            max_page_size)
        cursor (None | str | Unset): `next_cursor` of the previous page
        format_ (GetTrajectoriesV1TrajectoriesGetFormat | Unset): json, csv, geojson or parquet
            Default: GetTrajectoriesV1TrajectoriesGetFormat.JSON.
        site (None | str | Unset): Site id (a central gateway serves several; default: its first)

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Response[PointPage | Problem]
    """

    kwargs = _get_kwargs(
        start=start,
        end=end,
        track_id=track_id,
        area=area,
        station_min=station_min,
        station_max=station_max,
        bbox=bbox,
        lane=lane,
        min_speed=min_speed,
        max_speed=max_speed,
        smoothed=smoothed,
        limit=limit,
        cursor=cursor,
        format_=format_,
        site=site,
    )

    response = client.get_httpx_client().request(
        **kwargs,
    )

    return _build_response(client=client, response=response)


def sync(
    *,
    client: AuthenticatedClient,
    start: float | None | Unset = UNSET,
    end: float | None | Unset = UNSET,
    track_id: int | None | Unset = UNSET,
    area: AreaKind | None | Unset = UNSET,
    station_min: float | None | Unset = UNSET,
    station_max: float | None | Unset = UNSET,
    bbox: None | str | Unset = UNSET,
    lane: int | None | Unset = UNSET,
    min_speed: float | None | Unset = UNSET,
    max_speed: float | None | Unset = UNSET,
    smoothed: bool | Unset = False,
    limit: int | None | Unset = UNSET,
    cursor: None | str | Unset = UNSET,
    format_: GetTrajectoriesV1TrajectoriesGetFormat
    | Unset = GetTrajectoriesV1TrajectoriesGetFormat.JSON,
    site: None | str | Unset = UNSET,
) -> PointPage | Problem | None:
    """Get Trajectories

     Stored track points, oldest first, filtered by time window, area, speed and lane.

    Args:
        start (float | None | Unset): Capture time [s], inclusive
        end (float | None | Unset): Capture time [s], inclusive
        track_id (int | None | Unset):
        area (AreaKind | None | Unset): Only points in this work-zone area (by station)
        station_min (float | None | Unset): Station bound [m], inclusive
        station_max (float | None | Unset): Station bound [m], inclusive
        bbox (None | str | Unset): minLon,minLat,maxLon,maxLat [deg], e.g.
            `-84.40,33.74,-84.38,33.76`
        lane (int | None | Unset): Lane index (0: the rightmost; -1: between lanes)
        min_speed (float | None | Unset): Speed bound [m/s], inclusive
        max_speed (float | None | Unset): Speed bound [m/s], inclusive
        smoothed (bool | Unset): Smoothed points (true) or fused ones (false) Default: False.
        limit (int | None | Unset): Items per page (default 1000 points or 100 alerts, at most
            max_page_size)
        cursor (None | str | Unset): `next_cursor` of the previous page
        format_ (GetTrajectoriesV1TrajectoriesGetFormat | Unset): json, csv, geojson or parquet
            Default: GetTrajectoriesV1TrajectoriesGetFormat.JSON.
        site (None | str | Unset): Site id (a central gateway serves several; default: its first)

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        PointPage | Problem
    """

    return sync_detailed(
        client=client,
        start=start,
        end=end,
        track_id=track_id,
        area=area,
        station_min=station_min,
        station_max=station_max,
        bbox=bbox,
        lane=lane,
        min_speed=min_speed,
        max_speed=max_speed,
        smoothed=smoothed,
        limit=limit,
        cursor=cursor,
        format_=format_,
        site=site,
    ).parsed


async def asyncio_detailed(
    *,
    client: AuthenticatedClient,
    start: float | None | Unset = UNSET,
    end: float | None | Unset = UNSET,
    track_id: int | None | Unset = UNSET,
    area: AreaKind | None | Unset = UNSET,
    station_min: float | None | Unset = UNSET,
    station_max: float | None | Unset = UNSET,
    bbox: None | str | Unset = UNSET,
    lane: int | None | Unset = UNSET,
    min_speed: float | None | Unset = UNSET,
    max_speed: float | None | Unset = UNSET,
    smoothed: bool | Unset = False,
    limit: int | None | Unset = UNSET,
    cursor: None | str | Unset = UNSET,
    format_: GetTrajectoriesV1TrajectoriesGetFormat
    | Unset = GetTrajectoriesV1TrajectoriesGetFormat.JSON,
    site: None | str | Unset = UNSET,
) -> Response[PointPage | Problem]:
    """Get Trajectories

     Stored track points, oldest first, filtered by time window, area, speed and lane.

    Args:
        start (float | None | Unset): Capture time [s], inclusive
        end (float | None | Unset): Capture time [s], inclusive
        track_id (int | None | Unset):
        area (AreaKind | None | Unset): Only points in this work-zone area (by station)
        station_min (float | None | Unset): Station bound [m], inclusive
        station_max (float | None | Unset): Station bound [m], inclusive
        bbox (None | str | Unset): minLon,minLat,maxLon,maxLat [deg], e.g.
            `-84.40,33.74,-84.38,33.76`
        lane (int | None | Unset): Lane index (0: the rightmost; -1: between lanes)
        min_speed (float | None | Unset): Speed bound [m/s], inclusive
        max_speed (float | None | Unset): Speed bound [m/s], inclusive
        smoothed (bool | Unset): Smoothed points (true) or fused ones (false) Default: False.
        limit (int | None | Unset): Items per page (default 1000 points or 100 alerts, at most
            max_page_size)
        cursor (None | str | Unset): `next_cursor` of the previous page
        format_ (GetTrajectoriesV1TrajectoriesGetFormat | Unset): json, csv, geojson or parquet
            Default: GetTrajectoriesV1TrajectoriesGetFormat.JSON.
        site (None | str | Unset): Site id (a central gateway serves several; default: its first)

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Response[PointPage | Problem]
    """

    kwargs = _get_kwargs(
        start=start,
        end=end,
        track_id=track_id,
        area=area,
        station_min=station_min,
        station_max=station_max,
        bbox=bbox,
        lane=lane,
        min_speed=min_speed,
        max_speed=max_speed,
        smoothed=smoothed,
        limit=limit,
        cursor=cursor,
        format_=format_,
        site=site,
    )

    response = await client.get_async_httpx_client().request(**kwargs)

    return _build_response(client=client, response=response)


async def asyncio(
    *,
    client: AuthenticatedClient,
    start: float | None | Unset = UNSET,
    end: float | None | Unset = UNSET,
    track_id: int | None | Unset = UNSET,
    area: AreaKind | None | Unset = UNSET,
    station_min: float | None | Unset = UNSET,
    station_max: float | None | Unset = UNSET,
    bbox: None | str | Unset = UNSET,
    lane: int | None | Unset = UNSET,
    min_speed: float | None | Unset = UNSET,
    max_speed: float | None | Unset = UNSET,
    smoothed: bool | Unset = False,
    limit: int | None | Unset = UNSET,
    cursor: None | str | Unset = UNSET,
    format_: GetTrajectoriesV1TrajectoriesGetFormat
    | Unset = GetTrajectoriesV1TrajectoriesGetFormat.JSON,
    site: None | str | Unset = UNSET,
) -> PointPage | Problem | None:
    """Get Trajectories

     Stored track points, oldest first, filtered by time window, area, speed and lane.

    Args:
        start (float | None | Unset): Capture time [s], inclusive
        end (float | None | Unset): Capture time [s], inclusive
        track_id (int | None | Unset):
        area (AreaKind | None | Unset): Only points in this work-zone area (by station)
        station_min (float | None | Unset): Station bound [m], inclusive
        station_max (float | None | Unset): Station bound [m], inclusive
        bbox (None | str | Unset): minLon,minLat,maxLon,maxLat [deg], e.g.
            `-84.40,33.74,-84.38,33.76`
        lane (int | None | Unset): Lane index (0: the rightmost; -1: between lanes)
        min_speed (float | None | Unset): Speed bound [m/s], inclusive
        max_speed (float | None | Unset): Speed bound [m/s], inclusive
        smoothed (bool | Unset): Smoothed points (true) or fused ones (false) Default: False.
        limit (int | None | Unset): Items per page (default 1000 points or 100 alerts, at most
            max_page_size)
        cursor (None | str | Unset): `next_cursor` of the previous page
        format_ (GetTrajectoriesV1TrajectoriesGetFormat | Unset): json, csv, geojson or parquet
            Default: GetTrajectoriesV1TrajectoriesGetFormat.JSON.
        site (None | str | Unset): Site id (a central gateway serves several; default: its first)

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        PointPage | Problem
    """

    return (
        await asyncio_detailed(
            client=client,
            start=start,
            end=end,
            track_id=track_id,
            area=area,
            station_min=station_min,
            station_max=station_max,
            bbox=bbox,
            lane=lane,
            min_speed=min_speed,
            max_speed=max_speed,
            smoothed=smoothed,
            limit=limit,
            cursor=cursor,
            format_=format_,
            site=site,
        )
    ).parsed
