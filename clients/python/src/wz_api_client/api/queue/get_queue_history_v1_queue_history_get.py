from http import HTTPStatus
from typing import Any, cast
from urllib.parse import quote

import httpx

from ...client import AuthenticatedClient, Client
from ...types import Response, UNSET
from ... import errors

from ...models.get_queue_history_v1_queue_history_get_order import (
    GetQueueHistoryV1QueueHistoryGetOrder,
)
from ...models.problem import Problem
from ...models.queue_condition import QueueCondition
from ...models.queue_page import QueuePage
from ...types import UNSET, Unset
from typing import cast


def _get_kwargs(
    *,
    start: float | None | Unset = UNSET,
    end: float | None | Unset = UNSET,
    condition: list[QueueCondition] | None | Unset = UNSET,
    order: GetQueueHistoryV1QueueHistoryGetOrder
    | Unset = GetQueueHistoryV1QueueHistoryGetOrder.NEWEST,
    limit: int | None | Unset = UNSET,
    cursor: None | str | Unset = UNSET,
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

    json_condition: list[str] | None | Unset
    if isinstance(condition, Unset):
        json_condition = UNSET
    elif isinstance(condition, list):
        json_condition = []
        for condition_type_0_item_data in condition:
            condition_type_0_item = condition_type_0_item_data.value
            json_condition.append(condition_type_0_item)

    else:
        json_condition = condition
    params["condition"] = json_condition

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

    json_site: None | str | Unset
    if isinstance(site, Unset):
        json_site = UNSET
    else:
        json_site = site
    params["site"] = json_site

    params = {k: v for k, v in params.items() if v is not UNSET and v is not None}

    _kwargs: dict[str, Any] = {
        "method": "get",
        "url": "/v1/queue/history",
        "params": params,
    }

    return _kwargs


def _parse_response(
    *, client: AuthenticatedClient | Client, response: httpx.Response
) -> Problem | QueuePage | None:
    if response.status_code == 200:
        response_200 = QueuePage.from_dict(response.json())

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
) -> Response[Problem | QueuePage]:
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
    condition: list[QueueCondition] | None | Unset = UNSET,
    order: GetQueueHistoryV1QueueHistoryGetOrder
    | Unset = GetQueueHistoryV1QueueHistoryGetOrder.NEWEST,
    limit: int | None | Unset = UNSET,
    cursor: None | str | Unset = UNSET,
    site: None | str | Unset = UNSET,
) -> Response[Problem | QueuePage]:
    """Get Queue History

     Stored queue states (one a second of track stamps, and one at each change of a lane's
    condition), newest first unless ``order=oldest``.

    Args:
        start (float | None | Unset): Capture time [s], inclusive
        end (float | None | Unset): Capture time [s], inclusive
        condition (list[QueueCondition] | None | Unset): Only states whose worst lane is in this
            condition; repeat for several
        order (GetQueueHistoryV1QueueHistoryGetOrder | Unset):  Default:
            GetQueueHistoryV1QueueHistoryGetOrder.NEWEST.
        limit (int | None | Unset): Items per page (default 1000 points or 100 alerts, at most
            max_page_size)
        cursor (None | str | Unset): `next_cursor` of the previous page
        site (None | str | Unset): Site id (a central gateway serves several; default: its first)

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Response[Problem | QueuePage]
    """

    kwargs = _get_kwargs(
        start=start,
        end=end,
        condition=condition,
        order=order,
        limit=limit,
        cursor=cursor,
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
    condition: list[QueueCondition] | None | Unset = UNSET,
    order: GetQueueHistoryV1QueueHistoryGetOrder
    | Unset = GetQueueHistoryV1QueueHistoryGetOrder.NEWEST,
    limit: int | None | Unset = UNSET,
    cursor: None | str | Unset = UNSET,
    site: None | str | Unset = UNSET,
) -> Problem | QueuePage | None:
    """Get Queue History

     Stored queue states (one a second of track stamps, and one at each change of a lane's
    condition), newest first unless ``order=oldest``.

    Args:
        start (float | None | Unset): Capture time [s], inclusive
        end (float | None | Unset): Capture time [s], inclusive
        condition (list[QueueCondition] | None | Unset): Only states whose worst lane is in this
            condition; repeat for several
        order (GetQueueHistoryV1QueueHistoryGetOrder | Unset):  Default:
            GetQueueHistoryV1QueueHistoryGetOrder.NEWEST.
        limit (int | None | Unset): Items per page (default 1000 points or 100 alerts, at most
            max_page_size)
        cursor (None | str | Unset): `next_cursor` of the previous page
        site (None | str | Unset): Site id (a central gateway serves several; default: its first)

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Problem | QueuePage
    """

    return sync_detailed(
        client=client,
        start=start,
        end=end,
        condition=condition,
        order=order,
        limit=limit,
        cursor=cursor,
        site=site,
    ).parsed


async def asyncio_detailed(
    *,
    client: AuthenticatedClient,
    start: float | None | Unset = UNSET,
    end: float | None | Unset = UNSET,
    condition: list[QueueCondition] | None | Unset = UNSET,
    order: GetQueueHistoryV1QueueHistoryGetOrder
    | Unset = GetQueueHistoryV1QueueHistoryGetOrder.NEWEST,
    limit: int | None | Unset = UNSET,
    cursor: None | str | Unset = UNSET,
    site: None | str | Unset = UNSET,
) -> Response[Problem | QueuePage]:
    """Get Queue History

     Stored queue states (one a second of track stamps, and one at each change of a lane's
    condition), newest first unless ``order=oldest``.

    Args:
        start (float | None | Unset): Capture time [s], inclusive
        end (float | None | Unset): Capture time [s], inclusive
        condition (list[QueueCondition] | None | Unset): Only states whose worst lane is in this
            condition; repeat for several
        order (GetQueueHistoryV1QueueHistoryGetOrder | Unset):  Default:
            GetQueueHistoryV1QueueHistoryGetOrder.NEWEST.
        limit (int | None | Unset): Items per page (default 1000 points or 100 alerts, at most
            max_page_size)
        cursor (None | str | Unset): `next_cursor` of the previous page
        site (None | str | Unset): Site id (a central gateway serves several; default: its first)

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Response[Problem | QueuePage]
    """

    kwargs = _get_kwargs(
        start=start,
        end=end,
        condition=condition,
        order=order,
        limit=limit,
        cursor=cursor,
        site=site,
    )

    response = await client.get_async_httpx_client().request(**kwargs)

    return _build_response(client=client, response=response)


async def asyncio(
    *,
    client: AuthenticatedClient,
    start: float | None | Unset = UNSET,
    end: float | None | Unset = UNSET,
    condition: list[QueueCondition] | None | Unset = UNSET,
    order: GetQueueHistoryV1QueueHistoryGetOrder
    | Unset = GetQueueHistoryV1QueueHistoryGetOrder.NEWEST,
    limit: int | None | Unset = UNSET,
    cursor: None | str | Unset = UNSET,
    site: None | str | Unset = UNSET,
) -> Problem | QueuePage | None:
    """Get Queue History

     Stored queue states (one a second of track stamps, and one at each change of a lane's
    condition), newest first unless ``order=oldest``.

    Args:
        start (float | None | Unset): Capture time [s], inclusive
        end (float | None | Unset): Capture time [s], inclusive
        condition (list[QueueCondition] | None | Unset): Only states whose worst lane is in this
            condition; repeat for several
        order (GetQueueHistoryV1QueueHistoryGetOrder | Unset):  Default:
            GetQueueHistoryV1QueueHistoryGetOrder.NEWEST.
        limit (int | None | Unset): Items per page (default 1000 points or 100 alerts, at most
            max_page_size)
        cursor (None | str | Unset): `next_cursor` of the previous page
        site (None | str | Unset): Site id (a central gateway serves several; default: its first)

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Problem | QueuePage
    """

    return (
        await asyncio_detailed(
            client=client,
            start=start,
            end=end,
            condition=condition,
            order=order,
            limit=limit,
            cursor=cursor,
            site=site,
        )
    ).parsed
