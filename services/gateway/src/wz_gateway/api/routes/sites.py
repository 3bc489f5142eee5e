"""``GET /v1/sites`` (the sites served) and ``GET /v1/site`` (one site's description)."""

from __future__ import annotations

from fastapi import APIRouter

from wz_gateway.api.deps import SITE_RESPONSES, Ctx, Reader, SiteParam
from wz_gateway.api.errors import V1_RESPONSES
from wz_gateway.models import SiteSummary
from wz_shared.site import Site

router = APIRouter(prefix="/v1", responses=V1_RESPONSES)


@router.get("/sites", response_model=list[SiteSummary], tags=["site"])
def get_sites(context: Ctx, _: Reader) -> list[SiteSummary]:
    """The sites this gateway serves; the first is the default ``site`` of every route."""
    return [
        SiteSummary(site_id=site.site_id, name=site.name, default=index == 0)
        for index, site in enumerate(context.sites)
    ]


@router.get("/site", response_model=Site, tags=["site"], responses=SITE_RESPONSES)
def get_site(site: SiteParam, _: Reader) -> Site:
    """The site: road geometry, lanes, work-zone areas, limits, sensors, alert thresholds."""
    return site
