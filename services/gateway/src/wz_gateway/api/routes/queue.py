"""``GET /v1/queue``: each lane's queue now (back, head, length, speed in the queue, the back's
growth, whether the back is beyond the sensors' reach), and ``GET /v1/queue/history``: what
was stored, once a second, from the alert service's ``wz/<site>/queue``
(:mod:`wz_alert_service.queues`)."""

from __future__ import annotations

from typing import Annotated, Literal

from fastapi import APIRouter, Query, Request
from fastapi.responses import Response

from wz_gateway.api.deps import SITE_RESPONSES, Ctx, Reader, SiteParam
from wz_gateway.api.errors import V1_RESPONSES
from wz_gateway.api.params import Cursor, Limit, Stamp, check_order, next_link, page_limit
from wz_gateway.models import QueuePage, SiteQueue
from wz_gateway.store_types import QueueQuery
from wz_shared.messages import QueueCondition, QueueState

router = APIRouter(prefix="/v1", responses=V1_RESPONSES)


@router.get("/queue", response_model=SiteQueue, tags=["queue"], responses=SITE_RESPONSES)
def get_queue(context: Ctx, site: SiteParam, _: Reader) -> SiteQueue:
    """Each lane's queue now: the newest state the site's alert service published, when it
    arrived and whether it is older than ``stale_after_s``. A lane's ``back_station_m`` is its
    most upstream queued vehicle; with ``back_beyond_reach`` the queue goes on past the
    sensors' upstream reach (``reach_station_m``) and its back is not measured."""
    row = context.storage.latest(site.site_id, "queue")
    if row is None:
        return SiteQueue(site=site.site_id, queue=None, received_at=None, age_s=None, stale=False)
    age_s = max(0.0, context.clock() - row.received_at)
    return SiteQueue(
        site=site.site_id,
        queue=QueueState.model_validate_json(row.body),
        received_at=row.received_at,
        age_s=age_s,
        stale=age_s > context.settings.stale_after_s,
    )


@router.get("/queue/history", response_model=QueuePage, tags=["queue"], responses=SITE_RESPONSES)
def get_queue_history(
    request: Request,
    response: Response,
    context: Ctx,
    site: SiteParam,
    _: Reader,
    start: Stamp = None,
    end: Stamp = None,
    condition: Annotated[
        list[QueueCondition] | None,
        Query(description="Only states whose worst lane is in this condition; repeat for several"),
    ] = None,
    order: Annotated[Literal["newest", "oldest"], Query()] = "newest",
    limit: Limit = None,
    cursor: Cursor = None,
) -> QueuePage:
    """Stored queue states (one a second of track stamps, and one at each change of a lane's
    condition), newest first unless ``order=oldest``."""
    check_order(start, end, "start", "end")
    page = context.storage.queue_history(
        QueueQuery(
            site=site.site_id,
            start_stamp=start,
            end_stamp=end,
            conditions=tuple(c.value for c in condition or ()),
            newest_first=order == "newest",
            limit=page_limit(limit, context, default=100),
            cursor=cursor,
        )
    )
    for name, value in next_link(request, page.next_cursor).items():
        response.headers[name] = value
    return QueuePage(
        site=site.site_id, count=len(page.items), next_cursor=page.next_cursor, states=page.items
    )
