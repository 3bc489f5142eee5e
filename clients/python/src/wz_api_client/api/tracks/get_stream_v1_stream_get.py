from http import HTTPStatus
from typing import Any, cast
from urllib.parse import quote

import httpx

from ...client import AuthenticatedClient, Client
from ...types import Response, UNSET
from ... import errors

from ...models.get_stream_v1_stream_get_event_type_0_item import (
    GetStreamV1StreamGetEventType0Item,
)
from ...models.problem import Problem
from ...types import UNSET, Unset
from typing import cast


def _get_kwargs(
    *,
    event: list[GetStreamV1StreamGetEventType0Item] | None | Unset = UNSET,
    last_event_id: None | str | Unset = UNSET,
) -> dict[str, Any]:
    headers: dict[str, Any] = {}
    if not isinstance(last_event_id, Unset):
        headers["last-event-id"] = last_event_id

    params: dict[str, Any] = {}

    json_event: list[str] | None | Unset
    if isinstance(event, Unset):
        json_event = UNSET
    elif isinstance(event, list):
        json_event = []
        for event_type_0_item_data in event:
            event_type_0_item = event_type_0_item_data.value
            json_event.append(event_type_0_item)

    else:
        json_event = event
    params["event"] = json_event

    params = {k: v for k, v in params.items() if v is not UNSET and v is not None}

    _kwargs: dict[str, Any] = {
        "method": "get",
        "url": "/v1/stream",
        "params": params,
    }

    _kwargs["headers"] = headers
    return _kwargs


def _parse_response(
    *, client: AuthenticatedClient | Client, response: httpx.Response
) -> Problem | str | None:
    if response.status_code == 200:
        response_200 = response.text
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
) -> Response[Problem | str]:
    return Response(
        status_code=HTTPStatus(response.status_code),
        content=response.content,
        headers=response.headers,
        parsed=_parse_response(client=client, response=response),
    )


def sync_detailed(
    *,
    client: AuthenticatedClient,
    event: list[GetStreamV1StreamGetEventType0Item] | None | Unset = UNSET,
    last_event_id: None | str | Unset = UNSET,
) -> Response[Problem | str]:
    """Get Stream

     Live events as Server-Sent Events: ``tracks`` (the newest track batch, compact, at
    most ``stream_max_hz`` a second), ``alert`` (each alert as it is stored) and
    ``calibration`` (each sensor's self-calibration as it is stored; each sensor's newest
    first on connecting), each with an ``id``; a ``retry`` hint first and a comment every
    ``stream_heartbeat_s``. A client
    that reads too slowly loses its oldest events, never holds up the gateway.

    Args:
        event (list[GetStreamV1StreamGetEventType0Item] | None | Unset): Events to send (repeat
            for several); default: all
        last_event_id (None | str | Unset): Sent by a reconnecting client: the alerts it missed
            come first

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Response[Problem | str]
    """

    kwargs = _get_kwargs(
        event=event,
        last_event_id=last_event_id,
    )

    response = client.get_httpx_client().request(
        **kwargs,
    )

    return _build_response(client=client, response=response)


def sync(
    *,
    client: AuthenticatedClient,
    event: list[GetStreamV1StreamGetEventType0Item] | None | Unset = UNSET,
    last_event_id: None | str | Unset = UNSET,
) -> Problem | str | None:
    """Get Stream

     Live events as Server-Sent Events: ``tracks`` (the newest track batch, compact, at
    most ``stream_max_hz`` a second), ``alert`` (each alert as it is stored) and
    ``calibration`` (each sensor's self-calibration as it is stored; each sensor's newest
    first on connecting), each with an ``id``; a ``retry`` hint first and a comment every
    ``stream_heartbeat_s``. A client
    that reads too slowly loses its oldest events, never holds up the gateway.

    Args:
        event (list[GetStreamV1StreamGetEventType0Item] | None | Unset): Events to send (repeat
            for several); default: all
        last_event_id (None | str | Unset): Sent by a reconnecting client: the alerts it missed
            come first

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Problem | str
    """

    return sync_detailed(
        client=client,
        event=event,
        last_event_id=last_event_id,
    ).parsed


async def asyncio_detailed(
    *,
    client: AuthenticatedClient,
    event: list[GetStreamV1StreamGetEventType0Item] | None | Unset = UNSET,
    last_event_id: None | str | Unset = UNSET,
) -> Response[Problem | str]:
    """Get Stream

     Live events as Server-Sent Events: ``tracks`` (the newest track batch, compact, at
    most ``stream_max_hz`` a second), ``alert`` (each alert as it is stored) and
    ``calibration`` (each sensor's self-calibration as it is stored; each sensor's newest
    first on connecting), each with an ``id``; a ``retry`` hint first and a comment every
    ``stream_heartbeat_s``. A client
    that reads too slowly loses its oldest events, never holds up the gateway.

    Args:
        event (list[GetStreamV1StreamGetEventType0Item] | None | Unset): Events to send (repeat
            for several); default: all
        last_event_id (None | str | Unset): Sent by a reconnecting client: the alerts it missed
            come first

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Response[Problem | str]
    """

    kwargs = _get_kwargs(
        event=event,
        last_event_id=last_event_id,
    )

    response = await client.get_async_httpx_client().request(**kwargs)

    return _build_response(client=client, response=response)


async def asyncio(
    *,
    client: AuthenticatedClient,
    event: list[GetStreamV1StreamGetEventType0Item] | None | Unset = UNSET,
    last_event_id: None | str | Unset = UNSET,
) -> Problem | str | None:
    """Get Stream

     Live events as Server-Sent Events: ``tracks`` (the newest track batch, compact, at
    most ``stream_max_hz`` a second), ``alert`` (each alert as it is stored) and
    ``calibration`` (each sensor's self-calibration as it is stored; each sensor's newest
    first on connecting), each with an ``id``; a ``retry`` hint first and a comment every
    ``stream_heartbeat_s``. A client
    that reads too slowly loses its oldest events, never holds up the gateway.

    Args:
        event (list[GetStreamV1StreamGetEventType0Item] | None | Unset): Events to send (repeat
            for several); default: all
        last_event_id (None | str | Unset): Sent by a reconnecting client: the alerts it missed
            come first

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Problem | str
    """

    return (
        await asyncio_detailed(
            client=client,
            event=event,
            last_event_id=last_event_id,
        )
    ).parsed
