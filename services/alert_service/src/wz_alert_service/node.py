"""The alert service node: fused tracks in, alerts and the roadside devices' state out.

Run it as ``python -m wz_alert_service.node`` (settings: ``WZ_ALERT_*``, bus ``WZ_BUS_*``; the
rules' thresholds are the ``alerts:`` section of the site file). It

- takes :class:`TrackBatch` messages from ``wz/<site>/tracks`` (a FIFO: every batch counts, in
  the order the tracker published them) and gives each to the :class:`AlertEngine`. Before a
  batch is queued, a gate reads its stamp off the bytes and sheds, undecoded, one that carries
  no news (``stale``: not newer than the last one let in; ``superseded``: newer by less than
  ``WZ_ALERT_MIN_BATCH_INTERVAL_S``, 5 ms; :mod:`wz_shared.shedding`), counted by reason in
  the status message's ``shed_counts``, ``wz status`` and ``wz_bus_shed_total``: a flood of
  batches from a faulty or hostile source never puts the engine behind the road;
- publishes each event the engine decides (an episode's start, a rise in severity, its clear)
  as an :class:`Alert` on ``wz/<site>/alerts/<type>``, reliably (congestion control blocks: an
  alert is never dropped), before anything else is done with the batch;
- publishes the flashing beacon's and the message sign's state
  (:class:`RoadsideDeviceState`) on ``wz/<site>/devices/state`` whenever what they show
  changes (and once, for the first batch, so a listener knows the starting state);
- publishes each lane's queue (:class:`QueueState`, :mod:`wz_alert_service.queues`) on
  ``wz/<site>/queue`` once a second of track stamps and at once when a lane's condition
  changes; the sign's queue message reads it (stopped or slow, the back's distance);
- takes the upstream point sensors' readings from ``wz/<site>/points/*`` where the site file
  lists point sensors: they bound a queue's back beyond the sensors' reach (one of a sensor
  the site file does not list is counted, ``unknown_sensor``, and dropped);
- answers queries on ``wz/<site>/alerts/active`` with :class:`ActiveAlerts`: per open
  episode its newest published event, and the devices' state, for a consumer that joins late.

Time is the batches' stamps (capture time); the node never reads the wall clock for its logic.
A tracker with no vehicles still publishes (empty) batches, which clear what is open.

Bad input never stops it; each problem is counted in the status message's ``invalid_counts``
under ``wz/<site>/tracks|<reason>``: the bus's own decode reasons (``bad_json``,
``wrong_kind``, ``schema_version``, ``invalid``...), ``wrong_site`` (a batch of another site)
and ``out_of_order`` (a batch older than the last one: the engine moves forward in time only).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from wz_alert_service.devices import SignHold, roadside_devices
from wz_alert_service.engine import AlertEngine
from wz_alert_service.recovery import (
    EpisodeRecovery,
    clear_event,
    load_open_episodes,
    save_open_episodes,
)
from wz_alert_service.settings import AlertServiceSettings
from wz_shared.codec import encode_json
from wz_shared.messages import (
    ActiveAlerts,
    Alert,
    AlertType,
    PointSensorReading,
    QueueState,
    RoadsideDeviceState,
    TrackBatch,
)
from wz_shared.service import NodeApp, ServiceRuntime
from wz_shared.shedding import StampGate
from wz_shared.site import Site
from wz_shared.timebase import RunWatch, SimClock

SERVICE = "alert-service"
log = logging.getLogger("wz_alert_service.node")
Report = Callable[[str, str], None]


@dataclass(frozen=True)
class AlertOutputs:
    """What one track batch produced.

    Attributes
    ----------
    accepted : bool
        False when the batch was refused (another site, or older than the last one).
    alerts : list of Alert
        The engine's events as messages, in the engine's order.
    devices : RoadsideDeviceState or None
        The devices' new state, when what they show changed; None otherwise.
    queue : QueueState or None
        The lanes' queue, when due (once a second of stamps, or on a change); None otherwise.
    """

    accepted: bool
    alerts: list[Alert] = field(default_factory=list)
    devices: RoadsideDeviceState | None = None
    queue: QueueState | None = None


class AlertCore:
    """What the node does without the bus: track batches in, alert messages and devices out.

    Parameters
    ----------
    site : Site
        The site: geometry, limits and the ``alerts:`` thresholds.
    report : callable
        ``report(reason, detail)`` for each refused batch.
    id_prefix : str
        Put before every episode id (see :class:`AlertEngine`).
    source_id : str
        The ``source_id`` of every message.
    """

    def __init__(
        self,
        site: Site,
        report: Report,
        *,
        id_prefix: str = "",
        source_id: str = SERVICE,
        recovered: Sequence[Alert] = (),
    ) -> None:
        self.site = site
        self.report = report
        self.source_id = source_id
        self._id_prefix = id_prefix
        self.engine = AlertEngine(site, id_prefix=id_prefix)
        self.devices: RoadsideDeviceState | None = None
        #: The lanes' newest queue state (published or not).
        self.queue_state: QueueState | None = None
        self._sign = SignHold(self.engine.rules.devices.message_hold_s)
        self._newest: dict[str, Alert] = {}  # episode id -> its newest start or update
        #: The episodes a previous process left open (:mod:`wz_alert_service.recovery`).
        self.recovery = EpisodeRecovery(site, recovered)
        for alert in recovered:
            self._newest[str(alert.episode_id)] = alert
        self._stamp_s = 0.0
        #: The tracker's stamps going back for good (a restarted simulation or replay): a new
        #: run, whose batches would otherwise all be ignored as out of order.
        self._run = RunWatch()
        self.runs = 1

    def _end_open_episodes(self, stamp: float, already: set[str]) -> list[Alert]:
        """A clear for each open episode of the old run (but those in ``already``): a sign
        or a consumer that saw its start must see it end, once."""
        return [
            clear_event(alert, stamp, "a new run: its tracks are gone")
            for episode, alert in self._newest.items()
            if episode not in already
        ]

    def _start_new_run(self, batch: TrackBatch) -> None:
        """Start the engine again for the new run; its episode numbers go on (ids stay unique).
        The old run's open episodes were cleared first (:meth:`_end_open_episodes`)."""
        count = self.engine.episode_count
        self.engine = AlertEngine(
            self.site, id_prefix=self._id_prefix, reach_m=self.engine.queues.reach_m
        )
        self.engine.episode_count = count
        self._newest.clear()
        self.runs += 1
        log.warning(
            "track stamps went back to %.3f s (from %.3f s): a new run; the alert "
            "engine starts again",
            batch.stamp,
            self._stamp_s,
        )

    def add(self, batch: TrackBatch) -> AlertOutputs:
        """Evaluate one track batch."""
        if batch.site != self.site.site_id:
            self.report("wrong_site", f"track batch of site {batch.site} from {batch.source_id}")
            return AlertOutputs(accepted=False)
        ended: list[Alert] = []
        if self._run.observe(batch.stamp) == "new_run":
            if self.recovery.active:
                ended = self.recovery.clear_all(batch.stamp, "a new run")
            ended += self._end_open_episodes(batch.stamp, {str(a.episode_id) for a in ended})
            self._start_new_run(batch)
        out_of_order = self.engine.counters.batches_out_of_order
        events = self.engine.update(batch)
        if self.engine.counters.batches_out_of_order > out_of_order:
            self.report(
                "out_of_order",
                f"track batch at {batch.stamp:.3f} s after {self._stamp_s:.3f} s: ignored",
            )
            return AlertOutputs(accepted=False)
        self._stamp_s = batch.stamp
        alerts = [event.to_message(self.site.site_id, self.source_id) for event in events]
        if self.recovery.active:
            alerts = self.recovery.rewrite(alerts, batch.stamp)
        alerts = ended + alerts
        for alert in alerts:
            assert alert.episode_id is not None  # the engine names every episode
            if alert.phase == "clear":
                self._newest.pop(alert.episode_id, None)
            else:
                self._newest[alert.episode_id] = alert
        queue_state = self.engine.queues.due(
            batch.stamp, site=self.site.site_id, source_id=self.source_id
        )
        if queue_state is not None:
            self.queue_state = queue_state
        devices = self._sign.apply(
            roadside_devices(
                self.engine.active(),
                self.engine.zone,
                batch.stamp,
                source_id=self.source_id,
                queue_state=self.queue_state,
            )
        )
        if devices.shows_same_as(self.devices):
            return AlertOutputs(accepted=True, alerts=alerts, queue=queue_state)
        self.devices = devices
        return AlertOutputs(accepted=True, alerts=alerts, devices=devices, queue=queue_state)

    def add_point(self, reading: PointSensorReading) -> str | None:
        """Take an upstream point sensor's reading (it bounds a queue's back beyond the
        sensors' reach); the reason it is refused (``wrong_site``, ``unknown_sensor``: one the
        site file does not list), None when taken."""
        if reading.site != self.site.site_id:
            return "wrong_site"
        if not self.engine.queues.observe(reading):
            return "unknown_sensor"
        return None

    def open_episodes(self) -> list[Alert]:
        """Each open episode's newest published event (what a restart recovers)."""
        return list(self._newest.values())

    def active(self) -> ActiveAlerts:
        """The open episodes (their newest events) and the devices, as of the last batch."""
        devices = self.devices or roadside_devices(
            [], self.engine.zone, self._stamp_s, source_id=self.source_id
        )
        alerts = list(self._newest.values())
        return ActiveAlerts(
            site=self.site.site_id,
            source_id=self.source_id,
            stamp=self._stamp_s,
            alerts=alerts,
            devices=devices,
        )


def _log_alert(alert: Alert) -> None:
    subject = "site" if alert.track_id is None else f"track {alert.track_id}"
    log.info(
        "%s %s %s (%s): %s",
        alert.alert_type.value,
        alert.phase,
        subject,
        alert.severity.value,
        alert.description,
        extra={
            "alert_type": alert.alert_type.value,
            "phase": alert.phase,
            "episode_id": alert.episode_id,
            "stamp": alert.stamp,
        },
    )


def run(
    runtime: ServiceRuntime,
    site: Site,
    settings: AlertServiceSettings,
    clock: SimClock,
    id_prefix: str,
) -> int:
    """Evaluate track batches until ``runtime.stop``; the number of alerts published."""
    bus = runtime.bus
    tracks_key = bus.keys.tracks

    def report(reason: str, detail: str) -> None:
        bus.stats.count_invalid(tracks_key, reason, detail)

    state_file = settings.state_file
    recovered = [] if state_file is None else load_open_episodes(state_file)
    core = AlertCore(site, report, id_prefix=id_prefix, recovered=recovered)
    publishers = {
        t: bus.publisher(bus.keys.alerts(t.value), Alert, history=settings.history_per_type)
        for t in AlertType
    }
    # The newest device state, for a gateway that starts (or reconnects) after it changed.
    devices_publisher = bus.publisher(bus.keys.devices_state, RoadsideDeviceState, history=1)
    queue_publisher = bus.publisher(bus.keys.queue, QueueState, history=1)
    snapshot = [encode_json(core.active())]
    bus.serve(bus.keys.alerts_active, lambda: snapshot[-1])
    gate = StampGate(settings.min_batch_interval_s) if settings.shed_stale_batches else None
    batches = bus.subscribe(
        tracks_key,
        TrackBatch,
        capacity=settings.queue_capacity,
        gate=gate,
    )
    points = (
        bus.subscribe(bus.keys.point_sensors_all, PointSensorReading, capacity=64)
        if site.point_sensors
        else None
    )
    log.info("alerting on %s -> %s", tracks_key, bus.keys.alerts_all)
    published = 0
    runs = core.runs
    while not runtime.stop.is_set():
        for reading in points.drain() if points is not None else ():
            refused = core.add_point(reading)
            if refused is not None:
                bus.stats.count_invalid(
                    bus.keys.point_sensors_all, refused, f"point reading of {reading.source_id}"
                )
        batch = batches.recv(0.1)
        runtime.beat(processed=batch is not None)
        if batch is None:
            continue
        outputs = core.add(batch)
        if gate is not None:
            gate.settle(batch.stamp, outputs.accepted)
        if not outputs.accepted:
            continue
        for alert in outputs.alerts:
            publishers[alert.alert_type].put(alert)
            published += 1
        for alert in outputs.alerts:
            _log_alert(alert)
        if outputs.alerts and state_file is not None:
            try:
                save_open_episodes(state_file, core.open_episodes())
            except OSError as exc:  # a full or read-only disk: alerts go on, unsaved
                log.error("cannot save the open episodes to %s: %s", state_file, exc)
        if outputs.devices is not None:
            devices_publisher.put(outputs.devices)
            log.info(
                "devices: beacon %s, sign %r",
                "on" if outputs.devices.beacon_on else "off",
                outputs.devices.sign_text,
            )
        if outputs.queue is not None:
            queue_publisher.put(outputs.queue)
        snapshot[:] = [encode_json(core.active())]
        if core.runs != runs:  # a new run: its time starts again
            runs = core.runs
            clock.restart(batch.stamp)
        elif batch.stamp >= clock.now():
            clock.advance_to(batch.stamp)
    return published


def main() -> None:
    node = NodeApp(SERVICE, AlertServiceSettings)
    site = node.load_site()
    settings = node.settings
    id_prefix = settings.episode_id_prefix or time.strftime("%Y%m%dT%H%M%S", time.gmtime())
    published = node.serve(lambda runtime: run(runtime, site, settings, node.clock, id_prefix))
    log.info("stopped after %d alerts", published)


if __name__ == "__main__":
    main()
