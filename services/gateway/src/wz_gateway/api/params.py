"""Query parameters the routes share (times, pages, speeds, stations, export format) and the
paging helpers: the checks OpenAPI cannot state, and the ``Link`` to the next page."""

from __future__ import annotations

from typing import Annotated, Literal

from fastapi import Query, Request

from wz_gateway.api.deps import GatewayContext
from wz_gateway.api.errors import InputError

OutputFormat = Literal["json", "csv", "geojson", "parquet"]
#: Largest track id, stamp and station a query may name: beyond any real value, and inside
#: what every database's integers and JSON numbers hold exactly.
MAX_ID = 2**53
_MAX_STAMP_S = 1e11
_MAX_STATION_M = 1e7

Stamp = Annotated[
    float | None,
    Query(ge=0.0, le=_MAX_STAMP_S, allow_inf_nan=False, description="Capture time [s], inclusive"),
]
Limit = Annotated[
    int | None,
    Query(
        ge=1,
        le=100_000,
        description="Items per page (default 1000 points or 100 alerts, at most max_page_size)",
    ),
]
#: A cursor is URL-safe base64 without padding of ``[stamp, row id]`` (at most ~48 bytes).
CURSOR_PATTERN = r"^[A-Za-z0-9_-]+$"
CURSOR_MAX_CHARS = 128
Cursor = Annotated[
    str | None,
    Query(
        min_length=1,
        max_length=CURSOR_MAX_CHARS,
        pattern=CURSOR_PATTERN,
        description="`next_cursor` of the previous page",
    ),
]
_DEGREES = r"-?(?:[0-9]{1,3}(?:\.[0-9]{0,15})?|\.[0-9]{1,15})"
#: ``minLon,minLat,maxLon,maxLat`` [deg]: four plain decimal numbers (no exponent, no inf).
BBOX_PATTERN = rf"^{_DEGREES},{_DEGREES},{_DEGREES},{_DEGREES}$"
BBox = Annotated[
    str | None,
    Query(
        max_length=4 * 20 + 3,
        pattern=BBOX_PATTERN,
        description="minLon,minLat,maxLon,maxLat [deg], e.g. `-84.40,33.74,-84.38,33.76`",
    ),
]
Format = Annotated[OutputFormat, Query(alias="format", description="json, csv, geojson or parquet")]
Speed = Annotated[
    float | None,
    Query(ge=0.0, le=200.0, allow_inf_nan=False, description="Speed bound [m/s], inclusive"),
]
Station = Annotated[
    float | None,
    Query(
        ge=-_MAX_STATION_M,
        le=_MAX_STATION_M,
        allow_inf_nan=False,
        description="Station bound [m], inclusive",
    ),
]


def check_order(low: float | None, high: float | None, low_name: str, high_name: str) -> None:
    """:class:`InputError` if both bounds are given and ``low`` is above ``high``."""
    if low is not None and high is not None and low > high:
        raise InputError(
            f"query.{low_name}", f"{low_name} ({low}) is greater than {high_name} ({high})"
        )


def page_limit(limit: int | None, context: GatewayContext, default: int = 1000) -> int:
    """The page size asked for (``default`` if none), at most ``max_page_size``."""
    if limit is None:
        return min(default, context.settings.max_page_size)
    if limit > context.settings.max_page_size:
        raise InputError("query.limit", f"at most {context.settings.max_page_size} per page")
    return limit


def next_link(request: Request, cursor: str | None) -> dict[str, str]:
    """The headers that point to the next page (none on the last)."""
    if cursor is None:
        return {}
    url = request.url.include_query_params(cursor=cursor)
    return {"Link": f'<{url}>; rel="next"', "X-Next-Cursor": cursor}
