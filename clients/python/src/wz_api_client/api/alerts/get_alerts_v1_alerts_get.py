from http import HTTPStatus
from typing import Any, cast
from urllib.parse import quote

import httpx

from ...client import AuthenticatedClient, Client
from ...types import Response, UNSET
from ... import errors

from ...models.alert_page import AlertPage
from ...models.alert_severity import AlertSeverity
from ...models.alert_type import AlertType
from ...models.get_alerts_v1_alerts_get_format import GetAlertsV1AlertsGetFormat
from ...models.get_alerts_v1_alerts_get_order import GetAlertsV1AlertsGetOrder
from ...models.get_alerts_v1_alerts_get_phase_type_0_item import (
    GetAlertsV1AlertsGetPhaseType0Item,
)
from ...models.problem import Problem
from ...types import UNSET, Unset
from typing import cast


def _get_kwargs(
    *,
    site: None | str | Unset = UNSET,
    type_: list[AlertType] | None | Unset = UNSET,
    severity: list[AlertSeverity] | None | Unset = UNSET,
    phase: list[GetAlertsV1AlertsGetPhaseType0Item] | None | Unset = UNSET,
    start: float | None | Unset = UNSET,
    end: float | None | Unset = UNSET,
    track_id: int | None | Unset = UNSET,
    episode_id: None | str | Unset = UNSET,
    order: GetAlertsV1AlertsGetOrder | Unset = GetAlertsV1AlertsGetOrder.NEWEST,
    limit: int | None | Unset = UNSET,
    cursor: None | str | Unset = UNSET,
    format_: GetAlertsV1AlertsGetFormat | Unset = GetAlertsV1AlertsGetFormat.JSON,
) -> dict[str, Any]:

    params: dict[str, Any] = {}

    json_site: None | str | Unset
    if isinstance(site, Unset):
        json_site = UNSET
    else:
        json_site = site
    params["site"] = json_site

    json_type_: list[str] | None | Unset
    if isinstance(type_, Unset):
        json_type_ = UNSET
    elif isinstance(type_, list):
        json_type_ = []
        for type_type_0_item_data in type_:
            type_type_0_item = type_type_0_item_data.value
            json_type_.append(type_type_0_item)

    else:
        json_type_ = type_
    params["type"] = json_type_

    json_severity: list[str] | None | Unset
    if isinstance(severity, Unset):
        json_severity = UNSET
    elif isinstance(severity, list):
        json_severity = []
        for severity_type_0_item_data in severity:
            severity_type_0_item = severity_type_0_item_data.value
            json_severity.append(severity_type_0_item)

    else:
        json_severity = severity
    params["severity"] = json_severity

    json_phase: list[str] | None | Unset
    if isinstance(phase, Unset):
        json_phase = UNSET
    elif isinstance(phase, list):
        json_phase = []
        for phase_type_0_item_data in phase:
            phase_type_0_item = phase_type_0_item_data.value
            json_phase.append(phase_type_0_item)

    else:
        json_phase = phase
    params["phase"] = json_phase

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

    json_episode_id: None | str | Unset
    if isinstance(episode_id, Unset):
        json_episode_id = UNSET
    else:
        json_episode_id = episode_id
    params["episode_id"] = json_episode_id

    json_order: str | Unset = UNSET
    if not isinstance(order, Unset):
        json_order = order.value

    params["order"] = json_order

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

    params = {k: v for k, v in params.items() if v is not UNSET and v is not None}

    _kwargs: dict[str, Any] = {
        "method": "get",
        "url": "/v1/alerts",
        "params": params,
    }

    return _kwargs


def _parse_response(
    *, client: AuthenticatedClient | Client, response: httpx.Response
) -> AlertPage | Problem | None:
    if response.status_code == 200:
        response_200 = AlertPage.from_dict(response.json())

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
) -> Response[AlertPage | Problem]:
    return Response(
        status_code=HTTPStatus(response.status_code),
        content=response.content,
        headers=response.headers,
        parsed=_parse_response(client=client, response=response),
    )


def sync_detailed(
    *,
    client: AuthenticatedClient,
    site: None | str | Unset = UNSET,
    type_: list[AlertType] | None | Unset = UNSET,
    severity: list[AlertSeverity] | None | Unset = UNSET,
    phase: list[GetAlertsV1AlertsGetPhaseType0Item] | None | Unset = UNSET,
    start: float | None | Unset = UNSET,
    end: float | None | Unset = UNSET,
    track_id: int | None | Unset = UNSET,
    episode_id: None | str | Unset = UNSET,
    order: GetAlertsV1AlertsGetOrder | Unset = GetAlertsV1AlertsGetOrder.NEWEST,
    limit: int | None | Unset = UNSET,
    cursor: None | str | Unset = UNSET,
    format_: GetAlertsV1AlertsGetFormat | Unset = GetAlertsV1AlertsGetFormat.JSON,
) -> Response[AlertPage | Problem]:
    """Get Alerts

     Alert events (start, update, clear), newest first unless ``order=oldest``; as CSV or
    GeoJSON with ``format``.

    Args:
        site (None | str | Unset): Site id, or `*` for every site's (default: the gateway's first
            site)
        type_ (list[AlertType] | None | Unset): Repeat for several
        severity (list[AlertSeverity] | None | Unset):
        phase (list[GetAlertsV1AlertsGetPhaseType0Item] | None | Unset):
        start (float | None | Unset): Capture time [s], inclusive
        end (float | None | Unset): Capture time [s], inclusive
        track_id (int | None | Unset):
        episode_id (None | str | Unset):
        order (GetAlertsV1AlertsGetOrder | Unset):  Default: GetAlertsV1AlertsGetOrder.NEWEST.
        limit (int | None | Unset): Items per page (default 1000 points or 100 alerts, at most
            max_page_size)
        cursor (None | str | Unset): `next_cursor` of the previous page
        format_ (GetAlertsV1AlertsGetFormat | Unset): json, csv or geojson Default:
            GetAlertsV1AlertsGetFormat.JSON.

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Response[AlertPage | Problem]
    """

    kwargs = _get_kwargs(
        site=site,
        type_=type_,
        severity=severity,
        phase=phase,
        start=start,
        end=end,
        track_id=track_id,
        episode_id=episode_id,
        order=order,
        limit=limit,
        cursor=cursor,
        format_=format_,
    )

    response = client.get_httpx_client().request(
        **kwargs,
    )

    return _build_response(client=client, response=response)


def sync(
    *,
    client: AuthenticatedClient,
    site: None | str | Unset = UNSET,
    type_: list[AlertType] | None | Unset = UNSET,
    severity: list[AlertSeverity] | None | Unset = UNSET,
    phase: list[GetAlertsV1AlertsGetPhaseType0Item] | None | Unset = UNSET,
    start: float | None | Unset = UNSET,
    end: float | None | Unset = UNSET,
    track_id: int | None | Unset = UNSET,
    episode_id: None | str | Unset = UNSET,
    order: GetAlertsV1AlertsGetOrder | Unset = GetAlertsV1AlertsGetOrder.NEWEST,
    limit: int | None | Unset = UNSET,
    cursor: None | str | Unset = UNSET,
    format_: GetAlertsV1AlertsGetFormat | Unset = GetAlertsV1AlertsGetFormat.JSON,
) -> AlertPage | Problem | None:
    """Get Alerts

     Alert events (start, update, clear), newest first unless ``order=oldest``; as CSV or
    GeoJSON with ``format``.

    Args:
        site (None | str | Unset): Site id, or `*` for every site's (default: the gateway's first
            site)
        type_ (list[AlertType] | None | Unset): Repeat for several
        severity (list[AlertSeverity] | None | Unset):
        phase (list[GetAlertsV1AlertsGetPhaseType0Item] | None | Unset):
        start (float | None | Unset): Capture time [s], inclusive
        end (float | None | Unset): Capture time [s], inclusive
        track_id (int | None | Unset):
        episode_id (None | str | Unset):
        order (GetAlertsV1AlertsGetOrder | Unset):  Default: GetAlertsV1AlertsGetOrder.NEWEST.
        limit (int | None | Unset): Items per page (default 1000 points or 100 alerts, at most
            max_page_size)
        cursor (None | str | Unset): `next_cursor` of the previous page
        format_ (GetAlertsV1AlertsGetFormat | Unset): json, csv or geojson Default:
            GetAlertsV1AlertsGetFormat.JSON.

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        AlertPage | Problem
    """

    return sync_detailed(
        client=client,
        site=site,
        type_=type_,
        severity=severity,
        phase=phase,
        start=start,
        end=end,
        track_id=track_id,
        episode_id=episode_id,
        order=order,
        limit=limit,
        cursor=cursor,
        format_=format_,
    ).parsed


async def asyncio_detailed(
    *,
    client: AuthenticatedClient,
    site: None | str | Unset = UNSET,
    type_: list[AlertType] | None | Unset = UNSET,
    severity: list[AlertSeverity] | None | Unset = UNSET,
    phase: list[GetAlertsV1AlertsGetPhaseType0Item] | None | Unset = UNSET,
    start: float | None | Unset = UNSET,
    end: float | None | Unset = UNSET,
    track_id: int | None | Unset = UNSET,
    episode_id: None | str | Unset = UNSET,
    order: GetAlertsV1AlertsGetOrder | Unset = GetAlertsV1AlertsGetOrder.NEWEST,
    limit: int | None | Unset = UNSET,
    cursor: None | str | Unset = UNSET,
    format_: GetAlertsV1AlertsGetFormat | Unset = GetAlertsV1AlertsGetFormat.JSON,
) -> Response[AlertPage | Problem]:
    """Get Alerts

     Alert events (start, update, clear), newest first unless ``order=oldest``; as CSV or
    GeoJSON with ``format``.

    Args:
        site (None | str | Unset): Site id, or `*` for every site's (default: the gateway's first
            site)
        type_ (list[AlertType] | None | Unset): Repeat for several
        severity (list[AlertSeverity] | None | Unset):
        phase (list[GetAlertsV1AlertsGetPhaseType0Item] | None | Unset):
        start (float | None | Unset): Capture time [s], inclusive
        end (float | None | Unset): Capture time [s], inclusive
        track_id (int | None | Unset):
        episode_id (None | str | Unset):
        order (GetAlertsV1AlertsGetOrder | Unset):  Default: GetAlertsV1AlertsGetOrder.NEWEST.
        limit (int | None | Unset): Items per page (default 1000 points or 100 alerts, at most
            max_page_size)
        cursor (None | str | Unset): `next_cursor` of the previous page
        format_ (GetAlertsV1AlertsGetFormat | Unset): json, csv or geojson Default:
            GetAlertsV1AlertsGetFormat.JSON.

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Response[AlertPage | Problem]
    """

    kwargs = _get_kwargs(
        site=site,
        type_=type_,
        severity=severity,
        phase=phase,
        start=start,
        end=end,
        track_id=track_id,
        episode_id=episode_id,
        order=order,
        limit=limit,
        cursor=cursor,
        format_=format_,
    )

    response = await client.get_async_httpx_client().request(**kwargs)

    return _build_response(client=client, response=response)


async def asyncio(
    *,
    client: AuthenticatedClient,
    site: None | str | Unset = UNSET,
    type_: list[AlertType] | None | Unset = UNSET,
    severity: list[AlertSeverity] | None | Unset = UNSET,
    phase: list[GetAlertsV1AlertsGetPhaseType0Item] | None | Unset = UNSET,
    start: float | None | Unset = UNSET,
    end: float | None | Unset = UNSET,
    track_id: int | None | Unset = UNSET,
    episode_id: None | str | Unset = UNSET,
    order: GetAlertsV1AlertsGetOrder | Unset = GetAlertsV1AlertsGetOrder.NEWEST,
    limit: int | None | Unset = UNSET,
    cursor: None | str | Unset = UNSET,
    format_: GetAlertsV1AlertsGetFormat | Unset = GetAlertsV1AlertsGetFormat.JSON,
) -> AlertPage | Problem | None:
    """Get Alerts

     Alert events (start, update, clear), newest first unless ``order=oldest``; as CSV or
    GeoJSON with ``format``.

    Args:
        site (None | str | Unset): Site id, or `*` for every site's (default: the gateway's first
            site)
        type_ (list[AlertType] | None | Unset): Repeat for several
        severity (list[AlertSeverity] | None | Unset):
        phase (list[GetAlertsV1AlertsGetPhaseType0Item] | None | Unset):
        start (float | None | Unset): Capture time [s], inclusive
        end (float | None | Unset): Capture time [s], inclusive
        track_id (int | None | Unset):
        episode_id (None | str | Unset):
        order (GetAlertsV1AlertsGetOrder | Unset):  Default: GetAlertsV1AlertsGetOrder.NEWEST.
        limit (int | None | Unset): Items per page (default 1000 points or 100 alerts, at most
            max_page_size)
        cursor (None | str | Unset): `next_cursor` of the previous page
        format_ (GetAlertsV1AlertsGetFormat | Unset): json, csv or geojson Default:
            GetAlertsV1AlertsGetFormat.JSON.

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        AlertPage | Problem
    """

    return (
        await asyncio_detailed(
            client=client,
            site=site,
            type_=type_,
            severity=severity,
            phase=phase,
            start=start,
            end=end,
            track_id=track_id,
            episode_id=episode_id,
            order=order,
            limit=limit,
            cursor=cursor,
            format_=format_,
        )
    ).parsed
