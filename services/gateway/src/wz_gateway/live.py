"""The live stream's broadcaster: what the writer stored, handed to every connected client.

The writer thread calls :meth:`Broadcaster.publish` after each stored group; each client of
``GET /v1/stream`` holds a :class:`Subscription` in the server's event loop. Nothing here can
hold the writer up: ``publish`` takes a lock for a few list operations and hands each client
its events with ``loop.call_soon_threadsafe`` (a deque append and a wake-up), never waiting
on a client.

Per client:

- ``tracks``: the newest track batch, at most ``max_tracks_hz`` a second. A batch that comes
  sooner after the last one sent waits, and a newer one replaces it (counted as decimated),
  so a client always ends on the newest batch;
- ``alert``: every alert stored, once (an ``alert_id`` the bus repeats is sent once);
- ``calibration``: every sensor self-calibration stored (each sensor's detector sends one on
  a change of state and every 5 s); a new client gets each sensor's newest at once;
- a bounded queue of ``queue_capacity`` events: when a slow client lets it fill, the oldest
  event is dropped and counted (``wz_gateway_stream_dropped_events``), never the writer held.

Event ids are ``<boot>-<sequence>``; a client that reconnects with ``Last-Event-ID`` of the
same boot gets the alerts it missed among the newest ``recent_alerts``.

The ``tracks`` event's data (JSON)::

    {"site", "stamp" [s], "cycle_index", "received_at" [Unix s], "tracks": [
        {"track_id", "x_m", "y_m", "station_m", "offset_m", "speed_mps", "heading_rad",
         "lane_index", "object_class", "status", "length_m", "width_m"}, ...]}

positions rounded to 1 cm, speeds to 0.01 m/s, headings to 1 mrad; ``length_m`` and
``width_m`` null when the tracker gave none. The ``alert`` event's data is the
:class:`~wz_shared.messages.Alert` as ``GET /v1/alerts`` returns it; the ``calibration``
event's the :class:`~wz_shared.messages.SensorCalibration` as the detector published it (and
``GET /v1/calibration`` shows it).
"""

from __future__ import annotations

import asyncio
import json
import logging
import math
import threading
import time
from collections import OrderedDict, deque
from collections.abc import Callable, Sequence
from typing import Any, Literal

from prometheus_client import CollectorRegistry, Counter, Gauge

from wz_gateway.settings import GatewaySettings
from wz_shared.messages import Alert, Message, SensorCalibration, TrackBatch

log = logging.getLogger(__name__)

EventKind = Literal["tracks", "alert", "calibration"]
EVENT_KINDS: tuple[EventKind, ...] = ("tracks", "alert", "calibration")
#: Alert ids remembered to send each alert once.
_SEEN_ALERT_IDS = 4096


def compact_tracks(batch: TrackBatch, received_at: float) -> dict[str, Any]:
    """The ``tracks`` event's data: what a live view draws of each track, rounded."""
    return {
        "site": batch.site,
        "stamp": batch.stamp,
        "cycle_index": batch.cycle_index,
        "received_at": round(received_at, 3),
        "tracks": [
            {
                "track_id": t.track_id,
                "x_m": round(t.x_m, 2),
                "y_m": round(t.y_m, 2),
                "station_m": round(t.station_m, 2),
                "offset_m": round(t.offset_m, 2),
                "speed_mps": round(t.speed_mps, 2),
                "heading_rad": round(t.heading_rad, 3),
                "lane_index": t.lane_index,
                "object_class": t.object_class.value,
                "status": t.status.value,
                "length_m": None if t.length_m is None else round(t.length_m, 2),
                "width_m": None if t.width_m is None else round(t.width_m, 2),
            }
            for t in batch.tracks
        ],
    }


class LiveEvent:
    """One event of the stream; its text is made once, when a client first needs it."""

    __slots__ = ("_make", "_text", "event_id", "kind", "sequence")

    def __init__(
        self, kind: EventKind, sequence: int, event_id: str, make: Callable[[], str]
    ) -> None:
        self.kind = kind
        self.sequence = sequence
        self.event_id = event_id
        self._make = make
        self._text: str | None = None

    def sse(self) -> str:
        """The event in the text/event-stream format (``id``, ``event``, one ``data`` line)."""
        if self._text is None:  # two threads may both make it: the same text either way
            self._text = f"id: {self.event_id}\nevent: {self.kind}\ndata: {self._make()}\n\n"
        return self._text


class Subscription:
    """One client's events, in the event loop that serves it.

    Everything but :meth:`get` runs in that loop, scheduled by the broadcaster from other
    threads; ``get`` is awaited by the client's response.
    """

    def __init__(
        self,
        broadcaster: Broadcaster,
        loop: asyncio.AbstractEventLoop,
        kinds: frozenset[EventKind],
        capacity: int,
        tracks_interval_s: float,
    ) -> None:
        self.loop = loop
        self.kinds = kinds
        self.dropped = 0
        self.decimated = 0
        self._broadcaster = broadcaster
        self._queue: asyncio.Queue[LiveEvent | None] = asyncio.Queue(capacity)
        self._tracks_interval_s = tracks_interval_s
        self._pending_tracks: LiveEvent | None = None
        self._timer: asyncio.TimerHandle | None = None
        self._last_tracks_at = -math.inf
        self._closed = False

    async def get(self) -> LiveEvent | None:
        """The next event; None once the stream is closed (the server stops)."""
        return await self._queue.get()

    def offer(self, event: LiveEvent) -> None:
        if self._closed or event.kind not in self.kinds:
            return
        if event.kind != "tracks":
            self._put(event)
            return
        if self._pending_tracks is not None:
            self.decimated += 1  # a newer batch came before the last one's turn
        self._pending_tracks = event
        if self._timer is None:
            delay_s = self._last_tracks_at + self._tracks_interval_s - self.loop.time()
            if delay_s <= 0.0:
                self._flush_tracks()
            else:
                self._timer = self.loop.call_later(delay_s, self._flush_tracks)

    def _flush_tracks(self) -> None:
        self._timer = None
        event, self._pending_tracks = self._pending_tracks, None
        if event is not None and not self._closed:
            self._last_tracks_at = self.loop.time()
            self._put(event)

    def _put(self, event: LiveEvent | None) -> None:
        if self._queue.full():
            self._queue.get_nowait()  # the oldest goes, so the client sees the newest
            self.dropped += 1
            self._broadcaster.count_drop()
        self._queue.put_nowait(event)

    def close(self) -> None:
        """End the stream: the client's :meth:`get` returns None after what is queued."""
        if self._closed:
            return
        self._closed = True
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        self._put(None)


class TooManyClientsError(RuntimeError):
    """The stream already has ``max_clients`` clients."""


class Broadcaster:
    """Hands the events the writer stores to every client of the live stream (thread-safe).

    Parameters
    ----------
    max_tracks_hz : float
        Most ``tracks`` events a second to one client [Hz].
    queue_capacity : int
        Events held for one client; beyond, the oldest are dropped (and counted).
    max_clients : int
        Clients at once; :meth:`subscribe` refuses more with :class:`TooManyClientsError`.
    recent_alerts : int
        Alert events kept for clients that reconnect with ``Last-Event-ID``.
    registry : CollectorRegistry, optional
        Where the stream's metrics go (the gateway's own registry); none without.
    clock : callable
        Wall clock [Unix s]: the ``received_at`` of the tracks events.
    """

    def __init__(
        self,
        *,
        max_tracks_hz: float = 10.0,
        queue_capacity: int = 64,
        max_clients: int = 32,
        recent_alerts: int = 100,
        registry: CollectorRegistry | None = None,
        clock: Callable[[], float] = time.time,
    ) -> None:
        if max_tracks_hz <= 0.0 or queue_capacity < 1 or max_clients < 1:
            raise ValueError("max_tracks_hz, queue_capacity and max_clients must be positive")
        self.tracks_interval_s = 1.0 / max_tracks_hz
        self.queue_capacity = queue_capacity
        self.max_clients = max_clients
        self.clock = clock
        #: Tells this process's ids from a previous one's (a reconnecting client's).
        self.boot = f"{time.time_ns() // 1_000_000:x}"
        self._lock = threading.Lock()
        self._subscriptions: set[Subscription] = set()
        self._sequence = 0
        self._latest_tracks: LiveEvent | None = None
        self._recent_alerts: deque[LiveEvent] = deque(maxlen=recent_alerts)
        #: Each sensor's newest calibration event, by (site, sensor id).
        self._latest_calibrations: dict[tuple[str, str], LiveEvent] = {}
        self._seen_alerts: OrderedDict[tuple[str, str], None] = OrderedDict()
        self._closed = False
        self.dropped = 0
        self._dropped_metric: Counter | None = None
        if registry is not None:
            self._dropped_metric = Counter(
                "wz_gateway_stream_dropped_events",
                "Live-stream events dropped because a client read too slowly",
                registry=registry,
            )
            clients = Gauge(
                "wz_gateway_stream_clients", "Clients of the live stream", registry=registry
            )
            clients.set_function(lambda: float(self.client_count))

    @property
    def client_count(self) -> int:
        with self._lock:
            return len(self._subscriptions)

    def count_drop(self) -> None:
        with self._lock:
            self.dropped += 1
        if self._dropped_metric is not None:
            self._dropped_metric.inc()

    # --- the writer's side ----------------------------------------------------------------

    def publish(self, group: Sequence[Message]) -> None:
        """Hand a stored group's newest track batch, its alerts and its sensor calibrations
        to every client.

        Called by the writer thread after the group's transaction; returns at once.
        """
        batch: TrackBatch | None = None
        alerts: list[Alert] = []
        calibrations: list[SensorCalibration] = []
        for message in group:
            if isinstance(message, TrackBatch):
                batch = message  # the group is in arrival order: the last is the newest
            elif isinstance(message, Alert):
                alerts.append(message)
            elif isinstance(message, SensorCalibration):
                calibrations.append(message)
        if batch is None and not alerts and not calibrations:
            return
        received_at = self.clock()
        events: list[LiveEvent] = []
        with self._lock:
            if self._closed:
                return
            if batch is not None:
                event = self._event("tracks", _tracks_text(batch, received_at))
                self._latest_tracks = event
                events.append(event)
            for alert in alerts:
                if (alert.site, alert.alert_id) in self._seen_alerts:
                    continue
                self._seen_alerts[(alert.site, alert.alert_id)] = None
                if len(self._seen_alerts) > _SEEN_ALERT_IDS:
                    self._seen_alerts.popitem(last=False)
                event = self._event("alert", alert.model_dump_json)
                self._recent_alerts.append(event)
                events.append(event)
            for calibration in calibrations:
                event = self._event("calibration", calibration.model_dump_json)
                self._latest_calibrations[(calibration.site, calibration.source_id)] = event
                events.append(event)
            subscriptions = list(self._subscriptions)
        for subscription in subscriptions:
            for event in events:
                self._schedule(subscription, subscription.offer, event)

    def _event(self, kind: EventKind, make: Callable[[], str]) -> LiveEvent:
        self._sequence += 1
        return LiveEvent(kind, self._sequence, f"{self.boot}-{self._sequence}", make)

    def _schedule(self, subscription: Subscription, call: Callable[..., None], *args: Any) -> None:
        try:
            subscription.loop.call_soon_threadsafe(call, *args)
        except RuntimeError:  # its event loop is closed: the server is gone
            self.unsubscribe(subscription)

    # --- the clients' side ----------------------------------------------------------------

    def subscribe(
        self, kinds: frozenset[EventKind], last_event_id: str | None = None
    ) -> Subscription:
        """A new client, in the running event loop: first each sensor's newest calibration
        and the newest track batch (when asked for them) and, after a reconnect, the alerts
        missed since ``last_event_id``."""
        subscription = Subscription(
            self, asyncio.get_running_loop(), kinds, self.queue_capacity, self.tracks_interval_s
        )
        with self._lock:
            if self._closed:
                subscription.close()
                return subscription
            if len(self._subscriptions) >= self.max_clients:
                raise TooManyClientsError(
                    f"the live stream already has the most clients it serves ({self.max_clients})"
                )
            self._subscriptions.add(subscription)
            missed = self._missed_alerts(last_event_id)
            latest = self._latest_tracks
            calibrations = sorted(self._latest_calibrations.values(), key=lambda e: e.sequence)
        for event in [*calibrations, *missed]:
            subscription.offer(event)
        if latest is not None:
            subscription.offer(latest)
        return subscription

    def _missed_alerts(self, last_event_id: str | None) -> list[LiveEvent]:
        if not last_event_id:
            return []
        boot, _, sequence = last_event_id.strip().partition("-")
        if boot != self.boot or not sequence.isdigit():
            return []
        after = int(sequence)
        return [event for event in self._recent_alerts if event.sequence > after]

    def unsubscribe(self, subscription: Subscription) -> None:
        with self._lock:
            self._subscriptions.discard(subscription)

    def close(self) -> None:
        """End every client's stream (the server is stopping) and refuse new ones."""
        with self._lock:
            self._closed = True
            subscriptions = list(self._subscriptions)
            self._subscriptions.clear()
        for subscription in subscriptions:
            self._schedule(subscription, subscription.close)


def broadcaster_for(
    settings: GatewaySettings, registry: CollectorRegistry | None = None
) -> Broadcaster:
    """The broadcaster the settings ask for (``stream_*``)."""
    return Broadcaster(
        max_tracks_hz=settings.stream_max_hz,
        queue_capacity=settings.stream_queue_capacity,
        max_clients=settings.stream_max_clients,
        registry=registry,
    )


def _tracks_text(batch: TrackBatch, received_at: float) -> Callable[[], str]:
    return lambda: json.dumps(compact_tracks(batch, received_at), separators=(",", ":"))
