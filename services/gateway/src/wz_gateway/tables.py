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
    LargeBinary,
    MetaData,
    SmallInteger,
    String,
    Table,
    Text,
    UniqueConstraint,
    false,
    inspect,
    text,
)
from sqlalchemy.schema import CreateColumn

metadata = MetaData()

#: ``struct`` format of ``track_points.covariance``.
COVARIANCE_FORMAT = "<16d"

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
    # Migration 3: the state's 4x4 covariance (x, y, vx, vy) as the tracker sent it (smoothed
    # rows: the smoothed one) [m^2, m^2/s, m^2/s^2], 16 little-endian float64s, row-major
    # (:data:`COVARIANCE_FORMAT`: cheaper than JSON on the ingest path); None on points
    # stored before.
    Column("covariance", LargeBinary, nullable=True),
    Index("ix_track_points_site_stamp", "site", "stamp"),
    Index("ix_track_points_site_track", "site", "track_id", "stamp"),
    Index("ix_track_points_received_at", "received_at"),
)

#: One row per track life (a track id in one run of the tracker), written when the gateway
#: first stores it; ``ended_at`` is set, in the transaction that writes its smoothed points,
#: once it has ended. Its points: that site and track id, stamps from ``first_stamp`` to
#: ``last_stamp``, received from ``first_received_at`` to ``last_received_at``.
tracks = Table(
    "tracks",
    metadata,
    Column("id", RowId, primary_key=True, autoincrement=True),
    Column("site", String(64), nullable=False),
    Column("track_id", BigInteger, nullable=False),
    Column("first_stamp", Double, nullable=False),
    Column("first_received_at", Double, nullable=False),
    Column("last_stamp", Double, nullable=True),
    Column("last_received_at", Double, nullable=True),
    #: Wall clock when it was smoothed [Unix s]; None while it lives (or waits to be smoothed).
    Column("ended_at", Double, nullable=True),
    Column("smoothed_points", Integer, nullable=True),
    # Migration 5: the process noise its track batches carried, which it is smoothed with
    # (wz_shared.motion.ProcessNoise); None in older rows: the model's defaults.
    Column("sigma_along_mps2", Double, nullable=True),
    Column("sigma_across_mps2", Double, nullable=True),
    Column("heading_min_speed_mps", Double, nullable=True),
    Index("ix_tracks_site_ended", "site", "ended_at"),
    Index("ix_tracks_site_track", "site", "track_id"),
)

#: Every alert event (start, update, clear) as the alert service published it.
alerts = Table(
    "alerts",
    metadata,
    Column("id", RowId, primary_key=True, autoincrement=True),
    Column("alert_id", String(128), nullable=False),
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
    # An alert is stored once per site and id (a central gateway stores many sites, whose
    # alert services may name episodes alike).
    Index("ux_alerts_site_alert", "site", "alert_id", unique=True),
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

#: Each lane's queue, once a second and at each change of a lane's condition (migration 8):
#: one row per :class:`~wz_shared.messages.QueueState`, its lanes as JSON (a list of
#: :class:`~wz_shared.messages.LaneQueue`), with the worst lane's condition and the most
#: upstream back as columns to filter on. The newest is also in ``latest`` (``queue``).
queue_states = Table(
    "queue_states",
    metadata,
    Column("id", RowId, primary_key=True, autoincrement=True),
    Column("site", String(64), nullable=False),
    Column("source_id", String(128), nullable=False),
    Column("stamp", Double, nullable=False),
    Column("condition", String(16), nullable=False),
    Column("back_station_m", Double, nullable=True),
    Column("lanes", JSON, nullable=False),
    Column("received_at", Double, nullable=False),
    Index("ix_queue_states_site_stamp", "site", "stamp"),
    Index("ix_queue_states_received_at", "received_at"),
)

#: Each sensor's self-calibration state as it changed (migration 7): a row when a sensor's
#: first :class:`~wz_shared.messages.SensorCalibration` arrives and each time its ``state``
#: (or the stamp it was entered at) differs from the one before, so that a technician can see
#: when a sensor was knocked and when it was learned again. The newest message of each sensor
#: is in ``latest`` (``calibration/<sensor>``).
calibration_changes = Table(
    "calibration_changes",
    metadata,
    Column("id", RowId, primary_key=True, autoincrement=True),
    Column("site", String(64), nullable=False),
    Column("sensor_id", String(64), nullable=False),
    Column("sensor_kind", String(16), nullable=False),
    Column("state", String(16), nullable=False),
    #: The state before; None for the first message of a sensor this gateway stored.
    Column("previous_state", String(16), nullable=True),
    #: The stamp of the message that brought the change, and the one the state was entered at
    #: [s, the sensor's time].
    Column("stamp", Double, nullable=False),
    Column("state_since_s", Double, nullable=False),
    Column("detail", String(500), nullable=False),
    Column("received_at", Double, nullable=False),
    Index("ix_calibration_changes_site_sensor", "site", "sensor_id", "id"),
    Index("ix_calibration_changes_received_at", "received_at"),
)

#: The newest message of each kind per site (``tracks``, ``devices``, ``status/<service>``,
#: ``calibration/<sensor>``): the live view, read by any number of API workers.
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
    # Migration 6: made while the gateway ran in dev mode (the dev admin key, and keys made
    # through the API then); revoked when the gateway starts outside dev mode.
    Column("dev_mode", Boolean, nullable=False, server_default=false()),
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
    # Migration 2: filters, why it was disabled, the secret before a rotation (still signed
    # with until ``previous_secret_until``, so receivers can switch without losing events).
    Column("min_severity", String(16), nullable=True),
    Column("phases", JSON, nullable=True),
    Column("disabled_reason", String(200), nullable=True),
    Column("previous_secret", Text, nullable=True),
    Column("previous_secret_until", Double, nullable=True),
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
    #: ``pending``, ``delivered``, ``failed`` (410 Gone, subscription disabled) or ``expired``
    #: (not delivered within the event's time to live).
    Column("state", String(16), nullable=False, default="pending"),
    # Migration 2: the claim's lease (a row claimed by a process that died is taken again
    # once it runs out), when the row reached its final state, the last attempt's result.
    Column("locked_until", Double, nullable=True),
    Column("finished_at", Double, nullable=True),
    Column("last_status_code", Integer, nullable=True),
    Column("last_error", Text, nullable=True),
    Index("ix_webhook_outbox_due", "state", "next_attempt_at"),
    Index("ux_webhook_outbox_subscription_event", "subscription_id", "event_id", unique=True),
)

webhook_deliveries = Table(
    "webhook_deliveries",
    metadata,
    Column("id", RowId, primary_key=True, autoincrement=True),
    Column("outbox_id", RowId, ForeignKey("webhook_outbox.id", ondelete="CASCADE"), nullable=False),
    Column("attempted_at", Double, nullable=False),
    Column("status_code", Integer, nullable=True),
    Column("error", Text, nullable=True),
    Column("duration_ms", Double, nullable=False),
    # Migration 2: which attempt of the event this was (1 the first).
    Column("attempt", Integer, nullable=False, server_default="0"),
    Index("ix_webhook_deliveries_outbox", "outbox_id"),
)


@dataclass(frozen=True)
class Migration:
    """One step of the schema: ``apply(connection)`` runs inside a transaction."""

    version: int
    description: str
    apply: Callable[[Connection], None]


# The webhook tables as migration 1 made them (migration 2 adds to them).
_v1_metadata = MetaData()
_v1_webhook_tables = [
    Table(
        "webhook_subscriptions",
        _v1_metadata,
        Column("id", RowId, primary_key=True, autoincrement=True),
        Column("subscription_id", String(64), nullable=False, unique=True),
        Column("url", Text, nullable=False),
        Column("secret", Text, nullable=False),
        Column("event_types", JSON, nullable=False),
        Column("description", String(200), nullable=False, default=""),
        Column("created_at", Double, nullable=False),
        Column("disabled_at", Double, nullable=True),
    ),
    Table(
        "webhook_outbox",
        _v1_metadata,
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
        Column("state", String(16), nullable=False, default="pending"),
        Index("ix_webhook_outbox_due", "state", "next_attempt_at"),
    ),
    Table(
        "webhook_deliveries",
        _v1_metadata,
        Column("id", RowId, primary_key=True, autoincrement=True),
        Column(
            "outbox_id", RowId, ForeignKey("webhook_outbox.id", ondelete="CASCADE"), nullable=False
        ),
        Column("attempted_at", Double, nullable=False),
        Column("status_code", Integer, nullable=True),
        Column("error", Text, nullable=True),
        Column("duration_ms", Double, nullable=False),
        Index("ix_webhook_deliveries_outbox", "outbox_id"),
    ),
]

# track_points as migration 1 made it (migration 3 adds the covariance).
_v1_track_points = Table(
    "track_points",
    _v1_metadata,
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


# alerts as migration 1 made it (migration 4 makes alert_id unique per site, not overall).
_v1_alerts = alerts.to_metadata(_v1_metadata)
_v1_alerts.append_constraint(UniqueConstraint("alert_id"))
_v1_alerts.indexes.discard(next(i for i in _v1_alerts.indexes if i.name == "ux_alerts_site_alert"))


# api_keys as migration 1 made it (migration 6 adds ``dev_mode``).
_v1_api_keys = Table(
    "api_keys",
    _v1_metadata,
    Column("id", RowId, primary_key=True, autoincrement=True),
    Column("key_id", String(32), nullable=False, unique=True),
    Column("fingerprint", String(16), nullable=False, index=True),
    Column("salt", String(64), nullable=False),
    Column("secret_hash", String(128), nullable=False),
    Column("scope", String(8), nullable=False),
    Column("name", String(100), nullable=False),
    Column("origin", String(16), nullable=False),
    Column("created_at", Double, nullable=False),
    Column("revoked_at", Double, nullable=True),
)


def _v1_initial(connection: Connection) -> None:
    metadata.create_all(connection, tables=[device_states, latest])
    _v1_metadata.create_all(
        connection, tables=[_v1_api_keys, _v1_alerts, _v1_track_points, *_v1_webhook_tables]
    )


def _add_columns(connection: Connection, table: Table, names: list[str]) -> None:
    """``ALTER TABLE ... ADD COLUMN`` for columns of ``table`` as defined above."""
    for name in names:
        spec = CreateColumn(table.c[name]).compile(dialect=connection.dialect)
        connection.execute(text(f"ALTER TABLE {table.name} ADD COLUMN {spec}"))


def _v2_webhooks(connection: Connection) -> None:
    _add_columns(
        connection,
        webhook_subscriptions,
        ["min_severity", "phases", "disabled_reason", "previous_secret", "previous_secret_until"],
    )
    _add_columns(
        connection,
        webhook_outbox,
        ["locked_until", "finished_at", "last_status_code", "last_error"],
    )
    _add_columns(connection, webhook_deliveries, ["attempt"])
    # One outbox row per event and subscription: an event enqueued twice is written once.
    next(
        i for i in webhook_outbox.indexes if i.name == "ux_webhook_outbox_subscription_event"
    ).create(connection)


# tracks as migration 3 made it (migration 5 adds the process noise).
_v3_tracks = Table(
    "tracks",
    _v1_metadata,
    Column("id", RowId, primary_key=True, autoincrement=True),
    Column("site", String(64), nullable=False),
    Column("track_id", BigInteger, nullable=False),
    Column("first_stamp", Double, nullable=False),
    Column("first_received_at", Double, nullable=False),
    Column("last_stamp", Double, nullable=True),
    Column("last_received_at", Double, nullable=True),
    Column("ended_at", Double, nullable=True),
    Column("smoothed_points", Integer, nullable=True),
    Index("ix_tracks_site_ended", "site", "ended_at"),
    Index("ix_tracks_site_track", "site", "track_id"),
)


def _v3_smoothing(connection: Connection) -> None:
    _add_columns(connection, track_points, ["covariance"])
    _v1_metadata.create_all(connection, tables=[_v3_tracks])


def _v4_alerts_per_site(connection: Connection) -> None:
    if connection.dialect.name == "sqlite":  # a constraint cannot be dropped: copy the table
        connection.execute(text("ALTER TABLE alerts RENAME TO alerts_v3"))
        for index in alerts.indexes:  # the old ones went with the renamed table
            connection.execute(text(f"DROP INDEX IF EXISTS {index.name}"))
        metadata.create_all(connection, tables=[alerts])
        names = ", ".join(column.name for column in alerts.c)
        connection.execute(text(f"INSERT INTO alerts ({names}) SELECT {names} FROM alerts_v3"))
        connection.execute(text("DROP TABLE alerts_v3"))
        return
    for constraint in inspect(connection).get_unique_constraints("alerts"):
        if constraint["column_names"] == ["alert_id"]:
            connection.execute(text(f'ALTER TABLE alerts DROP CONSTRAINT "{constraint["name"]}"'))
    next(i for i in alerts.indexes if i.name == "ux_alerts_site_alert").create(connection)


def _v5_track_process_noise(connection: Connection) -> None:
    _add_columns(
        connection, tracks, ["sigma_along_mps2", "sigma_across_mps2", "heading_min_speed_mps"]
    )


def _v6_dev_mode_keys(connection: Connection) -> None:
    _add_columns(connection, api_keys, ["dev_mode"])
    # Which older keys were made in dev mode is not recorded; a dev run made its admin key
    # (origin ``dev``) at start and the next start revoked it, so a key made through the API
    # while a dev key was live was made in a dev run.
    connection.execute(
        text(
            "UPDATE api_keys SET dev_mode = :yes WHERE origin = 'dev' OR (origin = 'api' AND "
            "EXISTS (SELECT 1 FROM api_keys AS d WHERE d.origin = 'dev' "
            "AND d.created_at <= api_keys.created_at "
            "AND (d.revoked_at IS NULL OR api_keys.created_at <= d.revoked_at)))"
        ),
        {"yes": True},
    )


def _v7_calibration_changes(connection: Connection) -> None:
    metadata.create_all(connection, tables=[calibration_changes])


def _v8_queue_states(connection: Connection) -> None:
    metadata.create_all(connection, tables=[queue_states])


#: Every migration, in order; the last one's version is the schema this code reads and writes.
MIGRATIONS: tuple[Migration, ...] = (
    Migration(1, "trajectories, alerts, device states, latest, API keys, webhooks", _v1_initial),
    Migration(2, "webhooks: filters, claim leases, expiry, delivery attempts", _v2_webhooks),
    Migration(3, "track points' covariances, track lives (smoothed when they end)", _v3_smoothing),
    Migration(
        4,
        "alerts: one per site and alert_id (a central gateway stores many sites)",
        _v4_alerts_per_site,
    ),
    Migration(
        5,
        "track lives: the process noise of their track batches, smoothed with it",
        _v5_track_process_noise,
    ),
    Migration(
        6,
        "API keys: marked when made in dev mode (revoked when dev mode is off)",
        _v6_dev_mode_keys,
    ),
    Migration(
        7,
        "the sensors' self-calibration: each change of state",
        _v7_calibration_changes,
    ),
    Migration(8, "each lane's queue, once a second", _v8_queue_states),
)
SCHEMA_VERSION = MIGRATIONS[-1].version
