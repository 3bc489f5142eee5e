"""The node's core without the bus: refused batches reported, alert messages and the devices'
state published only when it changes, the active episodes for the queryable."""

from __future__ import annotations

import pytest

from tests.alert_service.helpers import SITE, batch, make_track, stamps
from wz_alert_service.node import AlertCore, AlertOutputs
from wz_alert_service.settings import AlertServiceSettings
from wz_shared import codec
from wz_shared.messages import ActiveAlerts, Alert, AlertType, TrackBatch
from wz_shared.site import MPH_TO_MPS

FAST_MPS = 55.0 * MPH_TO_MPS + 8.0 * MPH_TO_MPS  # 8 mph over the 55 mph limit


def core_and_reports() -> tuple[AlertCore, list[tuple[str, str]]]:
    reports: list[tuple[str, str]] = []
    core = AlertCore(SITE, lambda reason, detail: reports.append((reason, detail)), id_prefix="t")
    return core, reports


def test_a_speeder_gives_one_start_then_a_clear_and_the_devices_follow() -> None:
    core, reports = core_and_reports()
    starts, clears, device_states = [], [], []
    for k, t in enumerate(stamps(3.0, rate_hz=10.0)):
        tracks = [make_track(1, 500.0 + 27.0 * t, FAST_MPS)] if t < 2.0 else []
        outputs = core.add(batch(t, tracks, k))
        assert outputs.accepted
        starts += [
            a for a in outputs.alerts if a.alert_type is AlertType.SPEEDING and a.phase == "start"
        ]
        clears += [
            a for a in outputs.alerts if a.alert_type is AlertType.SPEEDING and a.phase == "clear"
        ]
        if outputs.devices is not None:
            device_states.append(outputs.devices)
        if t == pytest.approx(1.5):
            active = core.active()
            assert [a.alert_type for a in active.alerts] == [
                AlertType.SPEEDING,
                AlertType.AGGRESSIVE_APPROACH,
            ]
            assert active.alerts[0] == starts[0]
            assert active.devices.beacon_on and active.stamp == pytest.approx(1.5)
            assert codec.decode_json(codec.encode_json(active), ActiveAlerts) == active
    assert reports == []
    (start,) = starts
    (clear,) = clears
    assert start.stamp == pytest.approx(1.0) and start.onset_stamp == pytest.approx(0.0)
    assert start.episode_id == clear.episode_id and start.episode_id.startswith("t-speeding-1-")
    assert (start.site, start.source_id) == (SITE.site_id, "alert-service")
    assert clear.stamp == pytest.approx(2.0)  # the track is gone: cleared at once
    # Off at the first batch, on with the first start, off again once both episodes cleared.
    assert [(d.beacon_on, d.sign_text, round(d.stamp, 6)) for d in device_states] == [
        (False, "", 0.0),
        (True, "SLOW DOWN", 1.0),
        (False, "", 2.0),
    ]
    assert core.active().alerts == [] and not core.active().devices.beacon_on


def test_batches_of_another_site_or_from_the_past_are_reported_and_ignored() -> None:
    core, reports = core_and_reports()
    assert core.add(batch(1.0, [make_track(1, 500.0, FAST_MPS)])).accepted
    other = TrackBatch(
        site="elsewhere", source_id="fusion-tracker", stamp=2.0, cycle_index=0, tracks=[]
    )
    assert core.add(other) == AlertOutputs(accepted=False)
    assert not core.add(batch(0.5, [])).accepted
    assert [reason for reason, _ in reports] == ["wrong_site", "out_of_order"]
    assert "elsewhere" in reports[0][1] and "0.500 s" in reports[1][1]
    assert core.engine.counters.batches == 1


def test_settings_refuse_an_episode_prefix_that_cannot_be_an_identifier(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setenv("WZ_ALERT_EPISODE_ID_PREFIX", "has space")
    with pytest.raises(ValueError, match="letters, digits"):
        AlertServiceSettings()
    monkeypatch.setenv("WZ_ALERT_EPISODE_ID_PREFIX", "edge-1")
    monkeypatch.setenv("WZ_ALERT_QUEUE_CAPACITY", "16")
    settings = AlertServiceSettings()
    assert (settings.episode_id_prefix, settings.queue_capacity) == ("edge-1", 16)


def test_a_new_run_of_the_tracker_starts_the_engine_again_with_ids_going_on() -> None:
    """The tracker's stamps go back for good (the simulation restarted): after RunWatch's
    confirmation the engine starts again and alerts on the new run; a single stray old batch
    before that is still ignored; no episode id repeats."""
    core, reports = core_and_reports()

    def speeder(start_s: float, duration_s: float, first_cycle: int) -> list[Alert]:
        alerts: list[Alert] = []
        for k, t in enumerate(stamps(duration_s, rate_hz=10.0, start_s=start_s)):
            tracks = (
                [make_track(1, 500.0 + 27.0 * (t - start_s), FAST_MPS)]
                if t < start_s + duration_s - 0.5
                else []
            )
            alerts += core.add(batch(t, tracks, first_cycle + k)).alerts
        return alerts

    first = speeder(300.0, 3.0, 0)
    assert core.add(batch(5.0, [], 99)).accepted is False  # one stray old batch: ignored
    assert [reason for reason, _ in reports] == ["out_of_order"]
    second = speeder(0.0, 3.0, 0)  # the new run, from 0 s
    assert core.runs == 2
    starts = [
        a for a in first + second if a.phase == "start" and a.alert_type is AlertType.SPEEDING
    ]
    # The new run is confirmed at its third batch (0.2 s): the hold runs from there.
    assert len(starts) == 2 and starts[1].stamp == pytest.approx(1.2)
    ids = [a.alert_id for a in first + second]
    assert len(ids) == len(set(ids))


def test_a_new_run_clears_every_open_episode_once() -> None:
    """The tracker restarts mid-episode (its stamps go back): each episode open then gets one
    clear, its next event id, before the new run's events; the beacon goes off; nothing is
    cleared twice when the new run goes on."""
    core, _ = core_and_reports()
    events: list[Alert] = []
    devices = []
    for k, t in enumerate(stamps(2.0, rate_hz=10.0, start_s=100.0)):
        tracks = [make_track(1, 500.0 + 27.0 * (t - 100.0), FAST_MPS)]
        tracks.append(make_track(2, 520.0 + 27.0 * (t - 100.0), FAST_MPS, offset_m=-1.0))
        outputs = core.add(batch(t, tracks, k))
        events += outputs.alerts
        devices += [outputs.devices] if outputs.devices is not None else []
    opened = {a.episode_id: a for a in events if a.phase != "clear"}
    assert len(opened) >= 2 and not [a for a in events if a.phase == "clear"]
    assert devices[-1].beacon_on
    after: list[Alert] = []
    for k, t in enumerate(stamps(3.0, rate_hz=10.0)):  # the new run: nobody on the road yet
        outputs = core.add(batch(t, [], 100 + k))
        after += outputs.alerts
        devices += [outputs.devices] if outputs.devices is not None else []
    assert core.runs == 2
    clears = [a for a in after if a.phase == "clear"]
    assert sorted(a.episode_id for a in clears) == sorted(opened)
    newest = {a.episode_id: a for a in events}
    for clear in clears:
        last = newest[clear.episode_id]
        sequence = int(last.alert_id.rsplit("-", 1)[1])
        assert clear.alert_id == f"{clear.episode_id}-{sequence + 1}"
        assert clear.alert_type is last.alert_type and "a new run" in clear.description
    assert not devices[-1].beacon_on
    assert core.active().alerts == []
