"""Webhook delivery: a dispatcher thread takes due events from the outbox, a small pool of
threads POSTs them. What is due, the backoff, ``Retry-After``, expiry and 410 are decided by
the pure functions of :mod:`wz_gateway.webhooks`; this module does the I/O.

At least once. Each claim is a lease (``locked_until``, :attr:`GatewaySettings.webhook_lease_s`
ahead); the attempt's result is written in one transaction with its delivery log row. If the
gateway dies in between (``kill -9``, power cut) the row is due again when the lease runs out,
so an event whose 2xx was never recorded is sent again, with the same ``webhook-id``:
receivers drop ids they have seen.

One request in flight per subscription, several subscriptions at once
(``webhook_workers`` threads). A receiver that hangs holds one thread and delays only its
own events, never another subscriber's; and a small receiver is never sent more than one
request at a time by us (a subscription with a leased event waits, whichever process leased
it: after a crash, until that lease runs out). Events of one subscription go oldest first, but a retried event does
not hold up newer ones (the newest alert matters most), so receivers must not rely on order.

SSRF. Every new connection resolves the host, checks every address against the
:class:`~wz_gateway.webhooks.AddressPolicy`, then connects to a checked address (TLS still
verifies the host name): a name that resolved to a public address when the subscription was
made and to an internal one now (DNS rebinding) is refused at delivery time. Redirects are not
followed and proxies from the environment are not used.
"""

from __future__ import annotations

import ipaddress
import logging
import random
import socket
import threading
import time
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import httpcore
import httpx

from wz_gateway import webhooks
from wz_gateway.metrics import GatewayMetrics
from wz_gateway.settings import GatewaySettings
from wz_gateway.webhook_store import ClaimedEvent, WebhookStore

log = logging.getLogger(__name__)

#: ``resolve(host, port)``: the addresses a host name stands for (``getaddrinfo``).
Resolve = Callable[[str, int], list[str]]
#: Most of a receiver's answer read (for the delivery log); the rest is not waited for.
_ANSWER_EXCERPT_BYTES = 2048
_ERROR_CHARS = 500
_EXPIRY_SWEEP_S = 1.0


def resolve_host(host: str, port: int) -> list[str]:
    """The addresses of ``host`` (each once, in the resolver's order); an address literal is
    itself. ``OSError`` when it does not resolve."""
    infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    return list(dict.fromkeys(str(info[4][0]) for info in infos))


def address_policy(settings: GatewaySettings) -> webhooks.AddressPolicy:
    """Where webhooks may go under these settings (dev mode: this machine too)."""
    return webhooks.AddressPolicy(
        allow_private=settings.webhook_allow_private,
        allow_loopback=settings.dev_mode,
        allowed_networks=tuple(
            ipaddress.ip_network(n, strict=False) for n in settings.webhook_allowed_networks
        ),
    )


def check_url(url: str, policy: webhooks.AddressPolicy, resolve: Resolve = resolve_host) -> None:
    """Refuse a webhook URL the gateway would not call (scheme, credentials, addresses).

    Raises
    ------
    webhooks.RefusedDestinationError
        Saying why, for the person who gave the URL.
    """
    destination = webhooks.parse_destination(url)
    try:
        addresses = resolve(destination.host, destination.port)
    except (OSError, UnicodeError) as exc:  # UnicodeError: a label empty or over 63 characters
        raise webhooks.RefusedDestinationError(
            f"the host {destination.host} does not resolve ({exc})"
        ) from exc
    webhooks.check_addresses(destination.host, addresses, policy)


class _VettedBackend(httpcore.NetworkBackend):
    """httpcore's network layer, connecting only to addresses the policy allows."""

    def __init__(self, policy: webhooks.AddressPolicy, resolve: Resolve) -> None:
        self._policy = policy
        self._resolve = resolve
        self._inner = httpcore.SyncBackend()

    def connect_tcp(
        self,
        host: str,
        port: int,
        timeout: float | None = None,
        local_address: str | None = None,
        socket_options: Iterable[Any] | None = None,
    ) -> httpcore.NetworkStream:
        try:
            addresses = self._resolve(host, port)
        except OSError as exc:
            raise httpcore.ConnectError(f"{host} does not resolve: {exc}") from exc
        try:
            webhooks.check_addresses(host, addresses, self._policy)
        except webhooks.RefusedDestinationError as exc:
            raise httpcore.ConnectError(f"address refused: {exc}") from exc
        failure: Exception | None = None
        for address in addresses:  # the checked addresses, never the name again
            try:
                return self._inner.connect_tcp(
                    address, port, timeout, local_address, socket_options
                )
            except httpcore.ConnectError as exc:
                failure = exc
        assert failure is not None
        raise failure

    def connect_unix_socket(
        self, path: str, timeout: float | None = None, socket_options: Iterable[Any] | None = None
    ) -> httpcore.NetworkStream:
        raise httpcore.ConnectError("webhooks are not sent to Unix sockets")

    def sleep(self, seconds: float) -> None:
        time.sleep(seconds)


class _VettedTransport(httpx.HTTPTransport):
    """httpx's transport on a connection pool whose connections go through the policy."""

    def __init__(self, policy: webhooks.AddressPolicy, resolve: Resolve, connections: int) -> None:
        super().__init__(trust_env=False)
        self._pool = httpcore.ConnectionPool(
            ssl_context=httpx.create_ssl_context(trust_env=False),
            max_connections=connections,
            max_keepalive_connections=connections,
            keepalive_expiry=5.0,
            network_backend=_VettedBackend(policy, resolve),
        )


def vetted_client(
    policy: webhooks.AddressPolicy,
    *,
    timeout_s: float,
    connections: int = 16,
    resolve: Resolve = resolve_host,
) -> httpx.Client:
    """An HTTP client for webhooks: checked addresses, no redirects, no proxies from the
    environment, ``timeout_s`` for the connection, the sending and each read."""
    return httpx.Client(
        transport=_VettedTransport(policy, resolve, connections),
        timeout=httpx.Timeout(timeout_s),
        follow_redirects=False,
        trust_env=False,
    )


def _result_label(status_code: int | None) -> str:
    return "error" if status_code is None else f"{min(max(status_code // 100, 1), 5)}xx"


class WebhookDeliverer:
    """Delivers the outbox: :meth:`start` the dispatcher, :meth:`wake` it when events were
    stored, :meth:`close` at exit.

    Parameters
    ----------
    store : WebhookStore
    settings : GatewaySettings
        Timeouts, lease, backoff, time to live, workers, address policy.
    metrics : GatewayMetrics, optional
    clock : callable
        Wall clock [Unix s] (the outbox's times and the signatures' timestamps).
    rng : random.Random, optional
        The backoff's jitter (seed it in tests); a fresh one by default.
    resolve : callable
        Host name to addresses; ``getaddrinfo`` by default.
    """

    def __init__(
        self,
        store: WebhookStore,
        settings: GatewaySettings,
        metrics: GatewayMetrics | None = None,
        *,
        clock: Callable[[], float] = time.time,
        rng: random.Random | None = None,
        resolve: Resolve = resolve_host,
    ) -> None:
        # httpx logs each request at INFO; the line per attempt below says more.
        logging.getLogger("httpx").setLevel(logging.WARNING)
        self.store = store
        self.settings = settings
        self.metrics = metrics
        self.clock = clock
        self.policy = webhooks.RetryPolicy(
            backoff_base_s=settings.webhook_backoff_base_s,
            backoff_cap_s=settings.webhook_backoff_cap_s,
            event_ttl_s=settings.webhook_event_ttl_s,
        )
        self._rng = rng if rng is not None else random.Random()
        self._rng_lock = threading.Lock()
        self._client = vetted_client(
            address_policy(settings),
            timeout_s=settings.webhook_timeout_s,
            connections=2 * settings.webhook_workers,
            resolve=resolve,
        )
        self._pool = ThreadPoolExecutor(settings.webhook_workers, thread_name_prefix="webhook")
        self._busy: set[int] = set()  # subscription rows with an attempt in flight
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._next_sweep = 0.0

    # --- the dispatcher -------------------------------------------------------------------

    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name="webhooks", daemon=True)
        self._thread.start()

    def wake(self) -> None:
        """Look at the outbox now (events were just stored)."""
        self._wake.set()

    def close(self, timeout_s: float = 10.0) -> None:
        """Stop claiming, let the attempts in flight finish (their leases cover the rest)."""
        self._stop.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout_s)
        self._pool.shutdown(wait=True, cancel_futures=True)
        self._client.close()

    def _run(self) -> None:
        log.info(
            "webhook delivery: %d workers, time to live %.0f s, lease %.0f s",
            self.settings.webhook_workers,
            self.policy.event_ttl_s,
            self.settings.webhook_lease_s,
        )
        while not self._stop.is_set():
            self._wake.clear()  # before looking: a wake during the look is not lost
            try:
                self.dispatch()
            except Exception:  # the database refused: the next round tries again
                log.exception("webhook dispatch failed; trying again")
            self._wake.wait(self.settings.webhook_poll_interval_s)

    def dispatch(self) -> int:
        """Expire overdue events (at most once a second), claim what is due for the free
        subscriptions and hand each to the pool; the number handed out."""
        now = self.clock()
        if now >= self._next_sweep:
            self._next_sweep = now + _EXPIRY_SWEEP_S
            expired = self.store.expire_overdue(now, self.policy.event_ttl_s)
            if expired:
                log.warning(
                    "%d webhook events expired undelivered (time to live %.0f s)",
                    expired,
                    self.policy.event_ttl_s,
                )
                self._count_final({"expired": expired})
        with self._lock:
            busy = set(self._busy)
        claimed = self.store.claim(
            now,
            lease_until=now + self.settings.webhook_lease_s,
            limit=self.settings.webhook_workers - len(busy),
            busy=busy,
        )
        for event in claimed:
            with self._lock:
                self._busy.add(event.subscription_row)
            self._pool.submit(self._attempt_then_free, event)
        return len(claimed)

    def _attempt_then_free(self, event: ClaimedEvent) -> None:
        try:
            self.attempt(event)
        except Exception:  # its lease runs out and it is tried again
            log.exception(
                "webhook attempt for %s (%s) failed", event.event_id, event.subscription_id
            )
        finally:
            with self._lock:
                self._busy.discard(event.subscription_row)
            self._wake.set()  # the subscription's next event may go now

    # --- one attempt ----------------------------------------------------------------------

    def attempt(self, event: ClaimedEvent) -> webhooks.Outcome:
        """Send a claimed event once and record the result; its outcome."""
        started_at = self.clock()
        if webhooks.is_expired(event.created_at, started_at, self.policy):
            reason = f"not delivered within its time to live ({self.policy.event_ttl_s:.0f} s)"
            if self.store.expire(event.outbox_id, started_at, reason):
                self._count_final({"expired": 1})
            return webhooks.Outcome("expired", reason=reason)
        headers = webhooks.delivery_headers(
            event.signing_secrets, event.event_id, int(started_at), event.body
        )
        status_code: int | None = None
        retry_after: str | None = None
        error: str | None = None
        started = time.perf_counter()
        try:
            with self._client.stream(
                "POST", event.url, content=event.body.encode("utf-8"), headers=headers
            ) as response:
                status_code = response.status_code
                retry_after = response.headers.get("retry-after")
                excerpt = bytearray()
                for chunk in response.iter_bytes():
                    excerpt += chunk
                    if len(excerpt) >= _ANSWER_EXCERPT_BYTES:
                        break
            if not 200 <= status_code < 300:
                text = bytes(excerpt[:200]).decode("utf-8", "replace").strip()
                error = f"HTTP {status_code}" + (f": {text}" if text else "")
        except httpx.HTTPError as exc:
            error = f"{type(exc).__name__}: {exc}"[:_ERROR_CHARS]
        duration_s = time.perf_counter() - started
        now = self.clock()
        with self._rng_lock:
            outcome = webhooks.decide(
                attempt=event.attempts + 1,
                status_code=status_code,
                retry_after=retry_after,
                created_at=event.created_at,
                now=now,
                policy=self.policy,
                rng=self._rng,
            )
        finished = self.store.record_attempt(
            event,
            attempt=event.attempts + 1,
            attempted_at=started_at,
            status_code=status_code,
            error=None if error is None else error[:_ERROR_CHARS],
            duration_ms=1e3 * duration_s,
            outcome=outcome,
            now=now,
        )
        if self.metrics is not None:
            self.metrics.webhook_attempts.labels(_result_label(status_code)).inc()
            self.metrics.webhook_attempt_seconds.observe(duration_s)
        self._count_final(finished)
        self._log(event, outcome, error, duration_s)
        return outcome

    def _count_final(self, finished: dict[str, int]) -> None:
        if self.metrics is not None:
            for state, n in finished.items():
                self.metrics.webhook_events.labels(state).inc(n)

    def _log(
        self, event: ClaimedEvent, outcome: webhooks.Outcome, error: str | None, duration_s: float
    ) -> None:
        where = f"{event.event_type} {event.event_id} to {event.subscription_id}"
        attempt = event.attempts + 1
        if outcome.state == "delivered":
            log.info("webhook %s delivered (attempt %d, %.1f ms)", where, attempt, 1e3 * duration_s)
        elif outcome.state == "pending":
            assert outcome.next_attempt_at is not None
            log.info(
                "webhook %s attempt %d failed (%s); next in %.1f s",
                where,
                attempt,
                error,
                outcome.next_attempt_at - self.clock(),
            )
        else:
            log.warning(
                "webhook %s %s after %d attempts: %s", where, outcome.state, attempt, outcome.reason
            )
