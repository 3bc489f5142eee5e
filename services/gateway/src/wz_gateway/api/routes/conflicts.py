"""``GET /v1/conflicts``: traffic conflicts between the stored trajectories of a time window,
with SSAM's surrogate safety measures (:mod:`wz_gateway.conflicts`), as JSON or as SSAM's
conflict table (CSV)."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, Query, Request
from fastapi.responses import JSONResponse, Response

from wz_gateway.api.deps import SITE_RESPONSES, Ctx, Reader, SiteParam
from wz_gateway.api.errors import V1_RESPONSES, InputError
from wz_gateway.api.params import Cursor, Limit, check_order, next_link, page_limit
from wz_gateway.conflicts import ConflictSettings, find_conflicts, ssam_csv
from wz_gateway.models import ConflictPage
from wz_gateway.store_types import CursorError, decode_cursor, encode_cursor

#: The longest window one request may analyse [s]: an hour of a busy site is ~10^6 points.
MAX_WINDOW_S = 3600.0
_MAX_STAMP_S = 1e11

WindowStamp = Annotated[
    float,
    Query(
        ge=0.0,
        le=_MAX_STAMP_S,
        allow_inf_nan=False,
        description=f"Capture time [s], inclusive; the window is at most {MAX_WINDOW_S:g} s",
    ),
]

router = APIRouter(prefix="/v1", responses=V1_RESPONSES)


@router.get(
    "/conflicts",
    response_model=ConflictPage,
    tags=["tracks"],
    responses={
        **SITE_RESPONSES,
        200: {
            "content": {"text/csv": {"schema": {"type": "string"}}},
            "description": "JSON by default; SSAM's conflict table (its 44 columns, in its "
            "order) with `format=csv`",
        },
    },
)
def get_conflicts(
    request: Request,
    context: Ctx,
    site: SiteParam,
    _: Reader,
    start: WindowStamp,
    end: WindowStamp,
    max_ttc: Annotated[
        float,
        Query(gt=0.0, le=10.0, allow_inf_nan=False, description="TTC threshold [s] (SSAM: 1.5)"),
    ] = 1.5,
    max_pet: Annotated[
        float,
        Query(gt=0.0, le=30.0, allow_inf_nan=False, description="PET threshold [s] (SSAM: 5)"),
    ] = 5.0,
    smoothed: Annotated[
        bool, Query(description="Smoothed trajectories (true) or fused ones (false)")
    ] = False,
    limit: Limit = None,
    cursor: Cursor = None,
    output: Annotated[
        Literal["json", "csv"], Query(alias="format", description="json or csv (SSAM's table)")
    ] = "json",
) -> Response:
    """Conflicts (TTC, PET, DRAC, SSAM's MaxS, DeltaS, DR, MaxD, MaxDeltaV, angle and type)
    between the stored tracks of a window, ordered by the time of their minimum TTC."""
    check_order(start, end, "start", "end")
    if end - start > MAX_WINDOW_S:
        raise InputError(
            "query.end",
            f"the window is {end - start:g} s; ask for at most {MAX_WINDOW_S:g} s at a time",
        )
    settings = ConflictSettings(max_ttc_s=max_ttc, max_pet_s=max_pet)
    found = find_conflicts(
        context.storage.trajectories(site.site_id, start, end, smoothed=smoothed), settings
    )
    first = 0
    if cursor is not None:
        stamp, first = decode_cursor(cursor)
        if not 0 < first <= len(found) or found[first - 1].min_ttc_stamp != stamp:
            raise CursorError("not a cursor of this window; use the next_cursor of a page")
    size = page_limit(limit, context, default=500)
    page = found[first : first + size]
    more = first + size < len(found)
    next_cursor = encode_cursor(page[-1].min_ttc_stamp, first + len(page)) if more else None
    headers = next_link(request, next_cursor)
    if output == "csv":
        headers["Content-Disposition"] = 'attachment; filename="conflicts.csv"'
        trj_file = f"{site.site_id} {start:g}-{end:g} s{' smoothed' if smoothed else ''}"
        return Response(ssam_csv(page, trj_file), media_type="text/csv", headers=headers)
    body: dict[str, Any] = ConflictPage(
        site=site.site_id,
        start=start,
        end=end,
        max_ttc_s=max_ttc,
        max_pet_s=max_pet,
        count=len(page),
        next_cursor=next_cursor,
        conflicts=page,
    ).model_dump(mode="json")
    return JSONResponse(body, headers=headers)
