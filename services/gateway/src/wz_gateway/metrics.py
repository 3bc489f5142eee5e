"""Prometheus metrics of one gateway process, in their own registry (never the global one, so
that several apps in one process, as in tests, do not collide)."""

from __future__ import annotations

from collections.abc import Callable, Iterator

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram
from prometheus_client.core import CounterMetricFamily
from prometheus_client.registry import Collector

BusSnapshot = Callable[[], dict[str, dict[str, int]]]


class _BusCollector(Collector):
    """The bus's own counters (received, invalid, gaps per key), read at scrape time."""

    def __init__(self, snapshot: BusSnapshot) -> None:
        self._snapshot = snapshot

    def collect(self) -> Iterator[CounterMetricFamily]:
        snap = self._snapshot()
        received = CounterMetricFamily(
            "wz_gateway_bus_received", "Samples received per key", labels=["key"]
        )
        for key, n in snap.get("received", {}).items():
            received.add_metric([key], n)
        invalid = CounterMetricFamily(
            "wz_gateway_bus_invalid",
            "Messages dropped as invalid, per key and reason",
            labels=["key", "reason"],
        )
        for name, n in snap.get("invalid", {}).items():
            key, _, reason = name.partition("|")
            invalid.add_metric([key, reason], n)
        gaps = CounterMetricFamily(
            "wz_gateway_bus_gaps",
            "Gaps in a recovering subscription, re-fetched from the publishers' caches, per key",
            labels=["key"],
        )
        for key, n in snap.get("gaps", {}).items():
            gaps.add_metric([key], n)
        dropped = CounterMetricFamily(
            "wz_gateway_bus_dropped",
            "Samples a full ring dropped (the oldest first), per key: track batches of a flood",
            labels=["key"],
        )
        for key, n in snap.get("dropped", {}).items():
            dropped.add_metric([key], n)
        yield received
        yield invalid
        yield gaps
        yield dropped


class GatewayMetrics:
    """The counters, gauges and histograms the gateway exports on ``/metrics``."""

    def __init__(self) -> None:
        self.registry = CollectorRegistry()
        r = self.registry
        self.http_requests = Counter(
            "wz_gateway_http_requests",
            "HTTP requests by route template, method and status",
            ["route", "method", "status"],
            registry=r,
        )
        self.http_latency = Histogram(
            "wz_gateway_http_request_seconds",
            "HTTP request handling time",
            ["route"],
            buckets=(0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 10.0),
            registry=r,
        )
        self.auth_failures = Counter(
            "wz_gateway_auth_failures", "Requests refused: no or bad key", ["reason"], registry=r
        )
        self.rate_limited = Counter(
            "wz_gateway_rate_limited", "Requests refused with 429", registry=r
        )
        self.ingested = Counter(
            "wz_gateway_ingested_messages", "Bus messages stored, by kind", ["kind"], registry=r
        )
        self.ingested_points = Counter(
            "wz_gateway_ingested_track_points", "Track points stored", registry=r
        )
        self.duplicate_alerts = Counter(
            "wz_gateway_duplicate_alerts",
            "Alerts received again (same alert_id): not stored twice",
            registry=r,
        )
        self.write_errors = Counter(
            "wz_gateway_write_errors", "Groups of messages the database refused", registry=r
        )
        self.write_seconds = Histogram(
            "wz_gateway_write_seconds",
            "Time to store one group of messages",
            buckets=(0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 1.0),
            registry=r,
        )
        self.retention_deleted = Counter(
            "wz_gateway_retention_deleted", "Rows deleted by the retention", ["table"], registry=r
        )
        self.queue_depth = Gauge(
            "wz_gateway_write_queue_depth", "Messages waiting for the database writer", registry=r
        )
        self.smoothed_tracks = Counter(
            "wz_gateway_smoothed_tracks", "Ended track lives smoothed and stored", registry=r
        )
        self.smoothed_points = Counter(
            "wz_gateway_smoothed_track_points", "Smoothed track points stored", registry=r
        )
        self.smoothing_seconds = Histogram(
            "wz_gateway_smoothing_seconds",
            "Time to read, smooth and store one ended track",
            buckets=(0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 1.0),
            registry=r,
        )
        self.webhook_events = Counter(
            "wz_gateway_webhook_events",
            "Webhook events that reached a final state: delivered, "
            "failed (410 Gone, subscription disabled) or expired (past their time to live)",
            ["state"],
            registry=r,
        )
        self.webhook_attempts = Counter(
            "wz_gateway_webhook_attempts",
            "Webhook delivery attempts by answer: 2xx, 3xx, 4xx, "
            "5xx, or error (no answer: refused, timed out, address refused)",
            ["result"],
            registry=r,
        )
        self.webhook_attempt_seconds = Histogram(
            "wz_gateway_webhook_attempt_seconds",
            "Time of one webhook delivery attempt",
            buckets=(0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 10.0),
            registry=r,
        )
        self.webhook_pending = Gauge(
            "wz_gateway_webhook_pending", "Webhook events waiting to be delivered", registry=r
        )

    def watch_bus(self, snapshot: BusSnapshot) -> None:
        """Export the bus's counters (call once, with ``bus.stats.snapshot``)."""
        self.registry.register(_BusCollector(snapshot))

    def watch_queue(self, depth: Callable[[], int]) -> None:
        self.queue_depth.set_function(lambda: float(depth()))

    def watch_webhooks(self, pending: Callable[[], int]) -> None:
        """Export the outbox's pending events (read at scrape time; NaN if the database fails)."""

        def read() -> float:
            try:
                return float(pending())
            except Exception:  # a scrape must not fail because the database is busy
                return float("nan")

        self.webhook_pending.set_function(read)
