from http import HTTPStatus
from typing import Any, cast
from urllib.parse import quote

import httpx

from ...client import AuthenticatedClient, Client
from ...types import Response, UNSET
from ... import errors

from ...models.get_device_feed_v1_wzdx_device_feed_get_response_200 import (
    GetDeviceFeedV1WzdxDeviceFeedGetResponse200,
)
from ...models.problem import Problem
from ...types import UNSET, Unset
from typing import cast


def _get_kwargs(
    *,
    site: None | str | Unset = UNSET,
) -> dict[str, Any]:

    params: dict[str, Any] = {}

    json_site: None | str | Unset
    if isinstance(site, Unset):
        json_site = UNSET
    else:
        json_site = site
    params["site"] = json_site

    params = {k: v for k, v in params.items() if v is not UNSET and v is not None}

    _kwargs: dict[str, Any] = {
        "method": "get",
        "url": "/v1/wzdx/device-feed",
        "params": params,
    }

    return _kwargs


def _parse_response(
    *, client: AuthenticatedClient | Client, response: httpx.Response
) -> GetDeviceFeedV1WzdxDeviceFeedGetResponse200 | Problem | None:
    if response.status_code == 200:
        response_200 = GetDeviceFeedV1WzdxDeviceFeedGetResponse200.from_dict(
            response.json()
        )

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
) -> Response[GetDeviceFeedV1WzdxDeviceFeedGetResponse200 | Problem]:
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
) -> Response[GetDeviceFeedV1WzdxDeviceFeedGetResponse200 | Problem]:
    """Get Device Feed

     The WZDx 4.2 DeviceFeed: traffic sensor (per-lane volumes, speeds, occupancy over the
    newest collection interval), cameras, flashing beacon and message sign, with status (a
    knocked sensor, or one that has not learned its pose for long, is ``warning``).

    Args:
        site (None | str | Unset): Only this site's devices (default: every site's)

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Response[GetDeviceFeedV1WzdxDeviceFeedGetResponse200 | Problem]
    """

    kwargs = _get_kwargs(
        site=site,
    )

    response = client.get_httpx_client().request(
        **kwargs,
    )

    return _build_response(client=client, response=response)


def sync(
    *,
    client: AuthenticatedClient,
    site: None | str | Unset = UNSET,
) -> GetDeviceFeedV1WzdxDeviceFeedGetResponse200 | Problem | None:
    """Get Device Feed

     The WZDx 4.2 DeviceFeed: traffic sensor (per-lane volumes, speeds, occupancy over the
    newest collection interval), cameras, flashing beacon and message sign, with status (a
    knocked sensor, or one that has not learned its pose for long, is ``warning``).

    Args:
        site (None | str | Unset): Only this site's devices (default: every site's)

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        GetDeviceFeedV1WzdxDeviceFeedGetResponse200 | Problem
    """

    return sync_detailed(
        client=client,
        site=site,
    ).parsed


async def asyncio_detailed(
    *,
    client: AuthenticatedClient,
    site: None | str | Unset = UNSET,
) -> Response[GetDeviceFeedV1WzdxDeviceFeedGetResponse200 | Problem]:
    """Get Device Feed

     The WZDx 4.2 DeviceFeed: traffic sensor (per-lane volumes, speeds, occupancy over the
    newest collection interval), cameras, flashing beacon and message sign, with status (a
    knocked sensor, or one that has not learned its pose for long, is ``warning``).

    Args:
        site (None | str | Unset): Only this site's devices (default: every site's)

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Response[GetDeviceFeedV1WzdxDeviceFeedGetResponse200 | Problem]
    """

    kwargs = _get_kwargs(
        site=site,
    )

    response = await client.get_async_httpx_client().request(**kwargs)

    return _build_response(client=client, response=response)


async def asyncio(
    *,
    client: AuthenticatedClient,
    site: None | str | Unset = UNSET,
) -> GetDeviceFeedV1WzdxDeviceFeedGetResponse200 | Problem | None:
    """Get Device Feed

     The WZDx 4.2 DeviceFeed: traffic sensor (per-lane volumes, speeds, occupancy over the
    newest collection interval), cameras, flashing beacon and message sign, with status (a
    knocked sensor, or one that has not learned its pose for long, is ``warning``).

    Args:
        site (None | str | Unset): Only this site's devices (default: every site's)

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        GetDeviceFeedV1WzdxDeviceFeedGetResponse200 | Problem
    """

    return (
        await asyncio_detailed(
            client=client,
            site=site,
        )
    ).parsed
