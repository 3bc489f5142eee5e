from http import HTTPStatus
from typing import Any, cast
from urllib.parse import quote

import httpx

from ...client import AuthenticatedClient, Client
from ...types import Response, UNSET
from ... import errors

from ...models.conflict_page import ConflictPage
from ...models.get_conflicts_v1_conflicts_get_format import (
    GetConflictsV1ConflictsGetFormat,
)
from ...models.problem import Problem
from ...types import UNSET, Unset
from typing import cast


def _get_kwargs(
    *,
    start: float,
    end: float,
    max_ttc: float | Unset = 1.5,
    max_pet: float | Unset = 5.0,
    smoothed: bool | Unset = False,
    limit: int | None | Unset = UNSET,
    cursor: None | str | Unset = UNSET,
    format_: GetConflictsV1ConflictsGetFormat
    | Unset = GetConflictsV1ConflictsGetFormat.JSON,
    site: None | str | Unset = UNSET,
) -> dict[str, Any]:

    params: dict[str, Any] = {}

    params["start"] = start

    params["end"] = end

    params["max_ttc"] = max_ttc

    params["max_pet"] = max_pet

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
        "url": "/v1/conflicts",
        "params": params,
    }

    return _kwargs


def _parse_response(
    *, client: AuthenticatedClient | Client, response: httpx.Response
) -> ConflictPage | Problem | None:
    if response.status_code == 200:
        response_200 = ConflictPage.from_dict(response.json())

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
) -> Response[ConflictPage | Problem]:
    return Response(
        status_code=HTTPStatus(response.status_code),
        content=response.content,
        headers=response.headers,
        parsed=_parse_response(client=client, response=response),
    )


def sync_detailed(
    *,
    client: AuthenticatedClient,
    start: float,
    end: float,
    max_ttc: float | Unset = 1.5,
    max_pet: float | Unset = 5.0,
    smoothed: bool | Unset = False,
    limit: int | None | Unset = UNSET,
    cursor: None | str | Unset = UNSET,
    format_: GetConflictsV1ConflictsGetFormat
    | Unset = GetConflictsV1ConflictsGetFormat.JSON,
    site: None | str | Unset = UNSET,
) -> Response[ConflictPage | Problem]:
    """Get Conflicts

     Conflicts (TTC, PET, DRAC, SSAM's MaxS, DeltaS, DR, MaxD, MaxDeltaV, angle and type)
    between the stored tracks of a window, ordered by the time of their minimum TTC.

    Args:
        start (float): Capture time [s], inclusive; the window is at most 3600 s
        end (float): Capture time [s], inclusive; the window is at most 3600 s
        max_ttc (float | Unset): TTC threshold [s] (SSAM: 1.5) Default: 1.5.
        max_pet (float | Unset): PET threshold [s] (SSAM: 5) Default: 5.0.
        smoothed (bool | Unset): Smoothed trajectories (true) or fused ones (false) Default:
            False.
        limit (int | None | Unset): Items per page (default 1000 points or 100 alerts, at most
            max_page_size)
        cursor (None | str | Unset): `next_cursor` of the previous page
        format_ (GetConflictsV1ConflictsGetFormat | Unset): json or csv (SSAM's table) Default:
            GetConflictsV1ConflictsGetFormat.JSON.
        site (None | str | Unset): Site id (a central gateway serves several; default: its first)

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Response[ConflictPage | Problem]
    """

    kwargs = _get_kwargs(
        start=start,
        end=end,
        max_ttc=max_ttc,
        max_pet=max_pet,
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
    start: float,
    end: float,
    max_ttc: float | Unset = 1.5,
    max_pet: float | Unset = 5.0,
    smoothed: bool | Unset = False,
    limit: int | None | Unset = UNSET,
    cursor: None | str | Unset = UNSET,
    format_: GetConflictsV1ConflictsGetFormat
    | Unset = GetConflictsV1ConflictsGetFormat.JSON,
    site: None | str | Unset = UNSET,
) -> ConflictPage | Problem | None:
    """Get Conflicts

     Conflicts (TTC, PET, DRAC, SSAM's MaxS, DeltaS, DR, MaxD, MaxDeltaV, angle and type)
    between the stored tracks of a window, ordered by the time of their minimum TTC.

    Args:
        start (float): Capture time [s], inclusive; the window is at most 3600 s
        end (float): Capture time [s], inclusive; the window is at most 3600 s
        max_ttc (float | Unset): TTC threshold [s] (SSAM: 1.5) Default: 1.5.
        max_pet (float | Unset): PET threshold [s] (SSAM: 5) Default: 5.0.
        smoothed (bool | Unset): Smoothed trajectories (true) or fused ones (false) Default:
            False.
        limit (int | None | Unset): Items per page (default 1000 points or 100 alerts, at most
            max_page_size)
        cursor (None | str | Unset): `next_cursor` of the previous page
        format_ (GetConflictsV1ConflictsGetFormat | Unset): json or csv (SSAM's table) Default:
            GetConflictsV1ConflictsGetFormat.JSON.
        site (None | str | Unset): Site id (a central gateway serves several; default: its first)

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        ConflictPage | Problem
    """

    return sync_detailed(
        client=client,
        start=start,
        end=end,
        max_ttc=max_ttc,
        max_pet=max_pet,
        smoothed=smoothed,
        limit=limit,
        cursor=cursor,
        format_=format_,
        site=site,
    ).parsed


async def asyncio_detailed(
    *,
    client: AuthenticatedClient,
    start: float,
    end: float,
    max_ttc: float | Unset = 1.5,
    max_pet: float | Unset = 5.0,
    smoothed: bool | Unset = False,
    limit: int | None | Unset = UNSET,
    cursor: None | str | Unset = UNSET,
    format_: GetConflictsV1ConflictsGetFormat
    | Unset = GetConflictsV1ConflictsGetFormat.JSON,
    site: None | str | Unset = UNSET,
) -> Response[ConflictPage | Problem]:
    """Get Conflicts

     Conflicts (TTC, PET, DRAC, SSAM's MaxS, DeltaS, DR, MaxD, MaxDeltaV, angle and type)
    between the stored tracks of a window, ordered by the time of their minimum TTC.

    Args:
        start (float): Capture time [s], inclusive; the window is at most 3600 s
        end (float): Capture time [s], inclusive; the window is at most 3600 s
        max_ttc (float | Unset): TTC threshold [s] (SSAM: 1.5) Default: 1.5.
        max_pet (float | Unset): PET threshold [s] (SSAM: 5) Default: 5.0.
        smoothed (bool | Unset): Smoothed trajectories (true) or fused ones (false) Default:
            False.
        limit (int | None | Unset): Items per page (default 1000 points or 100 alerts, at most
            max_page_size)
        cursor (None | str | Unset): `next_cursor` of the previous page
        format_ (GetConflictsV1ConflictsGetFormat | Unset): json or csv (SSAM's table) Default:
            GetConflictsV1ConflictsGetFormat.JSON.
        site (None | str | Unset): Site id (a central gateway serves several; default: its first)

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Response[ConflictPage | Problem]
    """

    kwargs = _get_kwargs(
        start=start,
        end=end,
        max_ttc=max_ttc,
        max_pet=max_pet,
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
    start: float,
    end: float,
    max_ttc: float | Unset = 1.5,
    max_pet: float | Unset = 5.0,
    smoothed: bool | Unset = False,
    limit: int | None | Unset = UNSET,
    cursor: None | str | Unset = UNSET,
    format_: GetConflictsV1ConflictsGetFormat
    | Unset = GetConflictsV1ConflictsGetFormat.JSON,
    site: None | str | Unset = UNSET,
) -> ConflictPage | Problem | None:
    """Get Conflicts

     Conflicts (TTC, PET, DRAC, SSAM's MaxS, DeltaS, DR, MaxD, MaxDeltaV, angle and type)
    between the stored tracks of a window, ordered by the time of their minimum TTC.

    Args:
        start (float): Capture time [s], inclusive; the window is at most 3600 s
        end (float): Capture time [s], inclusive; the window is at most 3600 s
        max_ttc (float | Unset): TTC threshold [s] (SSAM: 1.5) Default: 1.5.
        max_pet (float | Unset): PET threshold [s] (SSAM: 5) Default: 5.0.
        smoothed (bool | Unset): Smoothed trajectories (true) or fused ones (false) Default:
            False.
        limit (int | None | Unset): Items per page (default 1000 points or 100 alerts, at most
            max_page_size)
        cursor (None | str | Unset): `next_cursor` of the previous page
        format_ (GetConflictsV1ConflictsGetFormat | Unset): json or csv (SSAM's table) Default:
            GetConflictsV1ConflictsGetFormat.JSON.
        site (None | str | Unset): Site id (a central gateway serves several; default: its first)

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        ConflictPage | Problem
    """

    return (
        await asyncio_detailed(
            client=client,
            start=start,
            end=end,
            max_ttc=max_ttc,
            max_pet=max_pet,
            smoothed=smoothed,
            limit=limit,
            cursor=cursor,
            format_=format_,
            site=site,
        )
    ).parsed
