from http import HTTPStatus
from typing import Any, cast
from urllib.parse import quote

import httpx

from ...client import AuthenticatedClient, Client
from ...types import Response, UNSET
from ... import errors

from ...models.problem import Problem
from ...models.site_queue import SiteQueue
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
        "url": "/v1/queue",
        "params": params,
    }

    return _kwargs


def _parse_response(
    *, client: AuthenticatedClient | Client, response: httpx.Response
) -> Problem | SiteQueue | None:
    if response.status_code == 200:
        response_200 = SiteQueue.from_dict(response.json())

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
) -> Response[Problem | SiteQueue]:
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
) -> Response[Problem | SiteQueue]:
    """Get Queue

     Each lane's queue now: the newest state the site's alert service published, when it
    arrived and whether it is older than ``stale_after_s``. A lane's ``back_station_m`` is its
    most upstream queued vehicle; with ``back_beyond_reach`` the queue goes on past the
    sensors' upstream reach (``reach_station_m``) and its back is not measured.

    Args:
        site (None | str | Unset): Site id (a central gateway serves several; default: its first)

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Response[Problem | SiteQueue]
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
) -> Problem | SiteQueue | None:
    """Get Queue

     Each lane's queue now: the newest state the site's alert service published, when it
    arrived and whether it is older than ``stale_after_s``. A lane's ``back_station_m`` is its
    most upstream queued vehicle; with ``back_beyond_reach`` the queue goes on past the
    sensors' upstream reach (``reach_station_m``) and its back is not measured.

    Args:
        site (None | str | Unset): Site id (a central gateway serves several; default: its first)

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Problem | SiteQueue
    """

    return sync_detailed(
        client=client,
        site=site,
    ).parsed


async def asyncio_detailed(
    *,
    client: AuthenticatedClient,
    site: None | str | Unset = UNSET,
) -> Response[Problem | SiteQueue]:
    """Get Queue

     Each lane's queue now: the newest state the site's alert service published, when it
    arrived and whether it is older than ``stale_after_s``. A lane's ``back_station_m`` is its
    most upstream queued vehicle; with ``back_beyond_reach`` the queue goes on past the
    sensors' upstream reach (``reach_station_m``) and its back is not measured.

    Args:
        site (None | str | Unset): Site id (a central gateway serves several; default: its first)

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Response[Problem | SiteQueue]
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
) -> Problem | SiteQueue | None:
    """Get Queue

     Each lane's queue now: the newest state the site's alert service published, when it
    arrived and whether it is older than ``stale_after_s``. A lane's ``back_station_m`` is its
    most upstream queued vehicle; with ``back_beyond_reach`` the queue goes on past the
    sensors' upstream reach (``reach_station_m``) and its back is not measured.

    Args:
        site (None | str | Unset): Site id (a central gateway serves several; default: its first)

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Problem | SiteQueue
    """

    return (
        await asyncio_detailed(
            client=client,
            site=site,
        )
    ).parsed
