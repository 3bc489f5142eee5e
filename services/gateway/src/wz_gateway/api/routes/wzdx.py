"""``GET /v1/wzdx/device-feed``: the WZDx 4.2 DeviceFeed of one site or of every site
(:mod:`wz_gateway.views` reads the devices' state, :mod:`wz_gateway.wzdx` writes the feed);
``GET /v1/wzdx/work-zone-feed``: the WorkZoneFeed, the work zone of each site as a road event
(:mod:`wz_gateway.wzdx_workzone`)."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query
from fastapi.responses import JSONResponse

from wz_gateway import views, wzdx_workzone
from wz_gateway.api.deps import SITE_PATTERN, SITE_RESPONSES, Ctx, Reader, site_of
from wz_gateway.api.errors import V1_RESPONSES
from wz_gateway.wzdx import CalibrationRules

router = APIRouter(prefix="/v1", responses=V1_RESPONSES)


@router.get(
    "/wzdx/device-feed",
    tags=["wzdx"],
    responses={
        200: {
            "description": "A WZDx 4.2 DeviceFeed (GeoJSON)",
            "content": {
                "application/json": {
                    "schema": {"type": "object", "required": ["feed_info", "type", "features"]}
                }
            },
        },
        **SITE_RESPONSES,
    },
)
def get_device_feed(
    context: Ctx,
    _: Reader,
    site: Annotated[
        str | None,
        Query(pattern=SITE_PATTERN, description="Only this site's devices (default: every site's)"),
    ] = None,
) -> JSONResponse:
    """The WZDx 4.2 DeviceFeed: traffic sensor (per-lane volumes, speeds, occupancy over the
    newest collection interval), cameras, flashing beacon and message sign, with status (a
    knocked sensor, or one that has not learned its pose for long, is ``warning``)."""
    settings = context.settings
    rules = CalibrationRules(
        stale_after_s=settings.calibration_stale_after_s,
        learning_warning_s=settings.calibration_learning_warning_s,
    )
    served = [site_of(context, site)] if site is not None else list(context.sites)
    feeds = [
        views.device_feed_of(
            context.storage,
            one,
            now=context.clock(),
            publisher=settings.publisher,
            stale_after_s=settings.stale_after_s,
            traffic_interval_s=settings.traffic_interval_s,
            detector_station_override_m=settings.traffic_detector_station_m,
            contact_email=settings.contact_email,
            calibration_rules=rules,
        )
        for one in served
    ]
    return JSONResponse(views.merge_device_feeds(feeds))


@router.get(
    "/wzdx/work-zone-feed",
    tags=["wzdx"],
    responses={
        200: {
            "description": "A WZDx 4.2 WorkZoneFeed (GeoJSON): one work-zone road event a site",
            "content": {
                "application/json": {
                    "schema": {"type": "object", "required": ["feed_info", "type", "features"]}
                }
            },
        },
        **SITE_RESPONSES,
    },
)
def get_work_zone_feed(
    context: Ctx,
    _: Reader,
    site: Annotated[
        str | None,
        Query(
            pattern=SITE_PATTERN, description="Only this site's work zone (default: every site's)"
        ),
    ] = None,
) -> JSONResponse:
    """The WZDx 4.2 WorkZoneFeed: each site's work zone (extent from the taper to the end of
    the termination area, lanes with the closed one, the reduced speed limit, the dates of its
    ``schedule``), from its site file; its devices are in the DeviceFeed."""
    settings = context.settings
    served = [site_of(context, site)] if site is not None else list(context.sites)
    feeds = [
        wzdx_workzone.work_zone_feed(
            one,
            now=context.clock(),
            served_since=context.started_at,
            publisher=settings.publisher,
            contact_email=settings.contact_email,
        )
        for one in served
    ]
    merged = feeds[0]
    for extra in feeds[1:]:
        merged["features"] += extra["features"]
        merged["feed_info"]["data_sources"] += extra["feed_info"]["data_sources"]
    return JSONResponse(merged)
