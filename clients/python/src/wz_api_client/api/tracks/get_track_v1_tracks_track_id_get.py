from http import HTTPStatus
from typing import Any, cast
from urllib.parse import quote

import httpx

from ...client import AuthenticatedClient, Client
from ...types import Response, UNSET
from ... import errors

from ...models.get_track_v1_tracks_track_id_get_format import (
    GetTrackV1TracksTrackIdGetFormat,
)
from ...models.problem import Problem
from ...models.trajectory import Trajectory
from ...types import UNSET, Unset
from typing import cast


def _get_kwargs(
    track_id: int,
    *,
    start: float | None | Unset = UNSET,
    end: float | None | Unset = UNSET,
    smoothed: bool | Unset = False,
    limit: int | None | Unset = UNSET,
    cursor: None | str | Unset = UNSET,
    format_: GetTrackV1TracksTrackIdGetFormat
    | Unset = GetTrackV1TracksTrackIdGetFormat.JSON,
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
        "url": "/v1/tracks/{track_id}".format(
            track_id=quote(str(track_id), safe=""),
        ),
        "params": params,
    }

    return _kwargs


def _parse_response(
    *, client: AuthenticatedClient | Client, response: httpx.Response
) -> Problem | Trajectory | None:
    if response.status_code == 200:
        response_200 = Trajectory.from_dict(response.json())

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
) -> Response[Problem | Trajectory]:
    return Response(
        status_code=HTTPStatus(response.status_code),
        content=response.content,
        headers=response.headers,
        parsed=_parse_response(client=client, response=response),
    )


def sync_detailed(
    track_id: int,
    *,
    client: AuthenticatedClient,
    start: float | None | Unset = UNSET,
    end: float | None | Unset = UNSET,
    smoothed: bool | Unset = False,
    limit: int | None | Unset = UNSET,
    cursor: None | str | Unset = UNSET,
    format_: GetTrackV1TracksTrackIdGetFormat
    | Unset = GetTrackV1TracksTrackIdGetFormat.JSON,
    site: None | str | Unset = UNSET,
) -> Response[Problem | Trajectory]:
    """Get Track

     One track's stored trajectory, oldest first, a page at a time.

    Args:
        track_id (int): The tracker's track id
        start (float | None | Unset): Capture time [s], inclusive
        end (float | None | Unset): Capture time [s], inclusive
        smoothed (bool | Unset): The smoothed trajectory (true; stored when the track ends) or the
            fused one (false) Default: False.
        limit (int | None | Unset): Items per page (default 1000 points or 100 alerts, at most
            max_page_size)
        cursor (None | str | Unset): `next_cursor` of the previous page
        format_ (GetTrackV1TracksTrackIdGetFormat | Unset): json, csv, geojson or parquet Default:
            GetTrackV1TracksTrackIdGetFormat.JSON.
        site (None | str | Unset): Site id (a central gateway serves several; default: its first)

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Response[Problem | Trajectory]
    """

    kwargs = _get_kwargs(
        track_id=track_id,
        start=start,
        end=end,
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
    track_id: int,
    *,
    client: AuthenticatedClient,
    start: float | None | Unset = UNSET,
    end: float | None | Unset = UNSET,
    smoothed: bool | Unset = False,
    limit: int | None | Unset = UNSET,
    cursor: None | str | Unset = UNSET,
    format_: GetTrackV1TracksTrackIdGetFormat
    | Unset = GetTrackV1TracksTrackIdGetFormat.JSON,
    site: None | str | Unset = UNSET,
) -> Problem | Trajectory | None:
    """Get Track

     One track's stored trajectory, oldest first, a page at a time.

    Args:
        track_id (int): The tracker's track id
        start (float | None | Unset): Capture time [s], inclusive
        end (float | None | Unset): Capture time [s], inclusive
        smoothed (bool | Unset): The smoothed trajectory (true; stored when the track ends) or the
            fused one (false) Default: False.
        limit (int | None | Unset): Items per page (default 1000 points or 100 alerts, at most
            max_page_size)
        cursor (None | str | Unset): `next_cursor` of the previous page
        format_ (GetTrackV1TracksTrackIdGetFormat | Unset): json, csv, geojson or parquet Default:
            GetTrackV1TracksTrackIdGetFormat.JSON.
        site (None | str | Unset): Site id (a central gateway serves several; default: its first)

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Problem | Trajectory
    """

    return sync_detailed(
        track_id=track_id,
        client=client,
        start=start,
        end=end,
        smoothed=smoothed,
        limit=limit,
        cursor=cursor,
        format_=format_,
        site=site,
    ).parsed


async def asyncio_detailed(
    track_id: int,
    *,
    client: AuthenticatedClient,
    start: float | None | Unset = UNSET,
    end: float | None | Unset = UNSET,
    smoothed: bool | Unset = False,
    limit: int | None | Unset = UNSET,
    cursor: None | str | Unset = UNSET,
    format_: GetTrackV1TracksTrackIdGetFormat
    | Unset = GetTrackV1TracksTrackIdGetFormat.JSON,
    site: None | str | Unset = UNSET,
) -> Response[Problem | Trajectory]:
    """Get Track

     One track's stored trajectory, oldest first, a page at a time.

    Args:
        track_id (int): The tracker's track id
        start (float | None | Unset): Capture time [s], inclusive
        end (float | None | Unset): Capture time [s], inclusive
        smoothed (bool | Unset): The smoothed trajectory (true; stored when the track ends) or the
            fused one (false) Default: False.
        limit (int | None | Unset): Items per page (default 1000 points or 100 alerts, at most
            max_page_size)
        cursor (None | str | Unset): `next_cursor` of the previous page
        format_ (GetTrackV1TracksTrackIdGetFormat | Unset): json, csv, geojson or parquet Default:
            GetTrackV1TracksTrackIdGetFormat.JSON.
        site (None | str | Unset): Site id (a central gateway serves several; default: its first)

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Response[Problem | Trajectory]
    """

    kwargs = _get_kwargs(
        track_id=track_id,
        start=start,
        end=end,
        smoothed=smoothed,
        limit=limit,
        cursor=cursor,
        format_=format_,
        site=site,
    )

    response = await client.get_async_httpx_client().request(**kwargs)

    return _build_response(client=client, response=response)


async def asyncio(
    track_id: int,
    *,
    client: AuthenticatedClient,
    start: float | None | Unset = UNSET,
    end: float | None | Unset = UNSET,
    smoothed: bool | Unset = False,
    limit: int | None | Unset = UNSET,
    cursor: None | str | Unset = UNSET,
    format_: GetTrackV1TracksTrackIdGetFormat
    | Unset = GetTrackV1TracksTrackIdGetFormat.JSON,
    site: None | str | Unset = UNSET,
) -> Problem | Trajectory | None:
    """Get Track

     One track's stored trajectory, oldest first, a page at a time.

    Args:
        track_id (int): The tracker's track id
        start (float | None | Unset): Capture time [s], inclusive
        end (float | None | Unset): Capture time [s], inclusive
        smoothed (bool | Unset): The smoothed trajectory (true; stored when the track ends) or the
            fused one (false) Default: False.
        limit (int | None | Unset): Items per page (default 1000 points or 100 alerts, at most
            max_page_size)
        cursor (None | str | Unset): `next_cursor` of the previous page
        format_ (GetTrackV1TracksTrackIdGetFormat | Unset): json, csv, geojson or parquet Default:
            GetTrackV1TracksTrackIdGetFormat.JSON.
        site (None | str | Unset): Site id (a central gateway serves several; default: its first)

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Problem | Trajectory
    """

    return (
        await asyncio_detailed(
            track_id=track_id,
            client=client,
            start=start,
            end=end,
            smoothed=smoothed,
            limit=limit,
            cursor=cursor,
            format_=format_,
            site=site,
        )
    ).parsed
