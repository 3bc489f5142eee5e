"""``GET /v1/calibration``: each sensor's self-calibration (its learned pose correction and
clock offset, its state, its latest changes of state), from what its detector published on
``wz/<site>/calibration/<sensor>`` (:mod:`wz_gateway.views` assembles it)."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query

from wz_gateway import views
from wz_gateway.api.deps import SITE_RESPONSES, Ctx, Reader, SiteParam
from wz_gateway.api.errors import V1_RESPONSES
from wz_gateway.models import SiteCalibration

#: Most changes of state shown per sensor.
MAX_CHANGES = 100

router = APIRouter(prefix="/v1", responses=V1_RESPONSES)


@router.get("/calibration", response_model=SiteCalibration, tags=["site"], responses=SITE_RESPONSES)
def get_calibration(
    context: Ctx,
    site: SiteParam,
    _: Reader,
    changes: Annotated[
        int,
        Query(
            ge=0,
            le=MAX_CHANGES,
            description="How many of each sensor's latest changes of state to list (newest "
            "first): when it was knocked (`bumped`), when it was learned again",
        ),
    ] = 10,
) -> SiteCalibration:
    """Each sensor's self-calibration: the newest message its detector published (pose
    correction with standard deviations, clock offset, state and since when, samples, why),
    when it arrived and whether that is longer ago than ``calibration_stale_after_s``, and
    its latest changes of state. Every sensor of the site file is listed, one never heard
    from without a message."""
    return views.site_calibration(
        context.storage,
        site,
        now=context.clock(),
        stale_after_s=context.settings.calibration_stale_after_s,
        changes=changes,
    )
