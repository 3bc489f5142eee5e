"""When a track ends (just under and just over the timeout, a new run, silence), and its
smoothed trajectory: written once in the same table, taken up again after a restart, deleted
by the retention with the fused points, served over HTTP."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from sqlalchemy import create_engine, insert

from tests.gateway.helpers import (
    READ_KEY,
    SITE,
    batch,
    gateway_settings,
    live_server,
    make_track,
    open_storage,
)
from tests.gateway.tracking import car_tracks, filtered_car, merged_batches
from wz_gateway.metrics import GatewayMetrics
from wz_gateway.node import Writer
from wz_gateway.settings import GatewaySettings
from wz_gateway.storage import Storage
from wz_gateway.store_types import PointQuery
from wz_gateway.tables import MIGRATIONS, schema_version, track_points
from wz_gateway.track_ends import TrackEnds, TrackFinisher
from wz_shared.messages import Message, TrackBatch
from wz_shared.motion import ProcessNoise, rts_smooth

T0 = 1_750_000_000.0
READ = {"X-API-Key": READ_KEY}


# --- the decision alone -----------------------------------------------------------------------


def ended_ids(
    ends: TrackEnds, stamp: float, track_ids: Iterable[int], received_at: float = T0
) -> list[int]:
    change = ends.observe(
        batch(stamp, [make_track(i, 900.0, 20.0) for i in track_ids]), received_at
    )
    return sorted(life.track_id for life in change.ended)


def test_a_track_ends_only_when_missing_for_longer_than_the_timeout() -> None:
    ends = TrackEnds(end_after_s=3.0, silence_s=30.0, restart_tolerance_s=1.0)
    assert ended_ids(ends, 10.0, [1, 2]) == []
    assert ended_ids(ends, 12.95, [2]) == []  # 2.95 s missing: just under
    assert ended_ids(ends, 13.0, [2]) == []  # exactly the timeout: not longer than it
    assert ended_ids(ends, 13.05, [2]) == [1]  # 3.05 s: just over
    assert sorted(ends.open) == [2]


def test_a_track_back_after_the_timeout_starts_a_new_life() -> None:
    ends = TrackEnds(end_after_s=3.0, silence_s=30.0, restart_tolerance_s=1.0)
    ends.observe(batch(10.0, [make_track(1, 900.0, 20.0)]), T0)
    change = ends.observe(batch(13.5, [make_track(1, 970.0, 20.0)]), T0 + 3.5)
    assert [life.last_stamp for life in change.ended] == [10.0]
    assert [(life.track_id, life.first_stamp) for life in change.started] == [(1, 13.5)]


def test_stamps_going_back_beyond_the_tolerance_end_the_run() -> None:
    ends = TrackEnds(end_after_s=3.0, silence_s=30.0, restart_tolerance_s=1.0)
    assert ended_ids(ends, 50.0, [1, 2]) == []
    assert ended_ids(ends, 49.5, [1, 2]) == []  # 0.5 s back: jitter, the same run
    assert ended_ids(ends, 0.0, [1]) == [1, 2]  # a new run: every track of the old one
    assert [life.first_stamp for life in ends.open.values()] == [0.0]


def test_silence_ends_every_track_after_its_time() -> None:
    ends = TrackEnds(end_after_s=3.0, silence_s=30.0, restart_tolerance_s=1.0)
    ended_ids(ends, 10.0, [1, 2], received_at=T0)
    assert ends.silence(T0 + 29.9) == []
    assert sorted(life.track_id for life in ends.silence(T0 + 30.1)) == [1, 2]
    assert ends.open == {}


# --- with the storage ---------------------------------------------------------------------------


@dataclass
class Gateway:
    """A writer with its finisher on a database, fed one message at a time as the node's loop
    does (store, then smooth within the budget), on a clock the test moves."""

    settings: GatewaySettings
    storage: Storage
    metrics: GatewayMetrics
    writer: Writer
    now: list[float]

    def feed(
        self, messages: Iterable[Message], *, period_s: float = 0.05, smooth: bool = True
    ) -> None:
        assert self.writer.finisher is not None
        for message in messages:
            self.now[0] += period_s
            assert self.writer.write([message])
            if smooth:
                self.writer.finisher.work(budget_s=10.0)

    def points(self, track_id: int, smoothed: bool) -> list[tuple[float, float, float]]:
        page = self.storage.points(
            PointQuery(site=SITE.site_id, track_id=track_id, smoothed=smoothed, limit=100_000)
        )
        return [(p.stamp, p.x_m, p.y_m) for p in page.items]


def start_gateway(settings: GatewaySettings, storage: Storage, now: list[float]) -> Gateway:
    metrics = GatewayMetrics()

    def clock() -> float:
        return now[0]

    writer = Writer(
        storage,
        SITE,
        settings,
        metrics,
        report=lambda *_: None,
        clock=clock,
        finisher=TrackFinisher.of(storage, SITE, settings, metrics, clock=clock),
    )
    assert writer.finisher is not None
    writer.finisher.resume()
    writer.finisher.work(budget_s=10.0)
    return Gateway(settings, storage, metrics, writer, now)


@pytest.fixture
def gateway(tmp_path: Path) -> Iterator[Gateway]:
    settings = gateway_settings(tmp_path)
    storage = open_storage(settings)
    yield start_gateway(settings, storage, [T0])
    storage.close()


def tracks_rows(storage: Storage) -> list[tuple[int, float | None, int | None]]:
    with storage.engine.connect() as connection:
        rows = connection.exec_driver_sql(
            "SELECT track_id, ended_at, smoothed_points FROM tracks ORDER BY id"
        ).all()
    return [(row[0], row[1], row[2]) for row in rows]


def two_cars(seed: int = 11) -> tuple[list[TrackBatch], int]:
    """Car 7 for 5 s (100 batches at 20 Hz), car 8 from 0 to 9 s: car 7's last batch is at
    4.95 s; the batches from 7.95 s on come with car 7 missing for just under, then over 3 s."""
    car7 = filtered_car(seed=seed, count=100, station0_m=800.0)
    car8 = filtered_car(seed=seed + 1, count=180, station0_m=700.0, offset_m=1.83)
    batches = merged_batches(
        (car7.stamps_s, car_tracks(7, car7)), (car8.stamps_s, car_tracks(8, car8))
    )
    return batches, 100


def test_a_track_is_smoothed_only_once_it_is_missing_longer_than_the_timeout(
    gateway: Gateway,
) -> None:
    batches, n7 = two_cars()
    just_under = next(k for k, b in enumerate(batches) if b.stamp > 4.95 + 2.96)  # 7.95 s
    gateway.feed(batches[: just_under + 1])  # up to 3.0 s missing
    assert gateway.points(7, smoothed=True) == []
    gateway.feed(batches[just_under + 1 : just_under + 2])  # 3.05 s missing
    smoothed, fused = gateway.points(7, smoothed=True), gateway.points(7, smoothed=False)
    assert len(smoothed) == len(fused) == n7
    assert [p[0] for p in smoothed] == [p[0] for p in fused]  # same stamps
    assert gateway.points(8, smoothed=True) == []  # still going
    assert tracks_rows(gateway.storage)[0][0] == 7 and tracks_rows(gateway.storage)[0][2] == n7


#: A tracker's process noise other than the model's defaults, carried by its track batches.
NOISE = ProcessNoise(1.5, 0.8, 1.0)


def test_the_stored_smoothed_points_are_the_rts_smoothed_fused_ones(gateway: Gateway) -> None:
    # the tracker's motion model, which its batches carry
    car = filtered_car(
        seed=21,
        count=160,
        sigma_a_mps2=NOISE.sigma_along_mps2,
        sigma_across_mps2=NOISE.sigma_across_mps2,
    )
    batches = merged_batches((car.stamps_s, car_tracks(3, car)), process_noise=NOISE)
    later = [batch(11.0 + 0.05 * k, [make_track(4, 900.0, 20.0)], 200 + k) for k in range(5)]
    gateway.feed([*batches, *later])
    stored = gateway.storage.points(
        PointQuery(site=SITE.site_id, track_id=3, smoothed=True, limit=1000)
    ).items
    x_s, _ = rts_smooth(car.stamps_s, car.x_filt, car.P_filt, NOISE)
    got = np.array([[p.x_m, p.y_m, p.vx_mps, p.vy_mps] for p in stored])
    # the covariances went through JSON and back: equal to the last bits
    np.testing.assert_allclose(got, x_s, rtol=0.0, atol=1e-9)
    # not what the model's defaults give
    x_default, _ = rts_smooth(car.stamps_s, car.x_filt, car.P_filt, ProcessNoise())
    assert np.max(np.abs(x_default - got)) > 1e-3
    assert all(p.smoothed and p.object_class.value == "unknown" for p in stored)
    assert {p.length_m for p in stored} == {4.5}  # the last estimate, for every point
    truth_error = {
        name: float(np.sqrt(np.mean(np.sum((xs[20:, :2] - car.truth[20:, :2]) ** 2, axis=1))))
        for name, xs in (("fused", car.x_filt), ("smoothed", got))
    }
    assert truth_error["smoothed"] < truth_error["fused"]
    assert gateway.metrics.smoothed_tracks._value.get() == 1.0
    assert gateway.metrics.smoothed_points._value.get() == len(stored)


def test_a_new_run_ends_the_old_tracks_and_smooths_only_their_points(gateway: Gateway) -> None:
    """The simulation starts again from stamp 0 and the tracker's ids from 1: the old life of
    track 1 is smoothed from its own points, never from the new run's under the same id."""
    old = [batch(0.05 * k, [make_track(1, 900.0 + k, 20.0)], k) for k in range(60)]
    new = [batch(0.05 * k, [make_track(1, 300.0 + k, 20.0)], k) for k in range(30)]
    gateway.feed([*old, *new])
    smoothed = gateway.points(1, smoothed=True)
    assert len(smoothed) == 60 and min(y for _, _, y in smoothed) == pytest.approx(900.0)
    assert [(row[0], row[2]) for row in tracks_rows(gateway.storage)] == [(1, 60), (1, None)]


def test_silence_ends_the_tracks_when_the_tracker_stops(gateway: Gateway) -> None:
    gateway.feed(batch(0.05 * k, [make_track(2, 900.0 + k, 20.0)], k) for k in range(40))
    assert gateway.writer.finisher is not None
    gateway.now[0] += 29.0
    assert gateway.writer.finisher.work() == 0
    gateway.now[0] += 2.0  # 31 s without a batch
    assert gateway.writer.finisher.work() == 1
    assert len(gateway.points(2, smoothed=True)) == 40


def test_a_restart_takes_up_unfinished_tracks_and_smooths_nothing_twice(tmp_path: Path) -> None:
    """Process 1: car 7 ends and is smoothed; car 9 ends but the process stops before it is
    smoothed; car 8 is still going. Process 2, started 5 s later (within the silence):
    smooths car 9 at start and follows car 8 on until it ends: one life, with the points of
    both processes; car 7 is not smoothed again."""
    settings = gateway_settings(tmp_path)
    storage = open_storage(settings)
    batches, n7 = two_cars(seed=31)  # stamps 0 to 8.95 s
    for k in range(120, 141):  # car 9 from 6.0 to 7.0 s
        batches[k] = batches[k].model_copy(
            update={"tracks": [*batches[k].tracks, make_track(9, 600.0 + k, 20.0)]}
        )
    first = start_gateway(settings, storage, [T0])
    first.feed(batches)
    assert len(first.points(7, smoothed=True)) == n7
    # The batch at 10.05 s ends car 9 (3.05 s missing): stored, then the process stops.
    car8 = batches[-1].tracks[-1]
    first.feed([batch(10.05, [car8], 500)], smooth=False)
    assert first.writer.finisher is not None
    assert [life.track_id for life in first.writer.finisher.pending] == [9]
    assert first.points(9, smoothed=True) == []

    second = start_gateway(settings, storage, [first.now[0] + 5.0])
    assert second.writer.finisher is not None
    assert sorted(second.writer.finisher.ends.open) == [8]
    assert len(second.points(9, smoothed=True)) == 21
    second.feed(batch(10.05 + 0.05 * k, [car8], 500 + k) for k in range(1, 40))  # to 12 s
    second.feed(
        batch(12.0 + 0.05 * k, [make_track(10, 500.0, 20.0)], 600 + k) for k in range(1, 62)
    )
    fused8 = second.points(8, smoothed=False)
    assert len(fused8) == 180 + 1 + 39
    assert [p[0] for p in second.points(8, smoothed=True)] == [p[0] for p in fused8]
    assert len(second.points(7, smoothed=True)) == n7  # not twice
    ended = sorted((track_id, n) for track_id, at, n in tracks_rows(storage) if at is not None)
    assert ended == [(7, n7), (8, len(fused8)), (9, 21)]
    storage.close()


@pytest.mark.parametrize("recorded", [True, False])
def test_a_life_taken_up_after_a_restart_is_smoothed_with_its_recorded_process_noise(
    tmp_path: Path,
    recorded: bool,
) -> None:
    """Car 3's batches carry ``NOISE``; the process stops while it goes on, and the next one
    ends it with batches of the model's defaults: smoothed with ``NOISE``, recorded with its
    life, or with the defaults where the row has none (a life recorded before migration 5)."""
    settings = gateway_settings(tmp_path)
    storage = open_storage(settings)
    car = filtered_car(
        seed=23,
        count=80,
        sigma_a_mps2=NOISE.sigma_along_mps2,
        sigma_across_mps2=NOISE.sigma_across_mps2,
    )
    first = start_gateway(settings, storage, [T0])
    first.feed(merged_batches((car.stamps_s, car_tracks(3, car)), process_noise=NOISE))
    if not recorded:
        with storage.engine.begin() as connection:
            connection.exec_driver_sql(
                "UPDATE tracks SET sigma_along_mps2 = NULL, "
                "sigma_across_mps2 = NULL, heading_min_speed_mps = NULL"
            )
    second = start_gateway(settings, storage, [first.now[0] + 1.0])
    assert second.writer.finisher is not None and sorted(second.writer.finisher.ends.open) == [3]
    second.feed(batch(7.5 + 0.05 * k, [make_track(4, 900.0, 20.0)], 100 + k) for k in range(5))
    got = np.array(
        [
            [p.x_m, p.y_m, p.vx_mps, p.vy_mps]
            for p in second.storage.points(
                PointQuery(site=SITE.site_id, track_id=3, smoothed=True, limit=1000)
            ).items
        ]
    )
    x_s, _ = rts_smooth(car.stamps_s, car.x_filt, car.P_filt, NOISE if recorded else ProcessNoise())
    np.testing.assert_allclose(got, x_s, rtol=0.0, atol=1e-9)
    storage.close()


def test_a_life_is_finished_once_however_often_it_is_asked(gateway: Gateway) -> None:
    gateway.feed(batch(0.05 * k, [make_track(2, 900.0 + k, 20.0)], k) for k in range(10))
    finisher = gateway.writer.finisher
    assert finisher is not None
    life = finisher.ends.open[2]
    assert finisher.finish(life) == 10
    assert finisher.finish(life) == 0  # already ended: nothing written
    assert len(gateway.points(2, smoothed=True)) == 10


def test_retention_deletes_the_smoothed_points_with_the_fused_ones(gateway: Gateway) -> None:
    gateway.feed(batch(0.05 * k, [make_track(2, 900.0 + k, 20.0)], k) for k in range(40))
    gateway.now[0] += 60.0  # track 3 a minute later; track 2 ends with its first batch
    gateway.feed(batch(6.0 + 0.05 * k, [make_track(3, 900.0, 20.0)], 40 + k) for k in range(5))
    assert len(gateway.points(2, smoothed=True)) == 40 and len(gateway.points(3, False)) == 5
    # Track 2's points (fused and smoothed) arrived over a minute before track 3's.
    cutoff = T0 + 30.0
    days = gateway.settings.retention_days
    deleted = gateway.storage.purge(
        cutoff + days * 86400.0, retention_days=days, alert_retention_days=365.0
    )
    assert deleted["track_points"] == 80 and deleted["tracks"] == 1
    assert gateway.points(2, smoothed=True) == [] and gateway.points(2, smoothed=False) == []
    assert len(gateway.points(3, smoothed=False)) == 5
    assert [row[0] for row in tracks_rows(gateway.storage)] == [3]  # open: kept


def test_smoothed_trajectory_over_http(gateway: Gateway) -> None:
    batches, n7 = two_cars(seed=41)
    gateway.feed(batches)
    with (
        live_server(gateway.settings, gateway.storage) as base,
        httpx.Client(base_url=base, headers=READ, timeout=10.0) as http,
    ):

        def points(path: str, **params: str | int) -> list[dict[str, Any]]:
            response = http.get(path, params=params)
            assert response.status_code == 200, response.text
            found: list[dict[str, Any]] = response.json()["points"]
            return found

        smoothed = points("/v1/tracks/7", smoothed="true")
        fused = points("/v1/tracks/7", smoothed="false")
        # without the flag: the fused trajectory only (one point per stamp)
        assert len(smoothed) == len(fused) == n7 and points("/v1/tracks/7") == fused
        assert all(p["smoothed"] is True for p in smoothed)
        assert all(p["smoothed"] is False for p in fused)
        assert [p["stamp"] for p in smoothed] == [p["stamp"] for p in fused]
        assert sum(s["x_m"] != f["x_m"] for s, f in zip(smoothed, fused, strict=True)) > n7 // 2
        page = http.get("/v1/trajectories", params={"smoothed": "true", "limit": 30}).json()
        assert page["count"] == 30 and page["next_cursor"] is not None
        assert {p["track_id"] for p in page["points"]} == {7}  # car 8 has not ended
        assert http.get("/v1/tracks/8", params={"smoothed": "true"}).status_code == 404


def test_an_older_database_gets_the_covariances_and_the_track_lives(tmp_path: Path) -> None:
    """A file at the schema before migration 3: its points stay, without a covariance; new
    ones carry theirs, and track lives are recorded from then on (a track going on through the
    upgrade is smoothed from its new points)."""
    settings = gateway_settings(tmp_path)
    url = settings.resolved_database_url()
    Path(url.removeprefix("sqlite:///")).parent.mkdir(parents=True)
    engine = create_engine(url)
    with engine.begin() as connection:
        schema_version.create(connection)
        for migration in MIGRATIONS[:2]:
            migration.apply(connection)
            connection.execute(
                insert(schema_version).values(
                    version=migration.version, description=migration.description, applied_at=T0
                )
            )
        old = [c for c in track_points.c if c.name not in ("id", "covariance")]
        connection.execute(
            insert(track_points).values(
                {c.name: 0.0 for c in old}
                | {
                    "site": SITE.site_id,
                    "track_id": 5,
                    "stamp": 1.0,
                    "lane_index": 0,
                    "object_class": "car",
                    "status": "confirmed",
                    "smoothed": False,
                }
            )
        )
    engine.dispose()
    storage = open_storage(settings)
    try:
        assert storage.current_schema_version() >= 3
        gateway = start_gateway(settings, storage, [T0])
        gateway.feed(batch(1.05 + 0.05 * k, [make_track(5, 900.0, 20.0)], k) for k in range(20))
        gateway.feed(batch(5.0 + 0.05 * k, [make_track(6, 900.0, 20.0)], 20 + k) for k in range(2))
        assert len(gateway.points(5, smoothed=False)) == 21
        assert len(gateway.points(5, smoothed=True)) == 20  # the new points only
    finally:
        storage.close()


def test_a_life_the_database_refuses_is_tried_again_then_left_to_the_next_start(
    gateway: Gateway,
    caplog: pytest.LogCaptureFixture,
) -> None:
    gateway.feed(batch(0.05 * k, [make_track(2, 900.0 + k, 20.0)], k) for k in range(10))
    finisher = gateway.writer.finisher
    assert finisher is not None
    with gateway.storage.engine.begin() as connection:  # the table gone: every attempt fails
        connection.exec_driver_sql("ALTER TABLE tracks RENAME TO tracks_away")
    gateway.feed([batch(5.0, [make_track(3, 900.0, 20.0)], 10)], smooth=False)
    assert [life.track_id for life in finisher.pending] == [2]
    assert [finisher.work() for _ in range(3)] == [0, 0, 0]
    assert not finisher.pending and "left for the next start" in caplog.text
    with gateway.storage.engine.begin() as connection:
        connection.exec_driver_sql("ALTER TABLE tracks_away RENAME TO tracks")
    assert gateway.points(2, smoothed=True) == []
    restarted = start_gateway(gateway.settings, gateway.storage, [gateway.now[0] + 1.0])
    assert len(restarted.points(2, smoothed=True)) == 10
