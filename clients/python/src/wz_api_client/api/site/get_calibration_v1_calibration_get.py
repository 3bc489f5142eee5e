from http import HTTPStatus
from typing import Any, cast
from urllib.parse import quote

import httpx

from ...client import AuthenticatedClient, Client
from ...types import Response, UNSET
from ... import errors

from ...models.problem import Problem
from ...models.site_calibration import SiteCalibration
from ...types import UNSET, Unset
from typing import cast


def _get_kwargs(
    *,
    changes: int | Unset = 10,
    site: None | str | Unset = UNSET,
) -> dict[str, Any]:

    params: dict[str, Any] = {}

    params["changes"] = changes

    json_site: None | str | Unset
    if isinstance(site, Unset):
        json_site = UNSET
    else:
        json_site = site
    params["site"] = json_site

    params = {k: v for k, v in params.items() if v is not UNSET and v is not None}

    _kwargs: dict[str, Any] = {
        "method": "get",
        "url": "/v1/calibration",
        "params": params,
    }

    return _kwargs


def _parse_response(
    *, client: AuthenticatedClient | Client, response: httpx.Response
) -> Problem | SiteCalibration | None:
    if response.status_code == 200:
        response_200 = SiteCalibration.from_dict(response.json())

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
) -> Response[Problem | SiteCalibration]:
    return Response(
        status_code=HTTPStatus(response.status_code),
        content=response.content,
        headers=response.headers,
        parsed=_parse_response(client=client, response=response),
    )


def sync_detailed(
    *,
    client: AuthenticatedClient,
    changes: int | Unset = 10,
    site: None | str | Unset = UNSET,
) -> Response[Problem | SiteCalibration]:
    """Get Calibration

     Each sensor's self-calibration: the newest message its detector published (pose
    correction with standard deviations, clock offset, state and since when, samples, why),
    when it arrived and whether that is longer ago than ``calibration_stale_after_s``, and
    its latest changes of state. Every sensor of the site file is listed, one never heard
    from without a message.

    Args:
        changes (int | Unset): How many of each sensor's latest changes of state to list (newest
            first): when it was knocked (`bumped`), when it was learned again Default: 10.
        site (None | str | Unset): Site id (a central gateway serves several; default: its first)

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Response[Problem | SiteCalibration]
    """

    kwargs = _get_kwargs(
        changes=changes,
        site=site,
    )

    response = client.get_httpx_client().request(
        **kwargs,
    )

    return _build_response(client=client, response=response)


def sync(
    *,
    client: AuthenticatedClient,
    changes: int | Unset = 10,
    site: None | str | Unset = UNSET,
) -> Problem | SiteCalibration | None:
    """Get Calibration

     Each sensor's self-calibration: the newest message its detector published (pose
    correction with standard deviations, clock offset, state and since when, samples, why),
    when it arrived and whether that is longer ago than ``calibration_stale_after_s``, and
    its latest changes of state. Every sensor of the site file is listed, one never heard
    from without a message.

    Args:
        changes (int | Unset): How many of each sensor's latest changes of state to list (newest
            first): when it was knocked (`bumped`), when it was learned again Default: 10.
        site (None | str | Unset): Site id (a central gateway serves several; default: its first)

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Problem | SiteCalibration
    """

    return sync_detailed(
        client=client,
        changes=changes,
        site=site,
    ).parsed


async def asyncio_detailed(
    *,
    client: AuthenticatedClient,
    changes: int | Unset = 10,
    site: None | str | Unset = UNSET,
) -> Response[Problem | SiteCalibration]:
    """Get Calibration

     Each sensor's self-calibration: the newest message its detector published (pose
    correction with standard deviations, clock offset, state and since when, samples, why),
    when it arrived and whether that is longer ago than ``calibration_stale_after_s``, and
    its latest changes of state. Every sensor of the site file is listed, one never heard
    from without a message.

    Args:
        changes (int | Unset): How many of each sensor's latest changes of state to list (newest
            first): when it was knocked (`bumped`), when it was learned again Default: 10.
        site (None | str | Unset): Site id (a central gateway serves several; default: its first)

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Response[Problem | SiteCalibration]
    """

    kwargs = _get_kwargs(
        changes=changes,
        site=site,
    )

    response = await client.get_async_httpx_client().request(**kwargs)

    return _build_response(client=client, response=response)


async def asyncio(
    *,
    client: AuthenticatedClient,
    changes: int | Unset = 10,
    site: None | str | Unset = UNSET,
) -> Problem | SiteCalibration | None:
    """Get Calibration

     Each sensor's self-calibration: the newest message its detector published (pose
    correction with standard deviations, clock offset, state and since when, samples, why),
    when it arrived and whether that is longer ago than ``calibration_stale_after_s``, and
    its latest changes of state. Every sensor of the site file is listed, one never heard
    from without a message.

    Args:
        changes (int | Unset): How many of each sensor's latest changes of state to list (newest
            first): when it was knocked (`bumped`), when it was learned again Default: 10.
        site (None | str | Unset): Site id (a central gateway serves several; default: its first)

    Raises:
        errors.UnexpectedStatus: If the server returns an undocumented status code and Client.raise_on_unexpected_status is True.
        httpx.TimeoutException: If the request takes longer than Client.timeout.

    Returns:
        Problem | SiteCalibration
    """

    return (
        await asyncio_detailed(
            client=client,
            changes=changes,
            site=site,
        )
    ).parsed
