"""The gateway's one data layer: SQLAlchemy Core over SQLite (default) or PostgreSQL.

SQLite runs in WAL mode (readers never wait for the writer) with foreign keys on and
``synchronous=NORMAL`` (a power cut may lose the last transactions, never corrupt the file).
Everything is written through :meth:`Storage.ingest`: one transaction per group of messages,
each track batch as one multi-row insert. Reads page by keyset (``stamp``, ``id``) cursors, so a
page never shifts when rows arrive or retention deletes old ones.

Usage::

    storage = Storage.open("sqlite:////var/lib/wz/gateway/gateway.sqlite3")  # migrates
    storage.ingest([batch, alert], geo=site.geo_frame, received_at=time.time())
    page = storage.points(PointQuery(site="us75-lincoln", start_stamp=10.0, limit=500))
"""

from __future__ import annotations

import logging
import math
import struct
import time
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
from sqlalchemy import (
    ColumnElement,
    Connection,
    Engine,
    Insert,
    Select,
    and_,
    create_engine,
    delete,
    event,
    func,
    insert,
    or_,
    select,
    text,
    true,
    tuple_,
)
from sqlalchemy.dialects import postgresql, sqlite
from sqlalchemy.engine import make_url
from sqlalchemy.exc import ArgumentError

from wz_gateway.conflicts import Trajectories
from wz_gateway.conflicts import trajectories as conflict_trajectories
from wz_gateway.models import TrackPoint
from wz_gateway.store_types import (
    AlertQuery,
    CalibrationChange,
    IngestResult,
    LatestRow,
    Page,
    PointQuery,
    QueueQuery,
    TrafficPoints,
    decode_cursor,
    encode_cursor,
)
from wz_gateway.tables import (
    COVARIANCE_FORMAT,
    MIGRATIONS,
    SCHEMA_VERSION,
    alerts,
    api_keys,
    calibration_changes,
    device_states,
    latest,
    queue_states,
    schema_version,
    track_points,
    tracks,
    webhook_deliveries,
    webhook_outbox,
)
from wz_gateway.webhook_store import enqueue_alert
from wz_shared.geometry import GeoFrame
from wz_shared.messages import (
    Alert,
    CalibrationState,
    LaneQueue,
    Message,
    PointSensorReading,
    QueueState,
    RoadsideDeviceState,
    SensorCalibration,
    ServiceStatus,
    Track,
    TrackBatch,
)
from wz_shared.timebase import NEW_RUN_STEP_BACK_S, stamp_went_back

log = logging.getLogger(__name__)

_DIALECTS = ("sqlite", "postgresql")
#: The ``latest`` rows of the sensors' self-calibration are named this and the sensor's id.
CALIBRATION_PREFIX = "calibration/"
#: ... and the upstream point speed sensors' newest readings this and the sensor's id.
POINTS_PREFIX = "points/"
#: A track batch this much older than the newest one starts a new run [s] (see ``run_start``).
RESTART_TOLERANCE_S = NEW_RUN_STEP_BACK_S
_DAY_S = 86400.0


class StorageError(RuntimeError):
    """The database cannot be used as configured (wrong URL, newer schema, unreachable)."""


# --- the storage --------------------------------------------------------------------------


def _sqlite_pragmas(dbapi_connection: Any, _record: Any) -> None:
    cursor = dbapi_connection.cursor()
    try:
        cursor.execute("PRAGMA journal_mode=WAL")
        cursor.execute("PRAGMA synchronous=NORMAL")
        cursor.execute("PRAGMA foreign_keys=ON")
        cursor.execute("PRAGMA busy_timeout=10000")
    finally:
        cursor.close()


class Storage:
    """Trajectories, alerts and device states in one database (the API keys, the track lives
    and the webhook tables share it: :mod:`wz_gateway.key_store`, :mod:`wz_gateway.track_lives`,
    :mod:`wz_gateway.webhook_store`; :meth:`migrate` and :meth:`purge` cover them all).

    Thread-safe: every call takes its own connection from the engine's pool. Build it with
    :meth:`open`, which checks the URL and applies the migrations.
    """

    def __init__(self, engine: Engine) -> None:
        self.engine = engine
        self.dialect = engine.dialect.name
        if self.dialect not in _DIALECTS:
            raise StorageError(
                f"database {self.dialect!r} is not supported: use SQLite (the default) or "
                "PostgreSQL (postgresql+psycopg://user:password@host/db)"
            )

    @classmethod
    def open(cls, url: str, *, migrate: bool = True) -> Storage:
        """Connect to ``url``, create the SQLite file's folder, apply missing migrations.

        Raises
        ------
        StorageError
            For a URL that is not SQLite or PostgreSQL, a file that cannot be created, a
            database at a newer schema than this gateway knows, or one that cannot be reached.
        """
        try:
            parsed = make_url(url)
        except ArgumentError as exc:
            raise StorageError(f"database URL {url!r} is not a valid SQLAlchemy URL") from exc
        backend = parsed.get_backend_name()
        if backend not in _DIALECTS:
            raise StorageError(
                f"database {backend!r} is not supported: use sqlite:///path/to/file or "
                "postgresql+psycopg://user:password@host/db"
            )
        if backend == "sqlite":
            database = parsed.database or ""
            if database in ("", ":memory:") or database.startswith("file:"):
                raise StorageError(
                    "an in-memory SQLite database would lose everything at exit; give a file: "
                    "sqlite:////var/lib/wz/gateway/gateway.sqlite3"
                )
            try:
                Path(database).parent.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise StorageError(f"cannot create the folder of {database}: {exc}") from exc
        try:
            engine = create_engine(url, pool_pre_ping=backend == "postgresql")
        except Exception as exc:  # a missing driver (psycopg) surfaces here
            raise StorageError(f"cannot use database {parsed!r}: {exc}") from exc
        if backend == "sqlite":
            event.listen(engine, "connect", _sqlite_pragmas)
        storage = cls(engine)
        if migrate:
            storage.migrate()
        return storage

    def close(self) -> None:
        self.engine.dispose()

    # --- schema ---------------------------------------------------------------------------

    def migrate(self) -> list[int]:
        """Apply the migrations not yet recorded; the versions applied."""
        try:
            with self.engine.begin() as connection:
                schema_version.create(connection, checkfirst=True)
                done = set(connection.scalars(select(schema_version.c.version)))
        except Exception as exc:
            raise StorageError(f"cannot open the database {self.engine.url!r}: {exc}") from exc
        newest = max(done, default=0)
        if newest > SCHEMA_VERSION:
            raise StorageError(
                f"the database is at schema version {newest}, this gateway knows up to "
                f"{SCHEMA_VERSION}: run a newer gateway (nothing was changed)"
            )
        applied: list[int] = []
        for migration in MIGRATIONS:
            if migration.version in done:
                continue
            with self.engine.begin() as connection:
                migration.apply(connection)
                connection.execute(
                    insert(schema_version).values(
                        version=migration.version,
                        description=migration.description,
                        applied_at=time.time(),
                    )
                )
            log.info(
                "database migrated to version %d: %s", migration.version, migration.description
            )
            applied.append(migration.version)
        return applied

    def current_schema_version(self) -> int:
        with self.engine.connect() as connection:
            version = connection.scalar(select(func.max(schema_version.c.version)))
        return int(version or 0)

    def ping(self) -> None:
        """Raise if the database cannot answer a trivial query."""
        with self.engine.connect() as connection:
            connection.execute(text("SELECT 1"))

    # --- writing --------------------------------------------------------------------------

    def _insert(self, table: Any) -> Insert:
        module = sqlite if self.dialect == "sqlite" else postgresql
        stmt: Insert = module.insert(table)
        return stmt

    def _upsert_latest(
        self, connection: Connection, site: str, name: str, message: Message, received_at: float
    ) -> None:
        stmt: Any = self._insert(latest).values(
            site=site,
            name=name,
            stamp=message.stamp,
            received_at=received_at,
            body=message.model_dump_json(),
        )
        stmt = stmt.on_conflict_do_update(
            index_elements=[latest.c.site, latest.c.name],
            set_={
                "stamp": stmt.excluded.stamp,
                "received_at": stmt.excluded.received_at,
                "body": stmt.excluded.body,
            },
        )
        connection.execute(stmt)

    def ingest(
        self,
        messages: Iterable[Message],
        *,
        geo: GeoFrame | Mapping[str, GeoFrame],
        received_at: float,
    ) -> IngestResult:
        """Write messages from the bus in one transaction.

        A :class:`TrackBatch` adds one point per track and becomes the live view; an
        :class:`Alert` is added once (a repeated ``alert_id`` is counted, not written twice);
        a :class:`RoadsideDeviceState` is added to the history and becomes the devices' state;
        a :class:`QueueState` is added to the queue's history and becomes the queue now;
        a :class:`ServiceStatus` becomes that service's latest status; a
        :class:`SensorCalibration` becomes that sensor's latest calibration, and is added to
        ``calibration_changes`` when its state differs from the one before (or was entered at
        another stamp: knocked again); a :class:`PointSensorReading` becomes that point
        sensor's latest reading (the WZDx feed's traffic sensor). Other messages are refused
        with ``TypeError`` before anything is written.

        Parameters
        ----------
        messages : iterable of Message
            In arrival order.
        geo : GeoFrame or mapping of site id to GeoFrame
            The site's WGS84 frame, for the points' latitude and longitude (one per site for
            a gateway that serves several; a batch of a site without one raises ``KeyError``).
        received_at : float
            The gateway's wall clock [s since the epoch] for every row.
        """
        items = list(messages)
        for message in items:
            if not isinstance(
                message,
                TrackBatch
                | Alert
                | RoadsideDeviceState
                | QueueState
                | ServiceStatus
                | SensorCalibration
                | PointSensorReading,
            ):
                raise TypeError(f"cannot store a {type(message).__name__}")
        result = IngestResult()
        with self.engine.begin() as connection:
            for message in items:
                if isinstance(message, TrackBatch):
                    frame = geo if isinstance(geo, GeoFrame) else geo[message.site]
                    result.points += self._write_batch(connection, message, frame, received_at)
                    result.track_batches += 1
                elif isinstance(message, Alert):
                    if self._write_alert(connection, message, received_at):
                        result.alerts += 1
                        # Its webhook events in the same transaction: both stored, or neither.
                        result.webhook_events += enqueue_alert(connection, message, received_at)
                    else:
                        result.duplicate_alerts += 1
                elif isinstance(message, RoadsideDeviceState):
                    connection.execute(
                        insert(device_states).values(
                            site=message.site,
                            source_id=message.source_id,
                            stamp=message.stamp,
                            beacon_on=message.beacon_on,
                            sign_text=message.sign_text,
                            cause=None if message.cause is None else message.cause.value,
                            queue_tail_station_m=message.queue_tail_station_m,
                            received_at=received_at,
                        )
                    )
                    self._upsert_latest(connection, message.site, "devices", message, received_at)
                    result.device_states += 1
                elif isinstance(message, QueueState):
                    connection.execute(
                        insert(queue_states).values(
                            site=message.site,
                            source_id=message.source_id,
                            stamp=message.stamp,
                            condition=message.condition.value,
                            back_station_m=message.back_station_m,
                            lanes=[lane.model_dump(mode="json") for lane in message.lanes],
                            received_at=received_at,
                        )
                    )
                    self._upsert_latest(connection, message.site, "queue", message, received_at)
                    result.queue_states += 1
                elif isinstance(message, ServiceStatus):
                    self._upsert_latest(
                        connection, message.site, f"status/{message.service}", message, received_at
                    )
                    result.statuses += 1
                elif isinstance(message, SensorCalibration):
                    if self._write_calibration(connection, message, received_at):
                        result.calibration_changes += 1
                    result.calibrations += 1
                elif isinstance(message, PointSensorReading):
                    name = POINTS_PREFIX + message.source_id
                    self._upsert_latest(connection, message.site, name, message, received_at)
                    result.point_readings += 1
        return result

    def _write_calibration(
        self, connection: Connection, calibration: SensorCalibration, received_at: float
    ) -> bool:
        """The sensor's latest calibration; a row of its history if its state changed."""
        name = CALIBRATION_PREFIX + calibration.source_id
        previous_body = connection.scalar(
            select(latest.c.body).where(latest.c.site == calibration.site, latest.c.name == name)
        )
        previous = _calibration_or_none(previous_body)
        changed = (
            previous is None
            or previous.state != calibration.state
            or previous.state_since_s != calibration.state_since_s
        )
        if changed:
            connection.execute(
                insert(calibration_changes).values(
                    site=calibration.site,
                    sensor_id=calibration.source_id,
                    sensor_kind=calibration.sensor_kind,
                    state=calibration.state.value,
                    previous_state=None if previous is None else previous.state.value,
                    stamp=calibration.stamp,
                    state_since_s=calibration.state_since_s,
                    detail=calibration.detail,
                    received_at=received_at,
                )
            )
        self._upsert_latest(connection, calibration.site, name, calibration, received_at)
        return changed

    def _write_batch(
        self, connection: Connection, batch: TrackBatch, geo: GeoFrame, received_at: float
    ) -> int:
        previous = connection.scalar(
            select(latest.c.stamp).where(latest.c.site == batch.site, latest.c.name == "tracks")
        )
        if stamp_went_back(previous, batch.stamp, RESTART_TOLERANCE_S):
            # Stamps went back: a new run (a restarted simulation counts from 0 again).
            log.warning(
                "track stamps went back from %.3f s to %.3f s: a new run starts",
                previous,
                batch.stamp,
            )
            self._upsert_latest(connection, batch.site, "run_start", batch, received_at)
        self._upsert_latest(connection, batch.site, "tracks", batch, received_at)
        if not batch.tracks:
            return 0
        x = np.array([t.x_m for t in batch.tracks])
        y = np.array([t.y_m for t in batch.tracks])
        latitude, longitude, _ = geo.to_wgs84(x, y)
        rows = [
            _point_row(batch, track, float(lat), float(lon), received_at)
            for track, lat, lon in zip(batch.tracks, latitude, longitude, strict=True)
        ]
        connection.execute(insert(track_points), rows)
        return len(rows)

    def _write_alert(self, connection: Connection, alert: Alert, received_at: float) -> bool:
        stmt: Any = self._insert(alerts).values(
            alert_id=alert.alert_id,
            site=alert.site,
            source_id=alert.source_id,
            episode_id=alert.episode_id,
            phase=alert.phase,
            alert_type=alert.alert_type.value,
            severity=alert.severity.value,
            stamp=alert.stamp,
            onset_stamp=alert.onset_stamp,
            track_id=alert.track_id,
            station_m=alert.station_m,
            offset_m=alert.offset_m,
            speed_mps=alert.speed_mps,
            measured_value=alert.measured_value,
            threshold_value=alert.threshold_value,
            value_unit=alert.value_unit,
            description=alert.description,
            evidence=dict(alert.evidence),
            track=None if alert.track is None else alert.track.model_dump(mode="json"),
            received_at=received_at,
        )
        # RETURNING says whether a row went in (rowcount is not reliable across drivers here).
        outcome = connection.execute(
            stmt.on_conflict_do_nothing(
                index_elements=[alerts.c.site, alerts.c.alert_id]
            ).returning(alerts.c.id)
        )
        return outcome.first() is not None

    # --- reading: live --------------------------------------------------------------------

    def latest(self, site: str, name: str) -> LatestRow | None:
        """The newest message stored under ``name``: ``tracks``, ``devices``, ``status/<service>``,
        or ``run_start`` (the first batch of the current run, when stamps went back)."""
        with self.engine.connect() as connection:
            row = connection.execute(
                select(latest).where(latest.c.site == site, latest.c.name == name)
            ).first()
        if row is None:
            return None
        return LatestRow(row.name, row.stamp, row.received_at, row.body)

    def latest_statuses(self, site: str) -> dict[str, LatestRow]:
        """Every service's newest status at ``site``, by service name."""
        with self.engine.connect() as connection:
            rows = connection.execute(
                select(latest).where(latest.c.site == site, latest.c.name.startswith("status/"))
            ).all()
        return {
            row.name.removeprefix("status/"): LatestRow(
                row.name, row.stamp, row.received_at, row.body
            )
            for row in rows
        }

    def _latest_named(self, site: str, prefix: str) -> dict[str, LatestRow]:
        """The ``latest`` rows of ``site`` whose name starts with ``prefix``, by the rest."""
        with self.engine.connect() as connection:
            rows = connection.execute(
                select(latest).where(latest.c.site == site, latest.c.name.startswith(prefix))
            ).all()
        return {
            row.name.removeprefix(prefix): LatestRow(row.name, row.stamp, row.received_at, row.body)
            for row in rows
        }

    def latest_calibrations(self, site: str) -> dict[str, LatestRow]:
        """Every sensor's newest self-calibration at ``site``, by sensor id."""
        return self._latest_named(site, CALIBRATION_PREFIX)

    def latest_point_readings(self, site: str) -> dict[str, LatestRow]:
        """Every upstream point speed sensor's newest reading at ``site``, by sensor id."""
        return self._latest_named(site, POINTS_PREFIX)

    def calibration_changes(
        self, site: str, *, per_sensor: int, sensor_id: str | None = None
    ) -> dict[str, list[CalibrationChange]]:
        """The newest ``per_sensor`` changes of state of each sensor at ``site`` (of
        ``sensor_id`` alone if given), newest first, by sensor id."""
        c = calibration_changes.c
        conditions: list[ColumnElement[bool]] = [c.site == site]
        if sensor_id is not None:
            conditions.append(c.sensor_id == sensor_id)
        if per_sensor <= 0:
            return {}
        rank = func.row_number().over(partition_by=c.sensor_id, order_by=c.id.desc()).label("rank")
        ranked = select(calibration_changes, rank).where(*conditions).subquery()
        stmt = (
            select(ranked)
            .where(ranked.c.rank <= per_sensor)
            .order_by(ranked.c.sensor_id, ranked.c.id.desc())
        )
        with self.engine.connect() as connection:
            rows = connection.execute(stmt).all()
        found: dict[str, list[CalibrationChange]] = {}
        for row in rows:
            found.setdefault(row.sensor_id, []).append(
                CalibrationChange(
                    sensor_id=row.sensor_id,
                    sensor_kind=row.sensor_kind,
                    state=CalibrationState(row.state),
                    previous_state=(
                        None if row.previous_state is None else CalibrationState(row.previous_state)
                    ),
                    stamp=row.stamp,
                    state_since_s=row.state_since_s,
                    detail=row.detail,
                    received_at=row.received_at,
                )
            )
        return found

    # --- reading: history -----------------------------------------------------------------

    @staticmethod
    def _page_order(
        stmt: Select[Any], table: Any, cursor: str | None, limit: int, newest_first: bool
    ) -> Select[Any]:
        key = tuple_(table.c.stamp, table.c.id)
        if cursor is not None:
            after = tuple_(*decode_cursor(cursor))
            stmt = stmt.where(key < after if newest_first else key > after)
        if newest_first:
            return stmt.order_by(table.c.stamp.desc(), table.c.id.desc()).limit(limit + 1)
        return stmt.order_by(table.c.stamp, table.c.id).limit(limit + 1)

    def _page(self, stmt: Select[Any], limit: int, item: Callable[[Any], Any]) -> Page:
        """Run a statement of :meth:`_page_order` (``limit + 1`` rows): the page's items and
        the next page's cursor."""
        with self.engine.connect() as connection:
            rows = connection.execute(stmt).all()
        more = len(rows) > limit
        rows = rows[:limit]
        next_cursor = encode_cursor(rows[-1].stamp, rows[-1].id) if more else None
        return Page([item(row) for row in rows], next_cursor)

    def points(self, query: PointQuery) -> Page:
        """A page of track points (oldest first), items :class:`TrackPoint`."""
        c = track_points.c
        conditions: list[ColumnElement[bool]] = [c.site == query.site]
        if query.start_stamp is not None:
            conditions.append(c.stamp >= query.start_stamp)
        if query.end_stamp is not None:
            conditions.append(c.stamp <= query.end_stamp)
        if query.track_id is not None:
            conditions.append(c.track_id == query.track_id)
        if query.station_min_m is not None:
            conditions.append(c.station_m >= query.station_min_m)
        if query.station_max_m is not None:
            conditions.append(c.station_m <= query.station_max_m)
        if query.bbox_deg is not None:
            lon_min, lat_min, lon_max, lat_max = query.bbox_deg
            conditions += [
                c.longitude_deg.between(lon_min, lon_max),
                c.latitude_deg.between(lat_min, lat_max),
            ]
        if query.lane_index is not None:
            conditions.append(c.lane_index == query.lane_index)
        if query.min_speed_mps is not None:
            conditions.append(c.speed_mps >= query.min_speed_mps)
        if query.max_speed_mps is not None:
            conditions.append(c.speed_mps <= query.max_speed_mps)
        if query.smoothed is not None:
            conditions.append(c.smoothed == query.smoothed)
        stmt = self._page_order(
            select(track_points).where(and_(*conditions)),
            track_points,
            query.cursor,
            query.limit,
            newest_first=False,
        )
        return self._page(stmt, query.limit, _track_point)

    def alerts(self, query: AlertQuery) -> Page:
        """A page of alert events, items :class:`Alert`."""
        c = alerts.c
        conditions: list[ColumnElement[bool]] = []
        if query.site is not None:
            conditions.append(c.site == query.site)
        if query.alert_types:
            conditions.append(c.alert_type.in_(query.alert_types))
        if query.severities:
            conditions.append(c.severity.in_(query.severities))
        if query.phases:
            conditions.append(c.phase.in_(query.phases))
        if query.start_stamp is not None:
            conditions.append(c.stamp >= query.start_stamp)
        if query.end_stamp is not None:
            conditions.append(c.stamp <= query.end_stamp)
        if query.track_id is not None:
            conditions.append(c.track_id == query.track_id)
        if query.episode_id is not None:
            conditions.append(c.episode_id == query.episode_id)
        stmt = self._page_order(
            select(alerts).where(and_(true(), *conditions)),
            alerts,
            query.cursor,
            query.limit,
            newest_first=query.newest_first,
        )
        return self._page(stmt, query.limit, _alert)

    def queue_history(self, query: QueueQuery) -> Page:
        """A page of stored queue states, items :class:`QueueState`."""
        c = queue_states.c
        conditions: list[ColumnElement[bool]] = [c.site == query.site]
        if query.start_stamp is not None:
            conditions.append(c.stamp >= query.start_stamp)
        if query.end_stamp is not None:
            conditions.append(c.stamp <= query.end_stamp)
        if query.conditions:
            conditions.append(c.condition.in_(query.conditions))
        stmt = self._page_order(
            select(queue_states).where(and_(*conditions)),
            queue_states,
            query.cursor,
            query.limit,
            newest_first=query.newest_first,
        )
        return self._page(stmt, query.limit, _queue_state)

    def traffic_points(
        self,
        site: str,
        start_stamp: float,
        end_stamp: float,
        station_min_m: float,
        station_max_m: float,
        received_since: float | None = None,
    ) -> TrafficPoints:
        """Fused (not smoothed) points in a stamp window and a station range, as arrays;
        ``received_since`` (wall clock) leaves out earlier runs that used the same stamps."""
        c = track_points.c
        conditions = [
            c.site == site,
            c.stamp >= start_stamp,
            c.stamp <= end_stamp,
            c.station_m >= station_min_m,
            c.station_m <= station_max_m,
            c.smoothed.is_(False),
        ]
        if received_since is not None:
            conditions.append(c.received_at >= received_since)
        stmt = (
            select(
                c.track_id,
                c.stamp,
                c.station_m,
                c.lane_index,
                c.offset_m,
                c.speed_mps,
                c.vx_mps,
                c.vy_mps,
                c.length_m,
                c.x_m,
                c.y_m,
                c.heading_rad,
                c.width_m,
                c.object_class,
            )
            .where(*conditions)
            .order_by(c.track_id, c.stamp)
        )
        with self.engine.connect() as connection:
            rows = connection.execute(stmt).all()
        return TrafficPoints(
            track_id=np.array([r.track_id for r in rows], dtype=np.int64),
            stamp=np.array([r.stamp for r in rows], dtype=np.float64),
            station_m=np.array([r.station_m for r in rows], dtype=np.float64),
            lane_index=np.array([r.lane_index for r in rows], dtype=np.int64),
            offset_m=np.array([r.offset_m for r in rows], dtype=np.float64),
            speed_mps=np.array([r.speed_mps for r in rows], dtype=np.float64),
            vx_mps=np.array([r.vx_mps for r in rows], dtype=np.float64),
            vy_mps=np.array([r.vy_mps for r in rows], dtype=np.float64),
            length_m=np.array(
                [math.nan if r.length_m is None else r.length_m for r in rows], dtype=np.float64
            ),
            x_m=np.array([r.x_m for r in rows], dtype=np.float64),
            y_m=np.array([r.y_m for r in rows], dtype=np.float64),
            heading_rad=np.array([r.heading_rad for r in rows], dtype=np.float64),
            width_m=np.array(
                [math.nan if r.width_m is None else r.width_m for r in rows], dtype=np.float64
            ),
            object_class=[r.object_class for r in rows],
        )

    def trajectories(
        self, site: str, start_stamp: float, end_stamp: float, *, smoothed: bool = False
    ) -> Trajectories:
        """Every fused (or smoothed) point of a stamp window, as the arrays
        :func:`~wz_gateway.conflicts.find_conflicts` takes (vehicle ids: the track ids)."""
        c = track_points.c
        stmt = select(
            c.track_id,
            c.stamp,
            c.x_m,
            c.y_m,
            c.vx_mps,
            c.vy_mps,
            c.heading_rad,
            c.length_m,
            c.width_m,
            c.lane_index,
        ).where(
            c.site == site,
            c.stamp >= start_stamp,
            c.stamp <= end_stamp,
            c.smoothed.is_(smoothed),
        )
        with self.engine.connect() as connection:
            rows = connection.execute(stmt).all()
        columns = list(zip(*rows, strict=True)) if rows else [()] * 10
        return conflict_trajectories([str(track_id) for track_id in columns[0]], *columns[1:])

    def count(self, table_name: str) -> int:
        """Rows in one of the gateway's tables (for tests and metrics)."""
        table = {
            t.name: t
            for t in (
                track_points,
                alerts,
                device_states,
                queue_states,
                calibration_changes,
                latest,
                api_keys,
            )
        }[table_name]
        with self.engine.connect() as connection:
            return int(connection.scalar(select(func.count()).select_from(table)) or 0)

    # --- retention ------------------------------------------------------------------------

    def purge(
        self, now: float, *, retention_days: float, alert_retention_days: float
    ) -> dict[str, int]:
        """Delete what arrived longer ago than the retention; rows deleted per table.

        Track points, device states, queue states and the sensors' changes of calibration
        state go after
        ``retention_days``; alerts and webhook
        deliveries (and delivered, failed or expired outbox entries) after
        ``alert_retention_days``.
        """
        cutoff = now - retention_days * _DAY_S
        alert_cutoff = now - alert_retention_days * _DAY_S
        deleted: dict[str, int] = {}
        with self.engine.begin() as connection:
            for table, limit in (
                (track_points, cutoff),
                (device_states, cutoff),
                (queue_states, cutoff),
                (calibration_changes, cutoff),
                (alerts, alert_cutoff),
            ):
                outcome = connection.execute(delete(table).where(table.c.received_at < limit))
                deleted[table.name] = outcome.rowcount
            outcome = connection.execute(
                delete(webhook_deliveries).where(webhook_deliveries.c.attempted_at < alert_cutoff)
            )
            deleted[webhook_deliveries.name] = outcome.rowcount
            outcome = connection.execute(
                delete(webhook_outbox).where(
                    webhook_outbox.c.created_at < alert_cutoff,
                    or_(
                        webhook_outbox.c.state == "delivered",
                        webhook_outbox.c.state == "failed",
                        webhook_outbox.c.state == "expired",
                    ),
                )
            )
            deleted[webhook_outbox.name] = outcome.rowcount
            # An ended life's record goes with its points (its smoothed ones share their
            # received_at); one still open stays until it ends.
            outcome = connection.execute(
                delete(tracks).where(
                    tracks.c.ended_at.is_not(None), tracks.c.last_received_at < cutoff
                )
            )
            deleted[tracks.name] = outcome.rowcount
        return deleted


# --- rows <-> models ----------------------------------------------------------------------


def _point_row(
    batch: TrackBatch, track: Track, latitude_deg: float, longitude_deg: float, received_at: float
) -> dict[str, Any]:
    return {
        "site": batch.site,
        "track_id": track.track_id,
        "stamp": batch.stamp,
        "x_m": track.x_m,
        "y_m": track.y_m,
        "latitude_deg": latitude_deg,
        "longitude_deg": longitude_deg,
        "station_m": track.station_m,
        "offset_m": track.offset_m,
        "lane_index": track.lane_index,
        "speed_mps": track.speed_mps,
        "heading_rad": track.heading_rad,
        "vx_mps": track.vx_mps,
        "vy_mps": track.vy_mps,
        "object_class": track.object_class.value,
        "status": track.status.value,
        "length_m": track.length_m,
        "width_m": track.width_m,
        "smoothed": False,
        "received_at": received_at,
        "covariance": struct.pack(COVARIANCE_FORMAT, *track.covariance),
    }


def _track_point(row: Any) -> TrackPoint:
    return TrackPoint(
        track_id=row.track_id,
        stamp=row.stamp,
        x_m=row.x_m,
        y_m=row.y_m,
        latitude_deg=row.latitude_deg,
        longitude_deg=row.longitude_deg,
        station_m=row.station_m,
        offset_m=row.offset_m,
        lane_index=row.lane_index,
        speed_mps=row.speed_mps,
        heading_rad=row.heading_rad,
        vx_mps=row.vx_mps,
        vy_mps=row.vy_mps,
        object_class=row.object_class,
        status=row.status,
        length_m=row.length_m,
        width_m=row.width_m,
        smoothed=bool(row.smoothed),
    )


def _queue_state(row: Any) -> QueueState:
    return QueueState(
        site=row.site,
        source_id=row.source_id,
        stamp=row.stamp,
        lanes=[LaneQueue.model_validate(lane) for lane in row.lanes],
    )


def _calibration_or_none(body: str | None) -> SensorCalibration | None:
    """A stored calibration, or None for none or one this gateway cannot read (written by
    another version: the next message starts its history afresh)."""
    if body is None:
        return None
    try:
        return SensorCalibration.model_validate_json(body)
    except ValueError:
        log.warning("a stored sensor calibration is unreadable; its history restarts")
        return None


def _alert(row: Any) -> Alert:
    return Alert(
        site=row.site,
        source_id=row.source_id,
        stamp=row.stamp,
        alert_id=row.alert_id,
        alert_type=row.alert_type,
        severity=row.severity,
        track_id=row.track_id,
        station_m=row.station_m,
        offset_m=row.offset_m,
        speed_mps=row.speed_mps,
        measured_value=row.measured_value,
        threshold_value=row.threshold_value,
        description=row.description,
        phase=row.phase,
        episode_id=row.episode_id,
        onset_stamp=row.onset_stamp,
        value_unit=row.value_unit,
        evidence=row.evidence,
        track=None if row.track is None else Track.model_validate(row.track),
    )
