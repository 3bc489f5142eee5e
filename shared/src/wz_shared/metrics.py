"""Prometheus metrics of a service node, on its own port (``WZ_METRICS_PORT``).

Every node's :class:`~wz_shared.service.ServiceRuntime` serves them when the setting is given
(``wz up`` gives each service its own port, compose ``9464``); the gateway also has them on its
API's ``/metrics``. Names follow Prometheus' conventions (base units, ``_total`` counters):

- ``wz_bus_published_total{key}``, ``wz_bus_received_total{key}``: messages put and taken;
- ``wz_bus_dropped_total{key}``: samples a ring subscription dropped (a consumer behind);
- ``wz_bus_shed_total{key,reason}``: samples shed undecoded (``stale``, ``superseded``: a
  flood or a replay, :mod:`wz_shared.shedding`), by reason;
- ``wz_bus_invalid_total{key,reason}``: messages refused (undecodable, out of range, from the
  wrong source), by reason;
- ``wz_queue_depth{key}`` and ``wz_queue_capacity{key}``: each subscription's queue now;
- ``wz_processing_seconds`` (histogram): from a message's arrival in the service's queue to
  the end of its processing (queueing included);
- ``wz_loop_age_seconds``, ``wz_input_age_seconds``: since the loop last went round and since
  it last processed an input (``NaN`` before the first);
- ``wz_service_state{state}``: 1 for the current state (running, degraded, stalled...);
- ``wz_service_uptime_seconds``;
- ``wz_device_reachable{device,address}``: 1 if a field device it drives answers, 0 if not.

Each series carries ``service`` and ``site`` labels, so one Prometheus can scrape every
service of several trailers.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

from prometheus_client import CollectorRegistry, Histogram, start_http_server
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, Metric
from prometheus_client.registry import Collector

from wz_shared.messages import ServiceState

log = logging.getLogger(__name__)

#: Processing latency buckets [s]: a LiDAR frame's clustering (~10-60 ms) to a backlog.
LATENCY_BUCKETS_S = (0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0)


@dataclass(frozen=True)
class RuntimeView:
    """What the collector reads from the runtime at scrape time (callables: no copies kept)."""

    service: str
    site: str
    bus_snapshot: Callable[[], dict[str, dict[str, int]]]
    queue_depths: Callable[[], dict[str, tuple[int, int]]]
    loop_age_s: Callable[[], float | None]
    input_age_s: Callable[[], float | None]
    state: Callable[[], ServiceState]
    uptime_s: Callable[[], float]
    devices: Callable[[], dict[str, Any]]


class _RuntimeCollector(Collector):
    def __init__(self, view: RuntimeView) -> None:
        self.view = view

    def collect(self) -> Iterator[Metric]:
        v = self.view
        base = ["service", "site"]
        ids = [v.service, v.site]
        snap = v.bus_snapshot()
        for name, what, doc in (
            ("published", "published", "Messages put, per key"),
            ("received", "received", "Samples received, per key"),
            ("dropped", "dropped", "Samples a ring subscription dropped, per key"),
            ("gaps", "gaps", "Gaps a recovering subscription re-fetched, per key"),
        ):
            family = CounterMetricFamily(f"wz_bus_{name}", doc, labels=[*base, "key"])
            for key, n in snap.get(what, {}).items():
                family.add_metric([*ids, key], n)
            yield family
        for name, doc in (
            ("invalid", "Messages refused, per key and reason"),
            ("shed", "Samples shed before decoding (a flood, a replay), per key and reason"),
        ):
            family = CounterMetricFamily(f"wz_bus_{name}", doc, labels=[*base, "key", "reason"])
            for key_reason, n in snap.get(name, {}).items():
                key, _, reason = key_reason.partition("|")
                family.add_metric([*ids, key, reason], n)
            yield family
        depth = GaugeMetricFamily("wz_queue_depth", "Samples queued now", labels=[*base, "key"])
        capacity = GaugeMetricFamily(
            "wz_queue_capacity", "A subscription queue's capacity", labels=[*base, "key"]
        )
        for key, (pending, size) in v.queue_depths().items():
            depth.add_metric([*ids, key], pending)
            capacity.add_metric([*ids, key], size)
        yield depth
        yield capacity
        for name, value, doc in (
            ("wz_loop_age_seconds", v.loop_age_s(), "Since the service's loop last went round"),
            ("wz_input_age_seconds", v.input_age_s(), "Since it last processed an input"),
            ("wz_service_uptime_seconds", v.uptime_s(), "Since the service started"),
        ):
            gauge = GaugeMetricFamily(name, doc, labels=base)
            gauge.add_metric(ids, math.nan if value is None else value)
            yield gauge
        state = GaugeMetricFamily(
            "wz_service_state", "1 for the service's state now", labels=[*base, "state"]
        )
        now = v.state()
        for candidate in ServiceState:
            state.add_metric([*ids, candidate.value], 1.0 if candidate is now else 0.0)
        yield state
        reachable = GaugeMetricFamily(
            "wz_device_reachable",
            "1 if the field device answers, 0 if not (NaN: not contacted yet)",
            labels=[*base, "device", "address"],
        )
        for device, link in v.devices().items():
            value = math.nan if link.reachable is None else float(link.reachable)
            reachable.add_metric([*ids, device, link.address], value)
        yield reachable


class ServiceMetrics:
    """A service's registry: the runtime's figures and the processing-time histogram."""

    def __init__(self, view: RuntimeView) -> None:
        self.registry = CollectorRegistry(auto_describe=True)
        self.registry.register(_RuntimeCollector(view))
        self.processing = Histogram(
            "wz_processing_seconds",
            "From a message's arrival in the service's queue to the end of its processing",
            labelnames=["service", "site"],
            buckets=LATENCY_BUCKETS_S,
            registry=self.registry,
        ).labels(service=view.service, site=view.site)
        self._server: Any = None

    def serve(self, host: str, port: int) -> bool:
        """Serve ``/metrics`` on ``host:port`` (a daemon thread); False if it cannot listen
        (the service goes on without it, said in the log)."""
        try:
            self._server, _ = start_http_server(port, addr=host, registry=self.registry)
        except OSError as exc:
            log.error("cannot serve metrics on %s:%d: %s", host, port, exc)
            return False
        log.info("metrics on http://%s:%d/metrics", host, port)
        return True

    def close(self) -> None:
        if self._server is not None:
            self._server.shutdown()
            self._server.server_close()
            self._server = None
