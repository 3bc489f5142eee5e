"""Typed publish / subscribe / query over Eclipse Zenoh 1.x.

One :class:`Bus` per process wraps one Zenoh session. Publishers encode pydantic messages (or
frame envelopes); subscriptions decode them, either into a queue the service reads
(:meth:`Bus.subscribe`) or in a callback (:meth:`Bus.on`).

Queues
------
- ``"ring"``: latest-wins, for sensor frames. A slow consumer gets the newest ``capacity``
  samples and the ones it missed are counted as dropped; the producer is never blocked.
- ``"fifo"``: every sample in order, for detections, tracks and alerts. When the queue is full
  Zenoh's receive thread waits (back-pressure), so nothing is lost.

Samples are decoded when the service takes them, not on Zenoh's thread, so a ring never spends
time decoding frames that will be overwritten.

Bad input
---------
A payload that fails to decode is counted under ``(key, reason)``, logged once per key and
reason, and dropped; it never raises into Zenoh's callback thread and never stops the service.
A callback that raises is logged and counted the same way. So is a message whose
``source_id`` is not the one its key carries (``wrong_source``, :func:`wz_shared.trust.
source_problem`): a track batch not from the tracker, an alert not from the alert service, a
detection batch not from the sensor its key names. So is a message that names another site than
its key (``wrong_site``): each site's certificates may put only their own site's keys, and a
message must say the same. The routers' access control already keeps other sessions from
putting them (:mod:`wz_shared.trust`); this is the consumer's own check.

Shutdown
--------
A Zenoh subscriber with a Python callback that is still declared when the interpreter exits
hangs the exit: :meth:`Bus.close` (or leaving the ``with`` block) undeclares everything, then
closes the session.
"""

from __future__ import annotations

import collections
import json
import logging
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any, Generic, Literal, TypeVar

import zenoh
import zenoh.ext

from wz_shared import codec
from wz_shared.keys import Keys
from wz_shared.messages import Message
from wz_shared.reach import open_session
from wz_shared.settings import BusSettings
from wz_shared.shedding import StampGate
from wz_shared.trust import expected_source, site_problem, source_problem, tls_config

log = logging.getLogger(__name__)

M = TypeVar("M", bound=Message)
T = TypeVar("T")
QueueMode = Literal["ring", "fifo"]
Decoder = Callable[[bytes], T]


def zenoh_config(settings: BusSettings) -> zenoh.Config:
    """Build a Zenoh config: the optional file first, then the settings on top.

    Without a file every setting applies, defaults included. With one (a deployment's
    ``deploy/zenoh/edge-service.json5``) only the settings given explicitly (``WZ_BUS_MODE`` ...
    in the environment) override it: the file's mode and endpoints are not replaced by
    defaults nobody asked for. ``tls_dir`` (``WZ_BUS_TLS_DIR``) puts that folder's
    credentials in place of the file's TLS paths.
    """
    if settings.config_file:
        config = zenoh.Config.from_file(str(settings.config_file))
        given = settings.model_fields_set
    else:
        config = zenoh.Config()
        given = set(BusSettings.model_fields)
    overrides = {
        "mode": ("mode", settings.mode),
        "connect_endpoints": ("connect/endpoints", settings.connect_endpoints),
        "listen_endpoints": ("listen/endpoints", settings.listen_endpoints),
        "multicast_scouting": ("scouting/multicast/enabled", settings.multicast_scouting),
    }
    for field_name, (path, value) in overrides.items():
        if field_name in given:
            config.insert_json5(path, json.dumps(value))
    if settings.tls_dir is not None:
        config.insert_json5("transport/link/tls", json.dumps(tls_config(settings.tls_dir)))
    return config


# --- counters -------------------------------------------------------------------------------


@dataclass
class BusStats:
    """Counters of one bus, read by the health reporter. Thread-safe."""

    published: collections.Counter[str] = field(default_factory=collections.Counter)
    received: collections.Counter[str] = field(default_factory=collections.Counter)
    invalid: collections.Counter[tuple[str, str]] = field(default_factory=collections.Counter)
    dropped: collections.Counter[str] = field(default_factory=collections.Counter)
    #: Samples a subscription's gate shed before decoding, by (key, reason): ``stale``,
    #: ``superseded`` (:mod:`wz_shared.shedding`).
    shed: collections.Counter[tuple[str, str]] = field(default_factory=collections.Counter)
    #: Gaps a recovering subscription found and re-fetched (:class:`CallbackSubscription`).
    gaps: collections.Counter[str] = field(default_factory=collections.Counter)
    #: When the newest message a consumer took from a queue had arrived (monotonic [s]): the
    #: node's processing latency is measured from there (:meth:`ServiceRuntime.beat`).
    last_taken_arrival: float | None = None
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)
    _logged: set[tuple[str, str]] = field(default_factory=set, repr=False)

    def taken(self, arrived: float) -> None:
        self.last_taken_arrival = arrived  # one float: atomic under the GIL

    def count_published(self, key: str) -> None:
        with self._lock:
            self.published[key] += 1

    def count_received(self, key: str) -> None:
        with self._lock:
            self.received[key] += 1

    def count_dropped(self, key: str, n: int = 1) -> None:
        with self._lock:
            self.dropped[key] += n

    def count_shed(self, key: str, reason: str) -> None:
        with self._lock:
            self.shed[(key, reason)] += 1

    def count_gap(self, key: str, detail: str) -> None:
        with self._lock:
            self.gaps[key] += 1
        log.info("gap on %s (%s): fetching the publishers' caches", key, detail, extra={"key": key})

    def count_invalid(self, key: str, reason: str, detail: str) -> None:
        """Count a rejected message; log the first of each (key, reason) only."""
        with self._lock:
            self.invalid[(key, reason)] += 1
            first = (key, reason) not in self._logged
            self._logged.add((key, reason))
        if first:
            log.warning(
                "dropped invalid message on %s (%s): %s; further ones are only counted",
                key,
                reason,
                detail,
                extra={"key": key, "reason": reason},
            )

    def snapshot(self) -> dict[str, dict[str, int]]:
        with self._lock:
            return {
                "published": dict(self.published),
                "received": dict(self.received),
                "invalid": {f"{k}|{r}": n for (k, r), n in self.invalid.items()},
                "dropped": dict(self.dropped),
                "shed": {f"{k}|{r}": n for (k, r), n in self.shed.items()},
                "gaps": dict(self.gaps),
            }


# --- publishing -----------------------------------------------------------------------------


#: How often a publisher with a history tells subscribers its newest sequence number [s]:
#: a subscriber that missed the last samples (a link down) asks for them within this period.
HEARTBEAT_S = 1.0


class Publisher(Generic[M]):
    """Publishes messages of one type on one key.

    With ``history`` (a number of samples) it is a Zenoh *advanced* publisher: it keeps its
    newest ``history`` samples, numbers every sample, and announces itself and its newest
    number (:data:`HEARTBEAT_S`). A subscriber with ``recover=True`` (:meth:`Bus.on`) that
    missed samples, because a link was down or because it started later, fetches them from that
    cache: store and forward without a broker. The cache is in this process's memory.
    """

    def __init__(
        self, bus: Bus, key: str, cls: type[M], *, block: bool, history: int | None = None
    ) -> None:
        self.key = key
        self.cls = cls
        self.history = history
        self._stats = bus.stats
        self._frame = codec.is_frame_type(cls)
        congestion = zenoh.CongestionControl.BLOCK if block else zenoh.CongestionControl.DROP
        self._publisher: Any
        if history is None:
            self._publisher = bus.session.declare_publisher(
                key, congestion_control=congestion, reliability=zenoh.Reliability.RELIABLE
            )
        else:
            if history < 1:
                raise ValueError("a publisher's history holds at least one sample")
            self._publisher = zenoh.ext.declare_advanced_publisher(
                bus.session,
                key,
                congestion_control=congestion,
                reliability=zenoh.Reliability.RELIABLE,
                cache=zenoh.ext.CacheConfig(history),
                sample_miss_detection=zenoh.ext.MissDetectionConfig(
                    heartbeat=HEARTBEAT_S, sporadic_heartbeat=None
                ),
                publisher_detection=True,
            )

    def put(self, message: M) -> None:
        """Publish a JSON message."""
        if self._frame:
            raise TypeError(f"{self.cls.__name__} is frame metadata: use put_bytes(envelope)")
        # The frame check above is the one codec.encode would repeat: encode straight away.
        self.put_bytes(codec.encode_json(message))

    def put_bytes(self, payload: bytes) -> None:
        """Publish an already-encoded payload (a frame envelope, or a replayed message)."""
        self._publisher.put(payload)
        self._stats.count_published(self.key)

    @property
    def matched(self) -> bool:
        """Whether any subscriber for this key is known to the session now."""
        if self.history is not None:
            raise TypeError(f"{self.key}: a publisher with a history does not report matching")
        # zenoh's stub says bool; at run time it is a MatchingStatus with a .matching flag.
        status: Any = self._publisher.matching_status
        return bool(status.matching)

    def wait_for_subscribers(self, timeout_s: float) -> bool:
        """Wait until a subscriber matches (declarations take a moment to propagate)."""
        deadline = time.monotonic() + timeout_s
        while not self.matched:
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.005)
        return True

    def undeclare(self) -> None:
        self._publisher.undeclare()


# --- subscribing ----------------------------------------------------------------------------


class _SampleQueue:
    """A ring or a bounded FIFO of raw payloads, fed from Zenoh's thread."""

    def __init__(
        self,
        mode: QueueMode,
        capacity: int,
        key: str,
        stats: BusStats,
        on_push: Callable[[], None] | None = None,
    ) -> None:
        if capacity < 1:
            raise ValueError("queue capacity must be at least 1")
        self.mode = mode
        self.capacity = capacity
        #: (key, payload, arrival on the monotonic clock)
        self._items: collections.deque[tuple[str, bytes, float]] = collections.deque()
        self._cond = threading.Condition()
        self._closed = False
        self._key = key
        self._stats = stats
        #: Called after each sample queued (a consumer that waits on several sources).
        self._on_push = on_push

    def push(self, key: str, payload: bytes) -> None:
        with self._cond:
            if self.mode == "ring":
                if len(self._items) >= self.capacity:
                    self._items.popleft()
                    self._stats.count_dropped(self._key)
            else:
                # Back-pressure: hold Zenoh's thread until the consumer makes room.
                while len(self._items) >= self.capacity and not self._closed:
                    self._cond.wait(0.1)
                if self._closed:
                    return
            self._items.append((key, payload, time.monotonic()))
            self._cond.notify_all()
        if self._on_push is not None:
            self._on_push()

    def pop(self, timeout_s: float | None) -> tuple[str, bytes] | None:
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        with self._cond:
            while not self._items:
                if self._closed:
                    return None
                remaining = None if deadline is None else deadline - time.monotonic()
                if remaining is not None and remaining <= 0:
                    return None
                self._cond.wait(remaining)
            key, payload, arrived = self._items.popleft()
            self._cond.notify_all()
        self._stats.taken(arrived)
        return key, payload

    def __len__(self) -> int:
        with self._cond:
            return len(self._items)

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify_all()


@dataclass(frozen=True)
class Received(Generic[T]):
    """A decoded sample and the concrete key it arrived on."""

    key: str
    value: T


class Subscription(Generic[T]):
    """A subscription whose samples the service takes with :meth:`recv`.

    Iterating yields values until the bus closes.
    """

    def __init__(
        self,
        bus: Bus,
        key: str,
        decoder: Decoder[T],
        mode: QueueMode,
        capacity: int,
        on_push: Callable[[], None] | None = None,
        gate: StampGate | None = None,
    ) -> None:
        self.key = key
        self._decoder = decoder
        self._stats = bus.stats
        self._queue = _SampleQueue(mode, capacity, key, bus.stats, on_push)
        self._gate = gate
        self._subscriber = bus.session.declare_subscriber(key, self._on_sample)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        try:
            self._stats.count_received(self.key)
            payload = sample.payload.to_bytes()
            if self._gate is not None:
                reason = self._gate.check(payload)
                if reason is not None:
                    self._stats.count_shed(self.key, reason)
                    return
            self._queue.push(str(sample.key_expr), payload)
        except Exception as exc:  # never raise into Zenoh's thread
            self._stats.count_invalid(self.key, "receive_error", repr(exc))

    def recv_with_key(self, timeout_s: float | None = None) -> Received[T] | None:
        """The next valid sample, or None on timeout or when the bus closes.

        Invalid payloads met on the way are counted and skipped.
        """
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while True:
            remaining = None if deadline is None else max(0.0, deadline - time.monotonic())
            item = self._queue.pop(remaining)
            if item is None:
                return None
            key, payload = item
            try:
                value = self._decoder(payload)
                _source_checked(key, value)
                return Received(key, value)
            except codec.DecodeError as exc:
                self._stats.count_invalid(self.key, exc.reason, exc.detail)
                if self._gate is not None:
                    self._gate.refused(payload)

    def recv(self, timeout_s: float | None = None) -> T | None:
        received = self.recv_with_key(timeout_s)
        return None if received is None else received.value

    def drain(self) -> list[T]:
        """Every valid sample queued now, without waiting."""
        values: list[T] = []
        while len(self._queue):
            value = self.recv(0.0)
            if value is not None:
                values.append(value)
        return values

    def __iter__(self) -> Iterator[T]:
        while True:
            value = self.recv(None)
            if value is None:
                return
            yield value

    @property
    def pending(self) -> int:
        return len(self._queue)

    @property
    def capacity(self) -> int:
        return self._queue.capacity

    def undeclare(self) -> None:
        self._queue.close()
        self._subscriber.undeclare()


class CallbackSubscription(Generic[T]):
    """A subscription that decodes and calls ``callback`` on Zenoh's thread.

    Keep the callback short; an exception in it is logged, counted, and the subscription goes on.

    With ``recover`` it is a Zenoh *advanced* subscriber: from publishers that keep a history
    (``Bus.publisher(..., history=N)``) it fetches what it missed: their cached samples when
    it starts or when one of them appears (a trailer whose link came back), and the samples
    lost in a gap, which it finds from their sequence numbers and heartbeats. A sample may then
    arrive twice (once live, once again from a cache after a reconnection): the callback must
    be idempotent (the gateway stores an alert once per ``alert_id``).

    Zenoh's own recovery gives a gap up when its query ends, even when the samples are in the
    cache but were not in that query's answer (a sample published while the routes were coming
    back after a link cut, with the next one already received). So every gap Zenoh reports is
    counted (``stats.gaps``) and then filled here: a plain query of the cache of the publisher
    Zenoh names (``<key>/@adv/pub/<zid>/<eid>/**``, zenoh-ext's cache queryable; every
    publisher's when it names none) on a worker thread, every cached sample handed to the
    callback. Only what a cache no longer holds (more than its ``history`` samples since) stays
    lost.
    """

    def __init__(
        self,
        bus: Bus,
        key: str,
        decoder: Decoder[T],
        callback: Callable[[str, T], None],
        *,
        recover: bool = False,
    ) -> None:
        self.key = key
        self._decoder = decoder
        self._callback = callback
        self._stats = bus.stats
        self._subscriber: Any
        if not recover:
            self._subscriber = bus.session.declare_subscriber(key, self._on_sample)
            return
        self._subscriber = zenoh.ext.declare_advanced_subscriber(
            bus.session,
            key,
            self._on_sample,
            history=zenoh.ext.HistoryConfig(detect_late_publishers=True),
            recovery=zenoh.ext.RecoveryConfig(periodic_queries=None, heartbeat=True),
            subscriber_detection=True,
        )
        self._refetch = _CacheRefetch(bus.session, key, self._on_sample)
        self._miss_listener = self._subscriber.sample_miss_listener(self._on_miss)

    def _on_miss(self, miss: Any) -> None:
        self._stats.count_gap(self.key, f"{miss.nb} samples from {miss.source}")
        zid, eid = getattr(miss.source, "zid", None), getattr(miss.source, "eid", None)
        self._refetch.request(None if zid is None or eid is None else f"{zid}/{eid}")

    def _on_sample(self, sample: zenoh.Sample) -> None:
        self._stats.count_received(self.key)
        try:
            value = self._decoder(sample.payload.to_bytes())
            _source_checked(str(sample.key_expr), value)
        except codec.DecodeError as exc:
            self._stats.count_invalid(self.key, exc.reason, exc.detail)
            return
        except Exception as exc:  # never raise into Zenoh's thread
            self._stats.count_invalid(self.key, "decode_error", repr(exc))
            return
        try:
            self._callback(str(sample.key_expr), value)
        except Exception:
            self._stats.count_invalid(self.key, "callback_error", "see traceback")
            log.exception("callback for %s raised; the subscription goes on", self.key)

    def undeclare(self) -> None:
        listener = getattr(self, "_miss_listener", None)
        if listener is not None:
            listener.undeclare()
            self._refetch.close()
        self._subscriber.undeclare()


#: Longest wait for the publishers' caches to answer a re-fetch [s].
REFETCH_TIMEOUT_S = 5.0


class _CacheRefetch:
    """Fetches every sample an advanced publisher on ``key`` holds, on its own thread, when
    asked (a gap): the publisher named ``"<zid>/<eid>"``, or all of them (None). Requests that
    come while a fetch runs are served by the next one."""

    def __init__(
        self, session: zenoh.Session, key: str, on_sample: Callable[[zenoh.Sample], None]
    ) -> None:
        self._session = session
        self._key = key
        self._on_sample = on_sample
        self._wanted: set[str | None] = set()
        self._cond = threading.Condition()
        self._closed = False
        self._thread: threading.Thread | None = None

    def request(self, publisher: str | None) -> None:
        with self._cond:
            if self._closed:
                return
            self._wanted.add(publisher)
            self._cond.notify()
            if self._thread is None:
                self._thread = threading.Thread(
                    target=self._run, daemon=True, name=f"refetch {self._key}"
                )
                self._thread.start()

    def _run(self) -> None:
        while True:
            with self._cond:
                while not self._wanted and not self._closed:
                    self._cond.wait()
                if self._closed:
                    return
                wanted, self._wanted = self._wanted, set()
            # one query of every publisher's cache covers each named one
            for publisher in [None] if None in wanted else sorted(p for p in wanted if p):
                self._fetch(f"{self._key}/@adv/pub/" + (f"{publisher}/**" if publisher else "**"))

    def _fetch(self, selector: str) -> None:
        try:
            replies = self._session.get(
                selector,
                timeout=REFETCH_TIMEOUT_S,
                accept_replies=zenoh.ReplyKeyExpr.ANY,  # a cache answers with the key itself
                consolidation=zenoh.ConsolidationMode.NONE,  # every sample, not the newest
            )
            for reply in replies:
                if self._closed:
                    return
                if reply.ok is not None:
                    self._on_sample(reply.ok)
        except Exception:  # a closing session; the next gap asks again
            log.debug("re-fetch of %s failed", selector, exc_info=True)

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify()


def _source_checked(key: str, value: object) -> object:
    """``value`` if its ``site`` is the one ``key`` names and its ``source_id`` the one
    ``key`` carries; else a DecodeError (``wrong_site``, ``wrong_source``)."""
    if isinstance(value, codec.Frame):
        message: Message = value.meta  # a frame's site and source are in its metadata
    elif isinstance(value, Message):
        message = value
    else:  # raw bytes: not decoded, not checked
        return value
    problem = site_problem(key, message.site)
    if problem is not None:
        raise codec.DecodeError("wrong_site", problem)
    expected = expected_source(key)
    if expected is not None and message.source_id != expected:
        raise codec.DecodeError("wrong_source", str(source_problem(key, message.source_id)))
    return value


def json_decoder(cls: type[M]) -> Decoder[M]:
    def decode(payload: bytes) -> M:
        return codec.decode_json(payload, cls)

    return decode


def frame_decoder(cls: type[M]) -> Decoder[codec.Frame[M]]:
    def decode(payload: bytes) -> codec.Frame[M]:
        return codec.decode_frame(payload, cls)

    return decode


def raw_decoder(payload: bytes) -> bytes:
    return payload


# --- the bus --------------------------------------------------------------------------------


class Bus:
    """One Zenoh session of one service at one site.

    Use as a context manager, or call :meth:`close`::

        with Bus.open(BusSettings(), site="us75-lincoln", service="simulator") as bus:
            truth = bus.publisher(bus.keys.truth, GroundTruth)
    """

    def __init__(self, session: zenoh.Session, *, site: str, service: str) -> None:
        self.session = session
        self.keys = Keys(site)
        self.site = site
        self.service = service
        self.stats = BusStats()
        self._declared: list[Any] = []
        self._lock = threading.Lock()
        self._closed = False

    @classmethod
    def open(
        cls,
        settings: BusSettings,
        *,
        site: str,
        service: str,
        on_wait: Callable[[str], None] | None = None,
        stop: threading.Event | None = None,
    ) -> Bus:
        """Join the bus; while the session waits for its router, log why every few seconds
        and pass the reason to ``on_wait`` (:func:`wz_shared.reach.open_session`). ``stop``
        set during the wait raises :class:`~wz_shared.reach.BusWaitAbortedError`."""
        session = open_session(zenoh_config(settings), on_wait=on_wait, stop=stop)
        log.debug("zenoh session %s open (%s)", session.zid(), settings.mode)
        return cls(session, site=site, service=service)

    def __enter__(self) -> Bus:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _keep(self, declare: Callable[[], T]) -> T:
        """Declare an entity (refused once closed) and remember it for :meth:`close`."""
        with self._lock:
            if self._closed:
                raise RuntimeError("the bus is closed")
            entity = declare()
            self._declared.append(entity)
        return entity

    def queue_depths(self) -> dict[str, tuple[int, int]]:
        """Per subscription key: the samples queued for the consumer now, and the capacity."""
        with self._lock:
            subscriptions = [d for d in self._declared if isinstance(d, Subscription)]
        return {s.key: (s.pending, s.capacity) for s in subscriptions}

    # publishing
    def publisher(
        self, key: str, cls: type[M], *, block: bool | None = None, history: int | None = None
    ) -> Publisher[M]:
        """A publisher of ``cls`` on ``key``.

        ``block`` chooses congestion control: frames default to dropping under congestion
        (a stale frame is worthless), everything else to blocking (never lost). ``history``:
        keep that many newest samples for subscribers that missed them (see :class:`Publisher`).
        """
        if block is None:
            block = not codec.is_frame_type(cls)
        return self._keep(lambda: Publisher(self, key, cls, block=block, history=history))

    # subscribing
    def subscribe(
        self,
        key: str,
        cls: type[M],
        *,
        mode: QueueMode = "fifo",
        capacity: int = 4096,
        on_push: Callable[[], None] | None = None,
        gate: StampGate | None = None,
    ) -> Subscription[M]:
        """Queue JSON messages of ``cls`` from ``key`` (may hold wildcards); ``on_push()``
        after each sample queued, on Zenoh's thread (keep it short: set an event).

        ``gate`` (:class:`~wz_shared.shedding.StampGate`) checks each sample on Zenoh's
        thread before anything else and sheds, undecoded, those that carry no news (counted
        in ``stats.shed`` by reason); tell it what became of those let in
        (:meth:`~wz_shared.shedding.StampGate.settle`)."""
        return self._keep(
            lambda: Subscription(self, key, json_decoder(cls), mode, capacity, on_push, gate)
        )

    def subscribe_frames(
        self,
        key: str,
        cls: type[M],
        *,
        mode: QueueMode = "ring",
        capacity: int = 1,
    ) -> Subscription[codec.Frame[M]]:
        """Queue frames (LiDAR or camera) from ``key``; a ring of one by default."""
        return self._keep(lambda: Subscription(self, key, frame_decoder(cls), mode, capacity))

    def subscribe_raw(
        self, key: str, *, mode: QueueMode = "fifo", capacity: int = 65536
    ) -> Subscription[bytes]:
        """Queue undecoded payloads (recorders and taps)."""
        return self._keep(lambda: Subscription(self, key, raw_decoder, mode, capacity))

    def on(
        self,
        key: str,
        cls: type[M],
        callback: Callable[[str, M], None],
        *,
        recover: bool = False,
    ) -> CallbackSubscription[M]:
        """Call ``callback(key, message)`` on Zenoh's thread for each valid JSON message;
        ``recover``: also for those missed, from publishers with a history (at least once)."""
        return self._keep(
            lambda: CallbackSubscription(self, key, json_decoder(cls), callback, recover=recover)
        )

    def on_raw(
        self, key: str, callback: Callable[[str, bytes], None]
    ) -> CallbackSubscription[bytes]:
        return self._keep(lambda: CallbackSubscription(self, key, raw_decoder, callback))

    # queries
    def serve(self, key: str, respond: Callable[[], bytes | None]) -> None:
        """Answer queries on ``key`` with the bytes ``respond()`` returns (None: no reply)."""

        def on_query(query: zenoh.Query) -> None:
            try:
                payload = respond()
                if payload is not None:
                    query.reply(key, payload)
            except Exception:
                log.exception("queryable %s failed to answer", key)

        self._keep(lambda: self.session.declare_queryable(key, on_query))

    def query(self, key: str, cls: type[M], timeout_s: float = 2.0) -> list[M]:
        """Ask ``key``'s queryables; return every valid reply."""
        replies = self.session.get(key, timeout=timeout_s)
        values: list[M] = []
        for reply in replies:
            if reply.ok is None:
                continue
            try:
                values.append(codec.decode_json(reply.ok.payload.to_bytes(), cls))
            except codec.DecodeError as exc:
                self.stats.count_invalid(key, exc.reason, exc.detail)
        return values

    def query_bytes(self, key: str, timeout_s: float = 2.0) -> list[bytes]:
        return [
            reply.ok.payload.to_bytes()
            for reply in self.session.get(key, timeout=timeout_s)
            if reply.ok is not None
        ]

    # liveliness
    def declare_alive(self) -> None:
        """Declare this service's liveliness token at ``wz/<site>/status/<service>``."""
        self._keep(lambda: self.session.liveliness().declare_token(self.keys.status(self.service)))

    def alive(self, key: str | None = None, timeout_s: float = 1.0) -> list[str]:
        """Keys of the liveliness tokens alive now under ``key`` (default: this site's status)."""
        selector = key or self.keys.status_all
        replies = self.session.liveliness().get(selector, timeout=timeout_s)
        return sorted({str(reply.ok.key_expr) for reply in replies if reply.ok is not None})

    # shutdown
    def close(self) -> None:
        """Undeclare every publisher, subscriber, queryable and token; close the session."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            declared, self._declared = self._declared, []
        for entity in reversed(declared):
            try:
                entity.undeclare()
            except Exception as exc:  # a session torn down under us must not block the rest
                log.debug("undeclare failed during close: %r", exc)
        self.session.close()

    @property
    def closed(self) -> bool:
        return self._closed
