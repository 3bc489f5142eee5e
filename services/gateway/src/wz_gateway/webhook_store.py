"""The webhooks' part of the data layer: subscriptions, the outbox and the delivery log.

Events are written to the outbox in the transaction that stores their cause
(:func:`enqueue_alert`, called by :meth:`Storage.ingest <wz_gateway.storage.Storage.ingest>`),
so an alert is never stored without its events nor the reverse. One row per event and
subscription (a unique index): an event enqueued twice is written once.

Claims are leases: :meth:`WebhookStore.claim` sets ``locked_until`` on the rows it hands out;
the attempt's result clears it. A row claimed by a process that died keeps its lease until it
runs out, then is due again: delivery is at least once, and receivers drop a repeated
``webhook-id``.
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass
from typing import Any

from sqlalchemy import Connection, Engine, and_, delete, func, insert, or_, select, update
from sqlalchemy.dialects import postgresql, sqlite

from wz_gateway import webhooks
from wz_gateway.models import WebhookEventInfo, WebhookInfo
from wz_gateway.tables import webhook_deliveries, webhook_outbox, webhook_subscriptions
from wz_shared.messages import Alert, AlertSeverity

_DISABLED_EVENT_ERROR = "subscription disabled"


@dataclass(frozen=True)
class ClaimedEvent:
    """An outbox row handed to one attempt, with what sending it needs."""

    outbox_id: int
    event_id: str
    event_type: str
    body: str
    created_at: float
    #: Attempts made before this one.
    attempts: int
    subscription_row: int
    subscription_id: str
    url: str
    #: The current secret, then the previous one while its grace period lasts.
    signing_secrets: tuple[str, ...]


def _insert_ignoring_duplicates(connection: Connection, rows: list[dict[str, Any]]) -> int:
    module = sqlite if connection.dialect.name == "sqlite" else postgresql
    stmt = module.insert(webhook_outbox).on_conflict_do_nothing(
        index_elements=[webhook_outbox.c.subscription_id, webhook_outbox.c.event_id]
    )
    written = 0
    for row in rows:  # one by one: RETURNING tells whether each went in
        outcome = connection.execute(stmt.values(**row).returning(webhook_outbox.c.id))
        written += outcome.first() is not None
    return written


def _filter_of(row: Any) -> webhooks.SubscriptionFilter:
    return webhooks.SubscriptionFilter(
        event_types=tuple(row.event_types),
        min_severity=None if row.min_severity is None else AlertSeverity(row.min_severity),
        phases=tuple(row.phases or ()),
    )


def enqueue_alert(connection: Connection, alert: Alert, received_at: float) -> int:
    """Add the alert's event for every active subscription that wants it, in the caller's
    transaction; the rows written (0 for an event already there)."""
    s = webhook_subscriptions.c
    subscriptions = connection.execute(
        select(s.id, s.event_types, s.min_severity, s.phases).where(s.disabled_at.is_(None))
    ).all()
    wanted = [row.id for row in subscriptions if _filter_of(row).matches(alert)]
    if not wanted:
        return 0
    event = webhooks.alert_event(alert, received_at)
    return _insert_ignoring_duplicates(
        connection,
        [
            {
                "event_id": event.event_id,
                "subscription_id": row_id,
                "event_type": event.event_type,
                "payload": event.body,
                "created_at": received_at,
                "next_attempt_at": received_at,
                "attempts": 0,
                "state": "pending",
            }
            for row_id in wanted
        ],
    )


def _info(row: Any) -> WebhookInfo:
    return WebhookInfo(
        subscription_id=row.subscription_id,
        url=row.url,
        event_types=list(row.event_types),
        min_severity=row.min_severity,
        phases=row.phases,
        description=row.description,
        created_at=row.created_at,
        disabled_at=row.disabled_at,
        disabled_reason=row.disabled_reason,
        previous_secret_until=row.previous_secret_until,
    )


class WebhookStore:
    """Subscriptions, outbox and delivery log on the gateway's database (thread-safe: each call
    takes its own connection)."""

    def __init__(self, engine: Engine) -> None:
        self.engine = engine

    # --- subscriptions --------------------------------------------------------------------

    def create(
        self,
        *,
        subscription_id: str,
        url: str,
        secret: str,
        event_types: list[str],
        min_severity: str | None,
        phases: list[str] | None,
        description: str,
        now: float,
    ) -> WebhookInfo:
        with self.engine.begin() as connection:
            connection.execute(
                insert(webhook_subscriptions).values(
                    subscription_id=subscription_id,
                    url=url,
                    secret=secret,
                    event_types=event_types,
                    min_severity=min_severity,
                    phases=phases or None,
                    description=description,
                    created_at=now,
                )
            )
        found = self.get(subscription_id)
        assert found is not None
        return found

    def subscriptions(self) -> list[WebhookInfo]:
        stmt = select(webhook_subscriptions).order_by(webhook_subscriptions.c.id)
        with self.engine.connect() as connection:
            return [_info(row) for row in connection.execute(stmt)]

    def get(self, subscription_id: str) -> WebhookInfo | None:
        stmt = select(webhook_subscriptions).where(
            webhook_subscriptions.c.subscription_id == subscription_id
        )
        with self.engine.connect() as connection:
            row = connection.execute(stmt).first()
        return None if row is None else _info(row)

    def delete(self, subscription_id: str) -> bool:
        """Delete a subscription with its outbox rows and delivery log; False if unknown."""
        s = webhook_subscriptions.c
        with self.engine.begin() as connection:
            row_id = connection.scalar(select(s.id).where(s.subscription_id == subscription_id))
            if row_id is None:
                return False
            # Explicitly, not only by the foreign keys' cascade (SQLite's is off unless asked).
            o, d = webhook_outbox.c, webhook_deliveries.c
            outbox_ids = select(o.id).where(o.subscription_id == row_id)
            connection.execute(delete(webhook_deliveries).where(d.outbox_id.in_(outbox_ids)))
            connection.execute(delete(webhook_outbox).where(o.subscription_id == row_id))
            connection.execute(delete(webhook_subscriptions).where(s.id == row_id))
        return True

    def rotate_secret(
        self, subscription_id: str, secret: str, *, now: float, grace_s: float
    ) -> WebhookInfo | None:
        """Sign with ``secret`` from now on, and with the old one too for ``grace_s``."""
        s = webhook_subscriptions.c
        with self.engine.begin() as connection:
            outcome = connection.execute(
                update(webhook_subscriptions)
                .where(s.subscription_id == subscription_id)
                .values(
                    previous_secret=s.secret, previous_secret_until=now + grace_s, secret=secret
                )
            )
        return self.get(subscription_id) if outcome.rowcount else None

    def enqueue(self, subscription_id: str, event: webhooks.WebhookEvent, now: float) -> bool:
        """Add one event for one subscription (the test event); False if there is no such
        active subscription."""
        s = webhook_subscriptions.c
        with self.engine.begin() as connection:
            row_id = connection.scalar(
                select(s.id).where(s.subscription_id == subscription_id, s.disabled_at.is_(None))
            )
            if row_id is None:
                return False
            _insert_ignoring_duplicates(
                connection,
                [
                    {
                        "event_id": event.event_id,
                        "subscription_id": row_id,
                        "event_type": event.event_type,
                        "payload": event.body,
                        "created_at": now,
                        "next_attempt_at": now,
                        "attempts": 0,
                        "state": "pending",
                    }
                ],
            )
        return True

    def events(self, subscription_id: str, *, limit: int = 100) -> list[WebhookEventInfo]:
        """The subscription's newest outbox rows, newest first."""
        o, s = webhook_outbox.c, webhook_subscriptions.c
        stmt = (
            select(webhook_outbox)
            .join(webhook_subscriptions, o.subscription_id == s.id)
            .where(s.subscription_id == subscription_id)
            .order_by(o.id.desc())
            .limit(limit)
        )
        with self.engine.connect() as connection:
            rows = connection.execute(stmt).all()
        return [
            WebhookEventInfo(
                event_id=row.event_id,
                event_type=row.event_type,
                state=row.state,
                attempts=row.attempts,
                created_at=row.created_at,
                next_attempt_at=row.next_attempt_at if row.state == "pending" else None,
                finished_at=row.finished_at,
                last_status_code=row.last_status_code,
                last_error=row.last_error,
            )
            for row in rows
        ]

    # --- the delivery's side --------------------------------------------------------------

    def claim(
        self, now: float, *, lease_until: float, limit: int, busy: Collection[int] = ()
    ) -> list[ClaimedEvent]:
        """Lease up to ``limit`` due events, at most one per subscription, none of a
        subscription in ``busy`` (row ids) or with an event leased now, oldest due first.

        Due: pending, ``next_attempt_at`` reached, not leased (or the lease ran out), of an
        active subscription. The lease is taken by one UPDATE that checks again that the row
        is free, so two claimers never get the same row.
        """
        if limit <= 0:
            return []
        o, s = webhook_outbox.c, webhook_subscriptions.c
        free = or_(o.locked_until.is_(None), o.locked_until <= now)
        due = and_(o.state == "pending", o.next_attempt_at <= now, free)
        # A subscription with a row leased (by any process) has its request in flight.
        leased = webhook_outbox.alias("leased")
        in_flight = (
            select(leased.c.id)
            .where(
                leased.c.subscription_id == o.subscription_id,
                leased.c.state == "pending",
                leased.c.locked_until > now,
            )
            .exists()
        )
        # Each subscription's first due row (however long another one's backlog is).
        ranked = (
            select(
                o.id,
                o.next_attempt_at,
                func.row_number()
                .over(partition_by=o.subscription_id, order_by=(o.next_attempt_at, o.id))
                .label("rank"),
            )
            .join(webhook_subscriptions, o.subscription_id == s.id)
            .where(due, s.disabled_at.is_(None), ~in_flight)
        )
        if busy:
            ranked = ranked.where(o.subscription_id.not_in(list(busy)))
        firsts = ranked.subquery()
        candidates = (
            select(firsts.c.id)
            .where(firsts.c.rank == 1)
            .order_by(firsts.c.next_attempt_at, firsts.c.id)
            .limit(limit)
        )
        with self.engine.begin() as connection:
            picked = list(connection.scalars(candidates))
            if not picked:
                return []
            claimed = (
                connection.execute(
                    update(webhook_outbox)
                    .where(o.id.in_(picked), due)
                    .values(locked_until=lease_until)
                    .returning(o.id)
                )
                .scalars()
                .all()
            )
            if not claimed:
                return []
            rows = connection.execute(
                select(
                    o.id,
                    o.event_id,
                    o.event_type,
                    o.payload,
                    o.created_at,
                    o.attempts,
                    o.subscription_id,
                    s.subscription_id.label("public_id"),
                    s.url,
                    s.secret,
                    s.previous_secret,
                    s.previous_secret_until,
                )
                .join(webhook_subscriptions, o.subscription_id == s.id)
                .where(o.id.in_(claimed))
                .order_by(o.next_attempt_at, o.id)
            ).all()
        return [
            ClaimedEvent(
                outbox_id=row.id,
                event_id=row.event_id,
                event_type=row.event_type,
                body=row.payload,
                created_at=row.created_at,
                attempts=row.attempts,
                subscription_row=row.subscription_id,
                subscription_id=row.public_id,
                url=row.url,
                signing_secrets=(row.secret,)
                + (
                    (row.previous_secret,)
                    if row.previous_secret is not None and (row.previous_secret_until or 0.0) > now
                    else ()
                ),
            )
            for row in rows
        ]

    def record_attempt(
        self,
        event: ClaimedEvent,
        *,
        attempt: int,
        attempted_at: float,
        status_code: int | None,
        error: str | None,
        duration_ms: float,
        outcome: webhooks.Outcome,
        now: float,
    ) -> dict[str, int]:
        """Log an attempt and apply its outcome, in one transaction.

        Returns
        -------
        dict
            Events that reached a final state, by state (``delivered``, ``failed``,
            ``expired``), including those failed because the subscription was disabled;
            empty when the row is gone (its subscription was deleted meanwhile).
        """
        final = outcome.state != "pending"
        o, s = webhook_outbox.c, webhook_subscriptions.c
        finished: dict[str, int] = {}
        with self.engine.begin() as connection:
            updated = connection.execute(
                update(webhook_outbox)
                .where(o.id == event.outbox_id)
                .values(
                    attempts=attempt,
                    state=outcome.state,
                    locked_until=None,
                    next_attempt_at=(
                        outcome.next_attempt_at
                        if outcome.next_attempt_at is not None
                        else o.next_attempt_at
                    ),
                    finished_at=now if final else None,
                    last_status_code=status_code,
                    last_error=error,
                )
            ).rowcount
            if not updated:
                return finished
            if final:
                finished[outcome.state] = 1
            connection.execute(
                insert(webhook_deliveries).values(
                    outbox_id=event.outbox_id,
                    attempt=attempt,
                    attempted_at=attempted_at,
                    status_code=status_code,
                    error=error,
                    duration_ms=duration_ms,
                )
            )
            if outcome.disable_subscription:
                connection.execute(
                    update(webhook_subscriptions)
                    .where(s.id == event.subscription_row, s.disabled_at.is_(None))
                    .values(disabled_at=now, disabled_reason=outcome.reason[:200])
                )
                others = connection.execute(
                    update(webhook_outbox)
                    .where(o.subscription_id == event.subscription_row, o.state == "pending")
                    .values(
                        state="failed",
                        finished_at=now,
                        locked_until=None,
                        last_error=_DISABLED_EVENT_ERROR,
                    )
                ).rowcount
                if others:
                    finished["failed"] = finished.get("failed", 0) + others
            if outcome.defer_subscription_until is not None:
                connection.execute(
                    update(webhook_outbox)
                    .where(
                        o.subscription_id == event.subscription_row,
                        o.state == "pending",
                        o.next_attempt_at < outcome.defer_subscription_until,
                    )
                    .values(next_attempt_at=outcome.defer_subscription_until)
                )
        return finished

    def expire(self, outbox_id: int, now: float, reason: str) -> bool:
        """Mark one claimed event expired without an attempt; False if it is gone."""
        o = webhook_outbox.c
        with self.engine.begin() as connection:
            outcome = connection.execute(
                update(webhook_outbox)
                .where(o.id == outbox_id, o.state == "pending")
                .values(state="expired", finished_at=now, locked_until=None, last_error=reason)
            )
        return bool(outcome.rowcount)

    def expire_overdue(self, now: float, ttl_s: float) -> int:
        """Mark expired every pending event created more than ``ttl_s`` ago and not in an
        attempt now (leased); the number marked."""
        o = webhook_outbox.c
        with self.engine.begin() as connection:
            outcome = connection.execute(
                update(webhook_outbox)
                .where(
                    o.state == "pending",
                    o.created_at <= now - ttl_s,
                    or_(o.locked_until.is_(None), o.locked_until <= now),
                )
                .values(
                    state="expired",
                    finished_at=now,
                    locked_until=None,
                    last_error=f"not delivered within its time to live ({ttl_s:.0f} s)",
                )
            )
        return int(outcome.rowcount)

    def pending_count(self) -> int:
        o = webhook_outbox.c
        with self.engine.connect() as connection:
            stmt = select(func.count()).select_from(webhook_outbox).where(o.state == "pending")
            return int(connection.scalar(stmt) or 0)

    def deliveries(self, event_id: str) -> list[dict[str, Any]]:
        """Every attempt logged for an event (all subscriptions), oldest first: for tests and
        for an operator's look at one event."""
        d, o = webhook_deliveries.c, webhook_outbox.c
        stmt = (
            select(
                d.attempt, d.attempted_at, d.status_code, d.error, d.duration_ms, o.subscription_id
            )
            .join(webhook_outbox, d.outbox_id == o.id)
            .where(o.event_id == event_id)
            .order_by(d.id)
        )
        with self.engine.connect() as connection:
            return [dict(row._mapping) for row in connection.execute(stmt)]
