"""The gateway node: the bus into the database, the database out over HTTP, in one process.

Run it as ``python -m wz_gateway.node`` (settings ``WZ_GATEWAY_*``, bus ``WZ_BUS_*``). It

- subscribes to ``wz/<site>/tracks`` (:class:`TrackBatch`), ``wz/<site>/alerts/*``
  (:class:`Alert`), ``wz/<site>/devices/state`` (:class:`RoadsideDeviceState`),
  ``wz/<site>/queue`` (:class:`QueueState`, each lane's queue once a second) and
  ``wz/<site>/status/*`` (:class:`ServiceStatus`, for the WZDx devices' status) and
  ``wz/<site>/calibration/*`` (:class:`SensorCalibration`, each sensor's self-calibration:
  its latest, each change of state, and the WZDx devices' status) and ``wz/<site>/points/*``
  (:class:`PointSensorReading`, the upstream point speed sensors: each one's latest, for the
  WZDx feed's traffic sensors); a central
  gateway given several sites (``WZ_GATEWAY_SITE_FILES``, :mod:`wz_gateway.sites`) subscribes
  to ``wz/*/...`` and keeps the sites it was given. Alerts and device states are subscribed
  with recovery: what the alert service published while this gateway was away (its link
  down, or itself restarting) is fetched from the alert service's history when it comes back,
  and stored once (by ``alert_id``). One writer thread (the main one) stores what arrives, a
  group per transaction, **alerts first**: alerts, device states, statuses and calibrations
  are decoded in
  Zenoh's callbacks into the writer's queue (a full queue holds the callbacks: back-pressure,
  nothing dropped), and every round of the writer stores all of them before it takes any
  track batch. Track batches, the bulk, wait undecoded in a ring of their own
  (``queue_capacity`` batches, latest wins: a flood drops the oldest, counted in the status's
  ``dropped_counts``), decoded by the writer in groups of at most ``MAX_TRACK_GROUP``; so a
  flood of track batches never holds Zenoh's receive thread, which also carries the alerts,
  and an alert waits for at most one track transaction;
- serves the API (:func:`wz_gateway.app.create_app`) with uvicorn in a thread of the same
  process, on ``WZ_GATEWAY_HOST:WZ_GATEWAY_PORT`` (127.0.0.1:8000 by default);
- delivers the webhooks the stored alerts queued (:mod:`wz_gateway.delivery`: a thread and a
  small pool, woken by the writer);
- smooths the stored trajectory of each track that has ended, in the writer thread between
  groups (:mod:`wz_gateway.track_ends`), and at start those a stopped process left;
- deletes what is older than the retention, at start and every ``retention_period_s``.

Bad input never stops it: an undecodable message, one of a site not served (or whose
``site`` is not the one of its key), or one whose ``source_id`` is not the one its key carries
(a calibration on ``calibration/cam-1`` from another sensor: ``wrong_source``), is counted in
the status message's ``invalid_counts`` (``<key>|<reason>``) and on ``/metrics``, and dropped. A
group the database refuses is retried, then logged and counted (``wz_gateway_write_errors``).
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import uvicorn

from wz_gateway.app import create_app
from wz_gateway.auth import new_secret, parse_configured_key
from wz_gateway.delivery import WebhookDeliverer
from wz_gateway.key_store import KeyStore
from wz_gateway.live import Broadcaster, broadcaster_for
from wz_gateway.metrics import GatewayMetrics
from wz_gateway.settings import GatewaySettings
from wz_gateway.sites import Sites, load_sites
from wz_gateway.storage import Storage, StorageError
from wz_gateway.track_ends import SiteFinishers, TrackFinisher
from wz_gateway.webhook_store import WebhookStore
from wz_shared.bus import Subscription
from wz_shared.keys import site_of_key
from wz_shared.messages import (
    Alert,
    Message,
    PointSensorReading,
    QueueState,
    RoadsideDeviceState,
    SensorCalibration,
    ServiceStatus,
    TrackBatch,
)
from wz_shared.service import NodeApp, ServiceRuntime
from wz_shared.site import Site, SiteFileError

SERVICE = "gateway"
log = logging.getLogger("wz_gateway.node")
Report = Callable[[str, str, str], None]  # key, reason, detail

#: Most messages stored in one transaction.
MAX_GROUP = 256
#: Most track batches stored in one transaction: an alert that comes meanwhile waits for it.
MAX_TRACK_GROUP = 64
#: After a full transaction of track batches (a backlog: the writer is behind, a flood) the
#: writer stores no other for this share of the time it took (alerts still go at once), so the
#: database stays free a third of the time for the webhook deliverer's transactions and the
#: API instead of back-to-back track transactions holding them off. A group that is not full
#: (the tracker's 10 Hz, several sites') never waits.
TRACK_PAUSE_SHARE = 0.5
_WRITE_ATTEMPTS = 3
#: Smoothing of ended tracks still done at a stop [s].
_STOP_SMOOTHING_S = 2.0


@dataclass
class Writer:
    """Queue of bus messages and the loop that stores them (no bus: tests feed it directly).

    Parameters
    ----------
    storage : Storage
    sites : Site or Sites
        The sites stored; a message of another site, or whose ``site`` is not its key's, is
        refused (``report(key, "wrong_site", ...)``).
    settings : GatewaySettings
        Queue capacity and retention.
    metrics : GatewayMetrics
    report : callable
        ``report(key, reason, detail)`` for each refused message.
    clock : callable
        Wall clock [Unix s] stamped on rows as ``received_at``.
    live : Broadcaster, optional
        Handed each stored group, for the live stream's clients.
    finisher : TrackFinisher, optional
        Records track lives and smooths those that end, between groups.
    webhooks : WebhookDeliverer, optional
        Woken when a group queued webhook events.
    tracks : Subscription of TrackBatch, optional
        The node's ring of track batches (bulk: stored after everything in the queue); its
        ``on_push`` must be :meth:`wake`.
    beat : callable, optional
        ``beat(processed)`` each round of :meth:`run` (the node's liveness).
    """

    storage: Storage
    sites: Site | Sites
    settings: GatewaySettings
    metrics: GatewayMetrics
    report: Report
    clock: Callable[[], float] = time.time
    stop: threading.Event = field(default_factory=threading.Event)
    written: int = 0
    last_error: str | None = None
    live: Broadcaster | None = None
    finisher: TrackFinisher | SiteFinishers | None = None
    webhooks: WebhookDeliverer | None = None
    tracks: Subscription[TrackBatch] | None = None
    beat: Callable[[bool], None] = lambda _processed: None

    def __post_init__(self) -> None:
        self.sites = Sites.of(self.sites)
        self._geo = {site.site_id: site.geo_frame for site in self.sites}
        self.queue: queue.Queue[Message] = queue.Queue(self.settings.queue_capacity)
        self._next_purge = 0.0
        #: When each site's newest track batch was taken [monotonic s].
        self._tracks_at: dict[str, float] = {}
        #: No track transaction before this [monotonic s] (:data:`TRACK_PAUSE_SHARE`).
        self._tracks_after = 0.0
        #: Set when something arrives (the queue or the track ring): the writer's wait.
        self._wake = threading.Event()

    def wake(self) -> None:
        """Something arrived (Zenoh's thread): the writer looks again."""
        self._wake.set()

    def offer(self, key: str, message: Message) -> None:
        """Queue a decoded message (Zenoh's thread); waits while the queue is full."""
        if message.site not in self.sites or site_of_key(key) not in (None, message.site):
            self.report(
                key, "wrong_site", f"{type(message).__name__} of site {message.site} on {key}"
            )
            return
        if isinstance(message, TrackBatch):
            self._tracks_at[message.site] = time.monotonic()
        while not self.stop.is_set():
            try:
                self.queue.put(message, timeout=0.1)
                self._wake.set()
                return
            except queue.Full:
                continue

    def _track_group(self) -> list[Message]:
        """Up to MAX_TRACK_GROUP track batches from the ring, without waiting."""
        group: list[Message] = []
        while self.tracks is not None and len(group) < MAX_TRACK_GROUP:
            received = self.tracks.recv_with_key(0.0)
            if received is None:
                break
            batch = received.value
            if batch.site not in self.sites or site_of_key(received.key) != batch.site:
                self.report(
                    received.key,
                    "wrong_site",
                    f"TrackBatch of site {batch.site} on {received.key}",
                )
                continue
            group.append(batch)
            self._tracks_at[batch.site] = time.monotonic()
        return group

    def stale_tracks(self, limit_s: float) -> str | None:
        """What is wrong when a site's newest track batch is older than ``limit_s`` (the
        tracker publishes even with no vehicle, every 0.1 s), or None; a site whose tracks
        never came is not judged (a gateway may start first)."""
        now = time.monotonic()
        old = {site: now - at for site, at in self._tracks_at.items() if now - at > limit_s}
        if not old:
            return None
        return "; ".join(
            f"{site}: newest track batch {age:.0f} s old (is the tracker running?)"
            for site, age in sorted(old.items())
        )

    def _queued(self) -> list[Message]:
        """Up to MAX_GROUP messages of the queue, without waiting."""
        group: list[Message] = []
        while len(group) < MAX_GROUP:
            try:
                group.append(self.queue.get_nowait())
            except queue.Empty:
                break
        return group

    def _group(self, timeout_s: float) -> list[Message]:
        """The next group: the queue's (alerts first), else track batches from the ring
        (unless paused), waiting up to ``timeout_s`` for either."""
        deadline = time.monotonic() + timeout_s
        while True:
            self._wake.clear()  # before looking: what comes after wakes the wait below
            group = self._queued()
            if group:
                return group
            now = time.monotonic()
            if now >= self._tracks_after or timeout_s <= 0.0:
                group = self._track_group()
                if group:
                    return group
            if now >= deadline:
                return []
            until = deadline if now >= self._tracks_after else min(deadline, self._tracks_after)
            self._wake.wait(until - now)

    def write(self, group: list[Message]) -> bool:
        """Store one group, retrying a refused transaction; False if it was given up."""
        received_at = self.clock()
        if self.finisher is not None:
            self.finisher.before_write(group, received_at)
        for attempt in range(1, _WRITE_ATTEMPTS + 1):
            started = time.perf_counter()
            try:
                result = self.storage.ingest(group, geo=self._geo, received_at=received_at)
            except Exception as exc:  # the database refused: retry, then give the group up
                self.last_error = f"{type(exc).__name__}: {exc}"
                if attempt == _WRITE_ATTEMPTS:
                    self.metrics.write_errors.inc()
                    log.exception(
                        "could not store %d messages after %d attempts; dropped",
                        len(group),
                        attempt,
                    )
                    return False
                log.warning("storing %d messages failed (%s); retrying", len(group), exc)
                self.stop.wait(0.2 * attempt)
                continue
            self.metrics.write_seconds.observe(time.perf_counter() - started)
            self.last_error = None
            self.written += len(group)
            if self.webhooks is not None and result.webhook_events:
                self.webhooks.wake()
            if self.live is not None:
                self.live.publish(group)  # returns at once, however slow its clients
            m = self.metrics
            m.ingested.labels("track_batch").inc(result.track_batches)
            m.ingested.labels("alert").inc(result.alerts)
            m.ingested.labels("roadside_devices").inc(result.device_states)
            m.ingested.labels("queue_states").inc(result.queue_states)
            m.ingested.labels("service_status").inc(result.statuses)
            m.ingested.labels("sensor_calibration").inc(result.calibrations)
            m.ingested.labels("point_reading").inc(result.point_readings)
            m.ingested_points.inc(result.points)
            m.duplicate_alerts.inc(result.duplicate_alerts)
            return True
        return False

    def purge_if_due(self) -> None:
        now = self.clock()
        if now < self._next_purge:
            return
        self._next_purge = now + self.settings.retention_period_s
        try:
            deleted = self.storage.purge(
                now,
                retention_days=self.settings.retention_days,
                alert_retention_days=self.settings.alert_retention_days,
            )
        except Exception:  # retention failing must not stop ingestion; next period tries again
            log.exception("retention failed")
            return
        for table, n in deleted.items():
            self.metrics.retention_deleted.labels(table).inc(n)
        if any(deleted.values()):
            log.info("retention deleted %s", ", ".join(f"{n} {t}" for t, n in deleted.items() if n))

    def run(self, keep_going: Callable[[], bool] = lambda: True) -> None:
        """Store messages until ``stop`` (or ``keep_going()`` is False), then what is queued;
        ended tracks are smoothed between groups."""
        if self.finisher is not None:
            self.finisher.resume()
        while not self.stop.is_set() and keep_going():
            self.purge_if_due()
            group = self._group(0.1)
            if group:
                started = time.monotonic()
                self.write(group)
                backlog = len(group) >= MAX_TRACK_GROUP and isinstance(group[0], TrackBatch)
                if backlog and self.tracks is not None:
                    took = time.monotonic() - started
                    self._tracks_after = time.monotonic() + TRACK_PAUSE_SHARE * took
            self.beat(bool(group))
            if self.finisher is not None and self.queue.empty():
                self.finisher.work()
        while group := self._group(0.0):  # what the bus delivered before the stop
            self.write(group)
        if self.finisher is not None:  # what is left is taken up at the next start
            self.finisher.work(budget_s=_STOP_SMOOTHING_S)


def prepare_keys(storage: Storage, settings: GatewaySettings, now: float) -> str | None:
    """Make the stored ``settings`` keys match the configuration; outside dev mode, revoke
    every key made in dev mode; in dev mode without an admin key, make one for this run (the
    previous run's is revoked). The dev key's secret, or None."""
    configured = [parse_configured_key(entry) for entry in settings.api_keys]
    keys = KeyStore(storage.engine)
    added, revoked = keys.sync_configured(configured, now)
    if added or revoked:
        log.info("API keys from the settings: %d added, %d revoked", added, revoked)
    if not settings.dev_mode:
        revoked = keys.revoke_dev_mode(now)
        if revoked:
            log.warning("dev mode is off: %d API keys made in dev mode revoked", revoked)
    for info in keys.all():
        if info.origin == "dev":
            keys.revoke(info.key_id, now)
    if settings.dev_mode and not any(scope == "admin" for scope, _ in configured):
        secret = new_secret()
        keys.add("admin", secret, name="dev mode admin key", origin="dev", now=now, dev_mode=True)
        return secret
    return None


class _PlainUvicorn(logging.Filter):
    """Drop uvicorn's ANSI-coloured copy of each message from our (JSON) log lines."""

    def filter(self, record: logging.LogRecord) -> bool:
        record.__dict__.pop("color_message", None)
        return True


def serve(app_server: uvicorn.Server) -> threading.Thread:
    thread = threading.Thread(target=app_server.run, name="http", daemon=True)
    thread.start()
    return thread


def run(
    runtime: ServiceRuntime,
    site: Site | Sites,
    settings: GatewaySettings,
    storage: Storage,
    metrics: GatewayMetrics,
) -> int:
    """Store the bus and serve HTTP until ``runtime.stop``; the messages stored."""
    bus = runtime.bus
    sites = Sites.of(site)
    deliverer = WebhookDeliverer(WebhookStore(storage.engine), settings, metrics)
    finisher = (
        SiteFinishers.of(storage, sites, settings, metrics)
        if sites.several
        else TrackFinisher.of(storage, sites.default, settings, metrics)
    )
    writer = Writer(
        storage,
        sites,
        settings,
        metrics,
        report=lambda key, reason, detail: bus.stats.count_invalid(key, reason, detail),
        stop=runtime.stop,
        live=broadcaster_for(settings, metrics.registry),
        finisher=finisher,
        webhooks=deliverer,
        beat=lambda processed: runtime.beat(processed=processed),
    )
    # Track batches, the bulk: a ring read (and decoded) by the writer thread, never a hold
    # on Zenoh's receive thread, which also carries the alerts; each one wakes the writer.
    tracks = bus.subscribe(
        sites.key("tracks"),
        TrackBatch,
        mode="ring",
        capacity=settings.queue_capacity,
        on_push=writer.wake,
    )
    writer.tracks = tracks
    bus.on(sites.key("alerts/*"), Alert, writer.offer, recover=True)
    bus.on(sites.key("devices/state"), RoadsideDeviceState, writer.offer, recover=True)
    bus.on(sites.key("queue"), QueueState, writer.offer, recover=True)
    bus.on(sites.key("status/*"), ServiceStatus, writer.offer)
    # A calibration's source must be the sensor its key names (the bus checks it, as for
    # detections: wz_shared.trust.expected_source).
    bus.on(sites.key("calibration/*"), SensorCalibration, writer.offer)
    # The upstream point speed sensors' readings (the WZDx feed's traffic sensors); a reading's
    # source must be the sensor its key names.
    bus.on(sites.key("points/*"), PointSensorReading, writer.offer)
    metrics.watch_bus(bus.stats.snapshot)
    metrics.watch_queue(lambda: writer.queue.qsize() + tracks.pending)
    metrics.watch_webhooks(deliverer.store.pending_count)

    def readiness() -> dict[str, str]:
        checks = {
            "bus": "closed" if bus.closed else "ok",
            "writer": "ok" if writer.last_error is None else writer.last_error,
        }
        loop_age_s = runtime.loop_age_s()
        if loop_age_s is not None and loop_age_s > settings.stall_after_s:
            checks["writer"] = f"its loop has not gone round for {loop_age_s:.1f} s: stalled"
        if writer.queue.qsize() >= 0.9 * settings.queue_capacity:
            checks["queue"] = f"{writer.queue.qsize()} of {settings.queue_capacity} waiting"
        stale = writer.stale_tracks(settings.stale_after_s)
        if stale:
            checks["tracks"] = stale
        return checks

    app = create_app(
        settings, storage, site=sites, metrics=metrics, readiness=readiness, live=writer.live
    )
    server = uvicorn.Server(
        uvicorn.Config(
            app,
            host=settings.host,
            port=settings.port,
            log_config=None,
            access_log=False,
            lifespan="off",
            server_header=False,
            timeout_graceful_shutdown=5,
        )
    )
    http = serve(server)
    log.info(
        "storing %s, %s, %s of %s; API on http://%s:%d",
        sites.key("tracks"),
        sites.key("alerts/*"),
        sites.key("devices/state"),
        ", ".join(sites.ids),
        settings.host,
        settings.port,
    )
    deliverer.start()
    writer.run(keep_going=http.is_alive)
    deliverer.close()  # attempts in flight finish; the rest waits in the outbox
    if writer.live is not None:
        writer.live.close()  # ends the live streams, which would otherwise hold the server
    server.should_exit = True
    http.join(timeout=10.0)
    if not server.started or not runtime.stop.is_set():
        runtime.stop.set()
        raise SystemExit(
            f"{SERVICE}: the HTTP server on {settings.host}:{settings.port} stopped (is the "
            "port in use?)"
        )
    return writer.written


def main() -> None:
    node = NodeApp(SERVICE, GatewaySettings)
    settings = node.settings
    with node.fatal(SiteFileError):
        sites = load_sites(settings.site_entries)
    node.start_logging(sites.default.site_id)
    for name in ("uvicorn", "uvicorn.error"):
        logging.getLogger(name).addFilter(_PlainUvicorn())
    with node.fatal(StorageError):
        storage = Storage.open(settings.resolved_database_url())
    try:
        dev_secret = prepare_keys(storage, settings, time.time())
        if dev_secret is not None:
            log.warning("dev mode: reads need no key; admin key for this run: %s", dev_secret)
        # Status on the wall clock; its health is /readyz, and the health file where one is
        # asked for (WZ_HEALTH_FILE: `wz up`'s stall check of the writer loop).
        written = node.serve(
            lambda runtime: run(runtime, sites, settings, storage, GatewayMetrics()),
            sim_clock=False,
        )
        log.info("stopped after storing %d messages", written)
    finally:
        storage.close()


if __name__ == "__main__":
    main()
