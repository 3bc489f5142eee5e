"""A trailer's fusion tracker, stood in for: speeding cars as track batches, in real time.

Usage: python -m tests.deploy.track_source SITE_FILE STOP_FILE

Publishes ``wz/<site>/tracks`` at 10 Hz (a client of the bus given by ``WZ_BUS_*``): a car
at 65 mph in the 55 mph zone enters at station 450 m every 2 s and is tracked for 3 s, then
leaves; the alert service raises a speeding alert for each and clears it when the track ends,
about one alert a second. Stops when ``STOP_FILE`` exists. The multi-site tests use it so
that two trailers make alerts without two full perception pipelines on a 2-core machine;
the alert service, the routers and the gateways downstream are the real ones.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from wz_shared.bus import Bus
from wz_shared.messages import Track, TrackBatch
from wz_shared.settings import BusSettings
from wz_shared.site import MPH_TO_MPS, load_site

PERIOD_S = 0.1
SPEED_MPS = 65.0 * MPH_TO_MPS
CAR_EVERY_S = 2.0
CAR_LIFE_S = 3.0


def car(track_id: int, age_s: float) -> Track:
    station_m = 450.0 + SPEED_MPS * age_s
    return Track(
        track_id=track_id,
        x_m=1.83,
        y_m=station_m,
        vx_mps=0.0,
        vy_mps=SPEED_MPS,
        covariance=[0.0] * 16,
        station_m=station_m,
        offset_m=-1.83,
        speed_mps=SPEED_MPS,
        heading_rad=1.5707963,
        lane_index=0,
        age_s=age_s + 1.0,
        hits=10,
        confirmed=True,
        sources=["lidar-mast"],
    )


def main() -> None:
    site_file, stop_file = sys.argv[1], Path(sys.argv[2])
    site = load_site(site_file)
    with Bus.open(BusSettings(), site=site.site_id, service="fusion-tracker") as bus:
        tracks = bus.publisher(bus.keys.tracks, TrackBatch)
        start = time.time()
        cycle = 0
        while not stop_file.exists():
            stamp = cycle * PERIOD_S
            first = int(max(0.0, stamp - CAR_LIFE_S) // CAR_EVERY_S)
            cars = [
                car(k, stamp - k * CAR_EVERY_S)
                for k in range(first, int(stamp // CAR_EVERY_S) + 1)
                if 0.0 <= stamp - k * CAR_EVERY_S < CAR_LIFE_S
            ]
            tracks.put(
                TrackBatch(
                    site=site.site_id,
                    source_id="fusion-tracker",
                    stamp=stamp,
                    cycle_index=cycle,
                    tracks=cars,
                )
            )
            cycle += 1
            time.sleep(max(0.0, start + cycle * PERIOD_S - time.time()))


if __name__ == "__main__":
    main()
