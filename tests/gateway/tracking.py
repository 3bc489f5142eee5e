"""A car on the test site's straight road and a Kalman filter's estimates of it, for the
smoothing tests: what the fusion tracker would publish, with real covariances."""

from __future__ import annotations

import numpy as np

from tests.gateway.helpers import SITE
from tests.shared.filtered import FilteredCar as FilteredCar
from tests.shared.filtered import filtered_car as filtered_car
from wz_shared.arrays import F64
from wz_shared.messages import Track, TrackBatch
from wz_shared.motion import ProcessNoise


def car_tracks(track_id: int, car: FilteredCar) -> list[Track]:
    """The filtered states as the tracker's Track messages (road frame and lane included)."""
    station, offset = SITE.road_frame.to_road(car.x_filt[:, 0], car.x_filt[:, 1])
    lanes = SITE.lane_index_at(offset)
    return [
        Track(
            track_id=track_id,
            x_m=float(x[0]),
            y_m=float(x[1]),
            vx_mps=float(x[2]),
            vy_mps=float(x[3]),
            covariance=[float(v) for v in ((P + P.T) / 2).reshape(-1)],
            station_m=float(s),
            offset_m=float(d),
            speed_mps=float(np.hypot(x[2], x[3])),
            heading_rad=float(np.arctan2(x[3], x[2])),
            lane_index=max(int(lane), -1),
            age_s=0.05 * k,
            hits=k + 1,
            confirmed=True,
            sources=["lidar-mast"],
            length_m=4.5 if k > 10 else None,
            width_m=1.8 if k > 10 else None,
        )
        for k, (x, P, s, d, lane) in enumerate(
            zip(car.x_filt, car.P_filt, station, offset, lanes, strict=True)
        )
    ]


def merged_batches(
    *cars: tuple[F64, list[Track]], first_cycle: int = 0, process_noise: ProcessNoise | None = None
) -> list[TrackBatch]:
    """One batch per distinct stamp, holding the track of every car seen at that stamp (and
    ``process_noise``, else the model's defaults)."""
    by_stamp: dict[float, list[Track]] = {}
    for stamps, tracks in cars:
        for stamp, track in zip(stamps, tracks, strict=True):
            by_stamp.setdefault(round(float(stamp), 9), []).append(track)
    return [
        TrackBatch(
            site=SITE.site_id,
            source_id="fusion-tracker",
            stamp=stamp,
            cycle_index=first_cycle + k,
            tracks=tracks,
            process_noise=process_noise or ProcessNoise(),
        )
        for k, (stamp, tracks) in enumerate(sorted(by_stamp.items()))
    ]
