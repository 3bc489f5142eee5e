"""The paper's Tables 1-2 on the evaluation's samples (wz_eval.fusion.paper_table): every
source is compared at the camera's frame times, the LiDAR at its nearest sample within half
its period, so a camera clock offset learned by the self-calibration does not empty the table."""

from __future__ import annotations

import pytest

from wz_eval.fusion import paper_table
from wz_eval.scores import Scores
from wz_shared.site import DEFAULT_SITE_PATH, load_site

SITE = load_site(DEFAULT_SITE_PATH)
MAST = (7.5, 980.0)  # the default site's mast: station 980 m
CAMERA_SOURCES = ("camera", "average", "paper_kf", "fused", "fused_smoothed", "fused_stored")


def _scores(camera_offset_s: float, lidar_error_m: float = 0.3, lidar_step: int = 1) -> Scores:
    """One vehicle 60 m upstream of the mast for 1 s: LiDAR samples on its 20 Hz grid (every
    ``lidar_step``-th frame: some lost), the camera's sources at 10 Hz, ``camera_offset_s``
    later."""
    scores = Scores()
    by_source = scores.per_vehicle["v1"]
    for k in range(0, 20, lidar_step):
        t = round(100.0 + 0.05 * k, 4)
        by_source["lidar"][t] = (lidar_error_m, 0.1, 920.0, -1.83)
    for k in range(10):
        t = round(100.0 + 0.1 * k + camera_offset_s, 4)
        for source in CAMERA_SOURCES:
            error = 0.1 if source.startswith("fused") else 0.5
            by_source[source][t] = (error, error, 920.0, -1.83)
    return scores


@pytest.mark.parametrize("offset_s", [0.0, 0.0043, -0.02])
def test_a_camera_clock_offset_keeps_every_frame(offset_s: float) -> None:
    (row,) = paper_table(SITE, _scores(offset_s), MAST, (40.0, 100.0))
    assert row["samples"] == 10
    assert row["lidar"]["longitudinal_m"] == pytest.approx(3.0)  # 10 of its 0.3 m
    assert row["fused"]["lateral_m"] == pytest.approx(1.0)


def test_a_lidar_sample_beyond_half_its_period_does_not_count() -> None:
    """Every other LiDAR frame lost: a camera frame 30 ms after one is 70 ms before the next,
    both beyond the 25 ms of half the LiDAR's period."""
    assert paper_table(SITE, _scores(0.03, lidar_step=2), MAST, (40.0, 100.0)) == []
    assert len(paper_table(SITE, _scores(0.02, lidar_step=2), MAST, (40.0, 100.0))) == 1


def test_only_samples_inside_the_window_count() -> None:
    scores = _scores(0.0)
    for source in scores.per_vehicle["v1"].values():
        for t, (lon, lat, _, offset) in list(source.items()):
            source[t] = (lon, lat, 860.0, offset)  # 120 m upstream: outside [880, 940] m
    assert paper_table(SITE, scores, MAST, (40.0, 100.0)) == []
