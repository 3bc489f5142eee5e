"""The closure's capacity (HCM 2010 Eq. 10-14) from the site's lanes and the truck share."""

from __future__ import annotations

import pytest

from wz_shared.capacity import closure_capacity_vph, heavy_vehicle_factor
from wz_shared.site_generator import generate_site


def test_the_capacity_is_hcm_s_work_zone_lanes_with_the_trucks_as_cars() -> None:
    assert heavy_vehicle_factor(0.0) == 1.0
    assert heavy_vehicle_factor(0.2) == pytest.approx(1.0 / 1.1)
    sites = {len(site.lanes): site for site in (generate_site(seed) for seed in range(12))}
    # Two lanes dropping to one, and three to two.
    assert closure_capacity_vph(sites[2], 0.15) == pytest.approx(1600.0 / 1.075)
    assert closure_capacity_vph(sites[3], 0.3) == pytest.approx(2 * 1600.0 / 1.15)


def test_a_bad_truck_share_is_refused() -> None:
    with pytest.raises(ValueError, match="truck_share"):
        heavy_vehicle_factor(1.5)
    with pytest.raises(ValueError, match="at least one passenger car"):
        heavy_vehicle_factor(0.2, truck_pce=0.5)
