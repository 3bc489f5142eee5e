"""An alert-service crash in the middle of open episodes (``kill -9``, its state file kept, as
a container's volume or `wz up`'s state folder keeps it): the new process continues the
episode of the car still speeding and clears the one of the car that left while it was down,
each once; no second ``start`` for either. Real processes on real Zenoh."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

from tests.alert_service.helpers import SITE, batch, make_track
from tests.alert_service.test_node_process import FAST_MPS, PERIOD_S, wait_for
from wz_alert_service.recovery import HISTORY_S, load_open_episodes
from wz_shared.bus import Bus, Publisher
from wz_shared.messages import Alert, AlertType, ServiceStatus, TrackBatch
from wz_shared.settings import BusSettings

ROOT = Path(__file__).resolve().parents[2]
STAYS, LEAVES = 1, 2  # track ids


def cars(stamp_s: float, ids: tuple[int, ...]) -> TrackBatch:
    """Both cars at 65 mph, 100 m apart, at ``stamp_s`` of a stream that began at 0."""
    tracks = [make_track(i, 450.0 - 100.0 * (i - 1) + FAST_MPS * stamp_s, FAST_MPS) for i in ids]
    return batch(stamp_s, tracks, round(stamp_s / PERIOD_S))


def publish(
    tracks: Publisher[TrackBatch], start_s: float, end_s: float, ids: tuple[int, ...]
) -> None:
    """One batch every 0.1 s of stream time, paced at real time."""
    for k in range(round((end_s - start_s) / PERIOD_S)):
        tracks.put(cars(start_s + k * PERIOD_S, ids))
        time.sleep(PERIOD_S / 2)


def test_kill_9_then_restart_continues_or_clears_each_episode_once(
    port: int, tmp_path: Path
) -> None:
    settings = BusSettings(listen_endpoints=[f"tcp/127.0.0.1:{port}"], connect_endpoints=[])
    state_file = tmp_path / "alert-service" / "open-episodes.json"
    env = {k: v for k, v in os.environ.items() if not k.startswith("WZ_")}
    env.update(
        WZ_BUS_CONNECT_ENDPOINTS=f"tcp/127.0.0.1:{port}",
        WZ_BUS_LISTEN_ENDPOINTS="",
        WZ_STATUS_PERIOD_S="0.2",
        WZ_LOG_FORMAT="json",
        WZ_ALERT_STATE_FILE=str(state_file),
    )

    def start(prefix: str) -> subprocess.Popen[bytes]:
        return subprocess.Popen(
            [sys.executable, "-m", "wz_alert_service.node"],
            cwd=ROOT,
            env={**env, "WZ_ALERT_EPISODE_ID_PREFIX": prefix},
        )

    received: list[Alert] = []
    with Bus.open(settings, site=SITE.site_id, service="restart-test") as bus:
        tracks = bus.publisher(bus.keys.tracks, TrackBatch)
        alerts = bus.subscribe(bus.keys.alerts_all, Alert)
        status = bus.subscribe(bus.keys.status("alert-service"), ServiceStatus)
        first = start("run1")
        try:
            assert tracks.wait_for_subscribers(30.0)
            publish(tracks, 0.0, 2.0, (STAYS, LEAVES))
            for track_id in (STAYS, LEAVES):
                wait_for(
                    alerts,
                    lambda a, t=track_id: a.phase == "start" and a.track_id == t,
                    f"track {track_id}'s start",
                    received,
                )
            saved = load_open_episodes(state_file)
            # Each car's speeding episode (and any other rule's it set off) saved as open.
            saved_speeding = [a for a in saved if a.alert_type is AlertType.SPEEDING]
            assert sorted(a.track_id for a in saved_speeding) == [STAYS, LEAVES]
        finally:
            first.send_signal(signal.SIGKILL)
            first.wait()
        # While it is down, the car LEAVES leaves; the stream goes on with STAYS only.
        second = start("run2")
        try:
            wait_for(status, lambda s: s.pid == second.pid, "the restarted node's status")
            assert tracks.wait_for_subscribers(30.0)
            publish(tracks, 2.5, 6.5, (STAYS,))
            publish(tracks, 6.5, 7.5, ())  # STAYS leaves too
            for track_id in (STAYS, LEAVES):
                wait_for(
                    alerts,
                    lambda a, t=track_id: a.phase == "clear" and a.track_id == t,
                    f"track {track_id}'s clear",
                    received,
                )
            while (late := alerts.recv(1.0)) is not None:
                received.append(late)
        finally:
            second.send_signal(signal.SIGTERM)
            assert second.wait(20.0) == 0

    speeding = [a for a in received if a.alert_type is AlertType.SPEEDING]
    for alert_type, track_id in {(a.alert_type, a.track_id) for a in received}:
        events = [a for a in received if (a.alert_type, a.track_id) == (alert_type, track_id)]
        phases = Counter(a.phase for a in events)
        # Every episode of either run: one start, one clear, one id (no second start).
        assert phases["start"] == 1 and phases["clear"] == 1, (alert_type, track_id, events)
        assert len({a.episode_id for a in events}) == 1, (track_id, events)
        assert events[0].phase == "start" and events[-1].phase == "clear"
        assert str(events[0].episode_id).startswith("run1-")
        assert len({a.alert_id for a in events}) == len(events)  # every event its own id
    leaves_clear = next(a for a in speeding if a.track_id == LEAVES and a.phase == "clear")
    rule = SITE.alerts.speeding
    # Cleared within the rule's hold + clear (+ the histories' second) of the restart's stream.
    assert leaves_clear.stamp <= 2.5 + rule.hold_s + rule.clear_s + HISTORY_S + PERIOD_S
    stays_clear = next(a for a in speeding if a.track_id == STAYS and a.phase == "clear")
    assert stays_clear.stamp >= 6.5  # it went on while the car was there
    assert load_open_episodes(state_file) == []
