"""The gateway's tables (SQLAlchemy Core) and the migrations that build them.

One schema for SQLite and PostgreSQL. Times: ``stamp`` columns are capture times [s] as the bus
carries them (simulation time in simulation); ``received_at`` and the other ``*_at`` columns
are the gateway's wall clock [s since the Unix epoch], which retention uses (a simulation
restarted from stamp 0 must not look older than what it follows).

Migrations
----------
``schema_version`` holds one row per migration applied. :data:`MIGRATIONS` lists them in
order; the storage applies those not yet recorded, each in its own transaction, at start. A
change to a table is a new migration at the end of the list, and the table definition here
changes with it; migration 1 then keeps its own copy of the old definition, so that an empty
database still goes through every step.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from sqlalchemy import (
    JSON,
    BigInteger,
    Boolean,
    Column,
    Connection,
    Double,
    ForeignKey,
    Index,
    Integer,
    MetaData,
    SmallInteger,
    String,
    Table,
    Text,
)

metadata = MetaData()

# SQLite makes an INTEGER PRIMARY KEY the rowid (auto-incremented); PostgreSQL gets a BIGINT.
RowId = BigInteger().with_variant(Integer(), "sqlite")

schema_version = Table(
    "schema_version",
    metadata,
    Column("version", Integer, primary_key=True, autoincrement=False),
    Column("description", String(200), nullable=False),
    Column("applied_at", Double, nullable=False),
)

#: One row per track per tracker cycle: the fused trajectory. ``smoothed`` rows are the
#: smoothed trajectory written when a track ends (same track, same stamps).
track_points = Table(
    "track_points",
    metadata,
    Column("id", RowId, primary_key=True, autoincrement=True),
    Column("site", String(64), nullable=False),
    Column("track_id", BigInteger, nullable=False),
    Column("stamp", Double, nullable=False),
    Column("x_m", Double, nullable=False),
    Column("y_m", Double, nullable=False),
    Column("latitude_deg", Double, nullable=False),
    Column("longitude_deg", Double, nullable=False),
    Column("station_m", Double, nullable=False),
    Column("offset_m", Double, nullable=False),
    Column("lane_index", SmallInteger, nullable=False),
    Column("speed_mps", Double, nullable=False),
    Column("heading_rad", Double, nullable=False),
    Column("vx_mps", Double, nullable=False),
    Column("vy_mps", Double, nullable=False),
    Column("object_class", String(16), nullable=False),
    Column("status", String(16), nullable=False),
    Column("length_m", Double, nullable=True),
    Column("width_m", Double, nullable=True),
    Column("smoothed", Boolean, nullable=False, default=False),
    Column("received_at", Double, nullable=False),
    Index("ix_track_points_site_stamp", "site", "stamp"),
    Index("ix_track_points_site_track", "site", "track_id", "stamp"),
    Index("ix_track_points_received_at", "received_at"),
)

#: Every alert event (start, update, clear) as the alert service published it.
alerts = Table(
    "alerts",
    metadata,
    Column("id", RowId, primary_key=True, autoincrement=True),
    Column("alert_id", String(128), nullable=False, unique=True),
    Column("site", String(64), nullable=False),
    Column("source_id", String(128), nullable=False),
    Column("episode_id", String(128), nullable=True),
    Column("phase", String(8), nullable=False),
    Column("alert_type", String(32), nullable=False),
    Column("severity", String(16), nullable=False),
    Column("stamp", Double, nullable=False),
    Column("onset_stamp", Double, nullable=True),
    Column("track_id", BigInteger, nullable=True),
    Column("station_m", Double, nullable=False),
    Column("offset_m", Double, nullable=False),
    Column("speed_mps", Double, nullable=True),
    Column("measured_value", Double, nullable=False),
    Column("threshold_value", Double, nullable=False),
    Column("value_unit", String(16), nullable=False),
    Column("description", String(500), nullable=False),
    Column("evidence", JSON, nullable=False),
    Column("track", JSON, nullable=True),
    Column("received_at", Double, nullable=False),
    Index("ix_alerts_site_stamp", "site", "stamp"),
    Index("ix_alerts_episode", "episode_id"),
    Index("ix_alerts_received_at", "received_at"),
)

#: What the beacon and the sign showed, each time it changed.
device_states = Table(
    "device_states",
    metadata,
    Column("id", RowId, primary_key=True, autoincrement=True),
    Column("site", String(64), nullable=False),
    Column("source_id", String(128), nullable=False),
    Column("stamp", Double, nullable=False),
    Column("beacon_on", Boolean, nullable=False),
    Column("sign_text", String(64), nullable=False),
    Column("cause", String(32), nullable=True),
    Column("queue_tail_station_m", Double, nullable=True),
    Column("received_at", Double, nullable=False),
    Index("ix_device_states_site_stamp", "site", "stamp"),
    Index("ix_device_states_received_at", "received_at"),
)

#: The newest message of each kind per site (``tracks``, ``devices``, ``status/<service>``):
#: the live view, read by any number of API workers.
latest = Table(
    "latest",
    metadata,
    Column("site", String(64), primary_key=True),
    Column("name", String(128), primary_key=True),
    Column("stamp", Double, nullable=False),
    Column("received_at", Double, nullable=False),
    Column("body", Text, nullable=False),
)

api_keys = Table(
    "api_keys",
    metadata,
    Column("id", RowId, primary_key=True, autoincrement=True),
    Column("key_id", String(32), nullable=False, unique=True),
    Column("fingerprint", String(16), nullable=False, index=True),
    Column("salt", String(64), nullable=False),
    Column("secret_hash", String(128), nullable=False),
    Column("scope", String(8), nullable=False),
    Column("name", String(100), nullable=False),
    #: ``settings`` (WZ_GATEWAY_API_KEYS), ``api`` (made through the admin API) or ``dev``.
    Column("origin", String(16), nullable=False),
    Column("created_at", Double, nullable=False),
    Column("revoked_at", Double, nullable=True),
)

webhook_subscriptions = Table(
    "webhook_subscriptions",
    metadata,
    Column("id", RowId, primary_key=True, autoincrement=True),
    Column("subscription_id", String(64), nullable=False, unique=True),
    Column("url", Text, nullable=False),
    #: Standard Webhooks signing secret (``whsec_...``): kept as is, the gateway signs with it.
    Column("secret", Text, nullable=False),
    Column("event_types", JSON, nullable=False),
    Column("description", String(200), nullable=False, default=""),
    Column("created_at", Double, nullable=False),
    Column("disabled_at", Double, nullable=True),
)

#: Durable outbox: an event for a subscriber is written here in the same transaction as what
#: caused it, and delivered (with retries) from here.
webhook_outbox = Table(
    "webhook_outbox",
    metadata,
    Column("id", RowId, primary_key=True, autoincrement=True),
    Column("event_id", String(64), nullable=False),
    Column(
        "subscription_id",
        RowId,
        ForeignKey("webhook_subscriptions.id", ondelete="CASCADE"),
        nullable=False,
    ),
    Column("event_type", String(64), nullable=False),
    Column("payload", Text, nullable=False),
    Column("created_at", Double, nullable=False),
    Column("next_attempt_at", Double, nullable=False),
    Column("attempts", Integer, nullable=False, default=0),
    #: ``pending``, ``delivered`` or ``failed`` (gave up).
    Column("state", String(16), nullable=False, default="pending"),
    Index("ix_webhook_outbox_due", "state", "next_attempt_at"),
)

webhook_deliveries = Table(
    "webhook_deliveries",
    metadata,
    Column("id", RowId, primary_key=True, autoincrement=True),
    Column(
        "outbox_id", RowId, ForeignKey("webhook_outbox.id", ondelete="CASCADE"), nullable=False
    ),
    Column("attempted_at", Double, nullable=False),
    Column("status_code", Integer, nullable=True),
    Column("error", Text, nullable=True),
    Column("duration_ms", Double, nullable=False),
    Index("ix_webhook_deliveries_outbox", "outbox_id"),
)


@dataclass(frozen=True)
class Migration:
    """One step of the schema: ``apply(connection)`` runs inside a transaction."""

    version: int
    description: str
    apply: Callable[[Connection], None]


def _v1_initial(connection: Connection) -> None:
    tables = [
        track_points,
        alerts,
        device_states,
        latest,
        api_keys,
        webhook_subscriptions,
        webhook_outbox,
        webhook_deliveries,
    ]
    metadata.create_all(connection, tables=tables)


#: Every migration, in order; the last one's version is the schema this code reads and writes.
MIGRATIONS: tuple[Migration, ...] = (
    Migration(1, "trajectories, alerts, device states, latest, API keys, webhooks", _v1_initial),
)
SCHEMA_VERSION = MIGRATIONS[-1].version
