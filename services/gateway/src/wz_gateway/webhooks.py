"""Signed webhooks without I/O: the events, their signatures, who gets which event, when to try
again, and which addresses may be called.

Each event is POSTed as JSON with the headers of the Standard Webhooks specification
(https://www.standardwebhooks.com)::

    webhook-id: msg_5f1c0a...          the event's id: the same on every attempt
    webhook-timestamp: 1750000000      when this attempt was signed [s since the epoch]
    webhook-signature: v1,<base64>     HMAC-SHA256 of "{id}.{timestamp}.{body}"

keyed with the subscription's secret ``whsec_<base64 of the key>`` (during a rotation the old
and the new secret each sign, space-separated). The body::

    {"type": "alert.speeding", "timestamp": "2025-06-15T14:26:40.123Z",
     "data": {...the Alert as the bus carries it, its site included...}}

Delivery is at least once: a receiver keeps the ``webhook-id`` values it has processed and
drops a repeat (the same event comes again when its 2xx was lost, or when the gateway died
between sending and recording it).

Retries: full-jitter exponential backoff, the n-th retry waits a uniform draw from
``[0, min(cap, base * 2^(n-1))]``, except after a 429 or 503 that says ``Retry-After``, which
is honoured as given. 410 Gone disables the subscription. An event not delivered within its
time to live (from its creation) expires: for safety alerts, late is as bad as never.
"""

from __future__ import annotations

import base64
import binascii
import datetime
import email.utils
import hashlib
import hmac
import ipaddress
import json
import random
import re
import secrets
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal
from urllib.parse import urlsplit

from wz_shared.messages import Alert, AlertPhase, AlertSeverity, AlertType

SECRET_PREFIX = "whsec_"
#: Bytes of a new signing key (192 bits; the specification asks for 24 to 64).
SECRET_KEY_BYTES = 24
ALERT_EVENT_PREFIX = "alert."
#: Every alert type as an event type, and the pattern for all of them.
ALERT_EVENT_TYPES: tuple[str, ...] = tuple(f"{ALERT_EVENT_PREFIX}{t.value}" for t in AlertType)
ALL_ALERTS = "alert.*"
#: What ``POST /v1/webhooks/{id}/test`` sends, whatever the subscription's filters.
TEST_EVENT_TYPE = "webhook.test"
SEVERITY_RANK: dict[AlertSeverity, int] = {
    AlertSeverity.INFO: 0,
    AlertSeverity.WARNING: 1,
    AlertSeverity.CRITICAL: 2,
}
EventState = Literal["pending", "delivered", "failed", "expired"]
Address = ipaddress.IPv4Address | ipaddress.IPv6Address
Network = ipaddress.IPv4Network | ipaddress.IPv6Network


# --- events -------------------------------------------------------------------------------


@dataclass(frozen=True)
class WebhookEvent:
    """One event as it is stored in the outbox and sent: ``body`` is signed byte for byte."""

    event_id: str
    event_type: str
    body: str


def iso_timestamp(unix_s: float) -> str:
    """``2025-06-15T14:26:40.123Z`` for a wall-clock time [s since the epoch]."""
    when = datetime.datetime.fromtimestamp(unix_s, datetime.UTC)
    return when.isoformat(timespec="milliseconds").replace("+00:00", "Z")


def _body(event_type: str, created_at: float, data: dict[str, object]) -> str:
    payload = {"type": event_type, "timestamp": iso_timestamp(created_at), "data": data}
    return json.dumps(payload, separators=(",", ":"))  # ASCII: the bytes sent are the str's


def alert_event_id(alert: Alert) -> str:
    """The webhook id of an alert event: derived from its site and ``alert_id`` (one id per
    episode and event of the episode), so a repeat of the same alert gets the same id."""
    digest = hashlib.sha256(f"alert:{alert.site}:{alert.alert_id}".encode()).hexdigest()
    return f"msg_{digest[:32]}"


def alert_event(alert: Alert, created_at: float) -> WebhookEvent:
    """The event ``alert.<alert_type>`` for an alert the gateway received at ``created_at``."""
    event_type = f"{ALERT_EVENT_PREFIX}{alert.alert_type.value}"
    return WebhookEvent(
        alert_event_id(alert),
        event_type,
        _body(event_type, created_at, alert.model_dump(mode="json")),
    )


def make_test_event(site: str, subscription_id: str, created_at: float, nonce: str) -> WebhookEvent:
    """A ``webhook.test`` event for one subscription; ``nonce`` (hex) makes its id unique."""
    data: dict[str, object] = {
        "site": site,
        "subscription_id": subscription_id,
        "description": "a test event from the work-zone gateway: no alert happened",
    }
    return WebhookEvent(
        f"msg_test_{nonce}", TEST_EVENT_TYPE, _body(TEST_EVENT_TYPE, created_at, data)
    )


# --- subscriptions ------------------------------------------------------------------------


def normalize_event_types(values: Sequence[str]) -> list[str]:
    """The event types a subscription asks for, checked, each once, in the order given.

    Raises
    ------
    ValueError
        For an empty list or an unknown type, naming the known ones.
    """
    known = (ALL_ALERTS, *ALERT_EVENT_TYPES)
    if not values:
        raise ValueError(f"give at least one event type: {', '.join(known)}")
    for value in values:
        if value not in known:
            raise ValueError(f"unknown event type {value!r}; known: {', '.join(known)}")
    return list(dict.fromkeys(values))


@dataclass(frozen=True)
class SubscriptionFilter:
    """Which alerts a subscription gets: its event types (``alert.*`` for all), the lowest
    severity (None: any) and the episode phases (empty: every phase)."""

    event_types: tuple[str, ...]
    min_severity: AlertSeverity | None = None
    phases: tuple[AlertPhase, ...] = ()

    def matches(self, alert: Alert) -> bool:
        event_type = f"{ALERT_EVENT_PREFIX}{alert.alert_type.value}"
        if ALL_ALERTS not in self.event_types and event_type not in self.event_types:
            return False
        if (
            self.min_severity is not None
            and SEVERITY_RANK[alert.severity] < SEVERITY_RANK[self.min_severity]
        ):
            return False
        return not self.phases or alert.phase in self.phases


# --- signatures ---------------------------------------------------------------------------


def new_secret(key: bytes | None = None) -> str:
    """A signing secret ``whsec_<base64>`` of ``key`` (by default 24 random bytes)."""
    key = secrets.token_bytes(SECRET_KEY_BYTES) if key is None else key
    return SECRET_PREFIX + base64.b64encode(key).decode("ascii")


def secret_key(secret: str) -> bytes:
    """The HMAC key of a ``whsec_`` secret; ``ValueError`` if it is not one."""
    if not secret.startswith(SECRET_PREFIX):
        raise ValueError(f"a webhook secret starts with {SECRET_PREFIX!r}")
    try:
        key = base64.b64decode(secret.removeprefix(SECRET_PREFIX), validate=True)
    except binascii.Error as exc:
        raise ValueError("a webhook secret is whsec_ and base64") from exc
    if not key:
        raise ValueError("a webhook secret may not be empty")
    return key


def sign(secret: str, webhook_id: str, timestamp_s: int, body: str) -> str:
    """``v1,<signature>`` of one message under one secret.

    signature = base64(HMAC-SHA256(key, "{webhook_id}.{timestamp_s}.{body}"))
    """
    signed = f"{webhook_id}.{timestamp_s}.{body}".encode()
    digest = hmac.new(secret_key(secret), signed, hashlib.sha256).digest()
    return "v1," + base64.b64encode(digest).decode("ascii")


def delivery_headers(
    signing_secrets: Sequence[str], webhook_id: str, timestamp_s: int, body: str
) -> dict[str, str]:
    """The request headers of one attempt; one signature per secret, space-separated."""
    return {
        "content-type": "application/json",
        "user-agent": "wz-gateway-webhooks/1",
        "webhook-id": webhook_id,
        "webhook-timestamp": str(timestamp_s),
        "webhook-signature": " ".join(
            sign(s, webhook_id, timestamp_s, body) for s in signing_secrets
        ),
    }


# --- when to try again --------------------------------------------------------------------


@dataclass(frozen=True)
class RetryPolicy:
    """Backoff ``base`` and ``cap`` [s]; an event's time to live from its creation [s]."""

    backoff_base_s: float = 1.0
    backoff_cap_s: float = 300.0
    event_ttl_s: float = 900.0


@dataclass(frozen=True)
class Outcome:
    """What follows an attempt: the event's new state, and for ``pending`` when to try again.

    ``disable_subscription``: the receiver answered 410 Gone. ``defer_subscription_until``:
    it asked (``Retry-After``) not to be called before then, for any event.
    """

    state: EventState
    next_attempt_at: float | None = None
    reason: str = ""
    disable_subscription: bool = False
    defer_subscription_until: float | None = None


def backoff_ceiling_s(attempt: int, policy: RetryPolicy) -> float:
    """Longest wait after the ``attempt``-th failed attempt (1 the first): base * 2^(n-1),
    at most the cap."""
    exponent = min(max(attempt, 1) - 1, 62)  # 2^62 s is past any cap
    return min(policy.backoff_cap_s, policy.backoff_base_s * 2.0**exponent)


def backoff_s(attempt: int, policy: RetryPolicy, rng: random.Random) -> float:
    """Full jitter: a uniform draw from [0, ceiling]; spreads the retries of many events (and
    of several gateways) so that a receiver coming back is not hit by all of them at once."""
    return rng.uniform(0.0, backoff_ceiling_s(attempt, policy))


_DELAY_SECONDS = re.compile(r"[0-9]{1,10}")


def parse_retry_after(value: str | None, now: float) -> float | None:
    """Seconds to wait as a ``Retry-After`` header says (RFC 9110 10.2.3): a number of seconds
    or an HTTP date (``Wed, 21 Oct 2015 07:28:00 GMT``); a date in the past is 0. None when
    there is no header or it reads as neither."""
    if value is None:
        return None
    text = value.strip()
    if _DELAY_SECONDS.fullmatch(text):
        return float(text)
    try:
        when = email.utils.parsedate_to_datetime(text)
    except (TypeError, ValueError, IndexError):
        return None
    if when.tzinfo is None:  # "-0000": UTC by the RFC
        when = when.replace(tzinfo=datetime.UTC)
    return max(0.0, when.timestamp() - now)


def expires_at(created_at: float, policy: RetryPolicy) -> float:
    return created_at + policy.event_ttl_s


def is_expired(created_at: float, now: float, policy: RetryPolicy) -> bool:
    """Whether an event created at ``created_at`` is past its time to live at ``now``."""
    return now >= expires_at(created_at, policy)


def decide(
    *,
    attempt: int,
    status_code: int | None,
    retry_after: str | None,
    created_at: float,
    now: float,
    policy: RetryPolicy,
    rng: random.Random,
) -> Outcome:
    """The outcome of the ``attempt``-th attempt (1 the first) that ended at ``now``.

    ``status_code`` None: no answer (refused connection, timeout, refused address). 2xx is
    delivered; 410 fails the event and disables the subscription; anything else is tried
    again after the backoff, or after ``Retry-After`` on a 429 or 503, unless that would be
    after the event expires.
    """
    if status_code is not None and 200 <= status_code < 300:
        return Outcome("delivered", reason=f"HTTP {status_code}")
    if status_code == 410:
        return Outcome(
            "failed",
            reason="the receiver answered 410 Gone: subscription disabled",
            disable_subscription=True,
        )
    delay_s = backoff_s(attempt, policy, rng)
    reason = "no answer" if status_code is None else f"HTTP {status_code}"
    defer_until = None
    if status_code in (429, 503):
        asked_s = parse_retry_after(retry_after, now)
        if asked_s is not None:
            delay_s = asked_s
            defer_until = now + asked_s
            reason += f", Retry-After {asked_s:.0f} s"
    next_attempt_at = now + delay_s
    if next_attempt_at >= expires_at(created_at, policy):
        return Outcome(
            "expired",
            reason=f"{reason}; the next attempt would come after the "
            f"event's time to live ({policy.event_ttl_s:.0f} s)",
        )
    return Outcome("pending", next_attempt_at, reason=reason, defer_subscription_until=defer_until)


# --- which addresses may be called (SSRF) --------------------------------------------------


class RefusedDestinationError(ValueError):
    """A webhook URL the gateway will not call: its scheme, or where its host resolves."""


_NAT64 = ipaddress.ip_network("64:ff9b::/96")
_DESCRIBED = {
    "unspecified": "the unspecified address",
    "not globally routable": "not a globally routable address",
}


def _translated_ipv4(ip: ipaddress.IPv6Address) -> ipaddress.IPv4Address | None:
    """The IPv4 address an IPv6 address stands for: IPv4-mapped (``::ffff:a.b.c.d``) or NAT64
    (``64:ff9b::a.b.c.d``, what DNS64 gives on an IPv6-only network)."""
    if ip.ipv4_mapped is not None:
        return ip.ipv4_mapped
    if ip in _NAT64:
        return ipaddress.IPv4Address(int(ip) & 0xFFFFFFFF)
    return None


def address_class(ip: Address) -> str | None:
    """Why ``ip`` is not a public unicast address (``loopback``, ``private``, ``link-local``,
    ``multicast``, ``reserved``, ``unspecified``, ``not globally routable``), or None.

    An IPv4-mapped or NAT64 address is judged as the IPv4 address it stands for; a 6to4 one
    (``2002:a.b.c.d::``) by the IPv4 address it tunnels to as well as by itself.
    """
    if isinstance(ip, ipaddress.IPv6Address):
        translated = _translated_ipv4(ip)
        if translated is not None:
            return address_class(translated)
        if ip.sixtofour is not None and (reason := address_class(ip.sixtofour)) is not None:
            return reason
    checks = (
        ("unspecified", ip.is_unspecified),
        ("loopback", ip.is_loopback),
        ("link-local", ip.is_link_local),
        ("multicast", ip.is_multicast),
        ("reserved", ip.is_reserved),
        ("private", ip.is_private),
        ("not globally routable", not ip.is_global),
    )
    return next((name for name, applies in checks if applies), None)


@dataclass(frozen=True)
class AddressPolicy:
    """Which addresses webhooks may be sent to: public ones, plus

    - ``allowed_networks``: these networks, whatever they are (a receiver on the site LAN);
    - ``allow_loopback``: this machine (dev mode);
    - ``allow_private``: any unicast address (a closed network where every host is trusted).
    """

    allow_private: bool = False
    allow_loopback: bool = False
    allowed_networks: tuple[Network, ...] = ()

    def refusal(self, ip: Address) -> str | None:
        """Why ``ip`` may not be called, or None if it may."""
        kind = address_class(ip)
        if kind is None:
            return None
        candidates: list[Address] = [ip]
        if isinstance(ip, ipaddress.IPv6Address) and ip.ipv4_mapped is not None:
            candidates.append(ip.ipv4_mapped)
        if any(
            a in net
            for a in candidates
            for net in self.allowed_networks
            if a.version == net.version
        ):
            return None
        if kind == "loopback" and self.allow_loopback:
            return None
        if self.allow_private and kind not in ("unspecified", "multicast"):
            return None
        return f"{ip} is {_DESCRIBED.get(kind, f'a {kind} address')}"


@dataclass(frozen=True)
class Destination:
    scheme: Literal["http", "https"]
    host: str
    port: int


def parse_destination(url: str) -> Destination:
    """Scheme, host and port of a webhook URL.

    Raises
    ------
    RefusedDestinationError
        For a scheme other than http or https, no host, a bad port, or credentials in the URL
        (they would be stored and listed in clear: use the signature to authenticate us).
    """
    try:
        parts = urlsplit(url.strip())
        port = parts.port
    except ValueError as exc:
        raise RefusedDestinationError(f"not a valid URL: {exc}") from exc
    scheme = parts.scheme.lower()
    if scheme not in ("http", "https"):
        raise RefusedDestinationError(
            f"the URL must be http:// or https://, not {scheme or 'none'}"
        )
    if not parts.hostname:
        raise RefusedDestinationError("the URL has no host")
    if parts.username is not None or parts.password is not None:
        raise RefusedDestinationError(
            "put no user or password in the URL; receivers check the signature instead"
        )
    default_port = 443 if scheme == "https" else 80
    return Destination(
        "https" if scheme == "https" else "http",
        parts.hostname,
        port if port is not None else default_port,
    )


def check_addresses(host: str, addresses: Sequence[str], policy: AddressPolicy) -> None:
    """Refuse a host unless every address it resolves to may be called.

    Every address, not just one: a name that resolves to a public and a private address
    would otherwise let the connection land on the private one.

    Raises
    ------
    RefusedDestinationError
        Naming the first address refused and why.
    """
    if not addresses:
        raise RefusedDestinationError(f"{host} resolves to no address")
    for text in addresses:
        try:
            ip = ipaddress.ip_address(text)
        except ValueError as exc:
            raise RefusedDestinationError(f"{host} resolves to {text!r}, not an address") from exc
        reason = policy.refusal(ip)
        if reason is not None:
            raise RefusedDestinationError(
                f"{host} resolves to {reason}; webhooks go to public addresses only unless "
                "WZ_GATEWAY_WEBHOOK_ALLOWED_NETWORKS (CIDRs) or WZ_GATEWAY_WEBHOOK_ALLOW_PRIVATE "
                "allows it"
            )
