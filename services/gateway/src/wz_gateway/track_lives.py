"""The track lives in the database (table ``tracks``) and the smoothed points written when one
ends; :mod:`wz_gateway.track_ends` decides when that is.

A life is recorded (:meth:`TrackLifeStore.record`) before its first points are written, so a
crash never leaves points of an unrecorded life; when it ends, its fused points are read back
(:meth:`~TrackLifeStore.points`), smoothed, and written as ``smoothed`` points in the
transaction that marks it ended (:meth:`~TrackLifeStore.finish`). The same database as
:class:`~wz_gateway.storage.Storage` (which purges ended lives with their points): build it
on ``storage.engine``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from sqlalchemy import Connection, Engine, func, insert, select, update

from wz_gateway.smoothing import StoredTrajectory
from wz_gateway.tables import track_points, tracks
from wz_shared.motion import ProcessNoise


@dataclass
class TrackLife:
    """One life of a track id (see :mod:`wz_gateway.track_ends`); ``last_*`` are those of its
    newest stored batch, ``life_id`` its row in ``tracks`` (None until recorded),
    ``process_noise`` that of its first batch, which it is smoothed with (None: not known, an
    older row; the model's defaults)."""

    track_id: int
    first_stamp: float
    first_received_at: float
    last_stamp: float
    last_received_at: float
    life_id: int | None = None
    process_noise: ProcessNoise | None = None


class TrackLifeStore:
    """Record, read back and finish track lives. Thread-safe (a connection per call)."""

    def __init__(self, engine: Engine) -> None:
        self.engine = engine

    def record(self, site: str, lives: Sequence[TrackLife]) -> None:
        """Record lives that start (before their first points are written); sets ``life_id``."""
        with self.engine.begin() as connection:
            for life in lives:
                life.life_id = _insert_life(connection, site, life)

    def unfinished(self, site: str) -> list[TrackLife]:
        """Lives recorded and not yet ended (a gateway stopped meanwhile), oldest first, each
        up to its newest stored point (its first batch's stamp when none was stored)."""
        t, c = tracks.c, track_points.c
        with self.engine.connect() as connection:
            rows = connection.execute(
                select(tracks).where(t.site == site, t.ended_at.is_(None)).order_by(t.id)
            ).all()
            lives = []
            for row in rows:
                # Its points end where the next life of the same id begins.
                following = connection.scalar(
                    select(func.min(t.first_received_at)).where(
                        t.site == site, t.track_id == row.track_id, t.id > row.id
                    )
                )
                conditions = [
                    c.site == site,
                    c.track_id == row.track_id,
                    c.smoothed.is_(False),
                    c.stamp >= row.first_stamp,
                    c.received_at >= row.first_received_at,
                ]
                if following is not None:
                    conditions.append(c.received_at < following)
                newest = connection.execute(
                    select(c.stamp, c.received_at)
                    .where(*conditions)
                    .order_by(c.received_at.desc(), c.stamp.desc())
                    .limit(1)
                ).first()
                last_stamp, last_received_at = (
                    (row.first_stamp, row.first_received_at)
                    if newest is None
                    else (newest.stamp, newest.received_at)
                )
                lives.append(
                    TrackLife(
                        row.track_id,
                        row.first_stamp,
                        row.first_received_at,
                        last_stamp,
                        last_received_at,
                        life_id=row.id,
                        process_noise=_noise_of(row),
                    )
                )
        return lives

    def points(self, site: str, life: TrackLife) -> StoredTrajectory:
        """The fused points of one life (those stored with a covariance), oldest first."""
        c = track_points.c
        numbers = (
            c.stamp,
            c.x_m,
            c.y_m,
            c.vx_mps,
            c.vy_mps,
            c.latitude_deg,
            c.longitude_deg,
            c.station_m,
            c.offset_m,
            c.speed_mps,
            c.heading_rad,
            c.length_m,
            c.width_m,
            c.received_at,
        )
        stmt = (
            select(*numbers, c.lane_index, c.object_class, c.status, c.covariance)
            .where(
                c.site == site,
                c.track_id == life.track_id,
                c.smoothed.is_(False),
                c.stamp.between(life.first_stamp, life.last_stamp),
                c.received_at.between(life.first_received_at, life.last_received_at),
                c.covariance.is_not(None),
            )
            .order_by(c.stamp, c.id)
        )
        with self.engine.connect() as connection:
            rows = connection.execute(stmt).all()
        # One float array per numeric column (None, a missing size, becomes NaN).
        table = np.array([row[: len(numbers)] for row in rows], dtype=np.float64)
        column = dict(
            zip((n.name for n in numbers), table.reshape(-1, len(numbers)).T, strict=True)
        )
        return StoredTrajectory(
            track_id=life.track_id,
            stamp=column["stamp"],
            x_m=column["x_m"],
            y_m=column["y_m"],
            vx_mps=column["vx_mps"],
            vy_mps=column["vy_mps"],
            covariance=np.frombuffer(b"".join(r.covariance for r in rows), dtype="<f8")
            .astype(np.float64)
            .reshape(-1, 4, 4),
            latitude_deg=column["latitude_deg"],
            longitude_deg=column["longitude_deg"],
            station_m=column["station_m"],
            offset_m=column["offset_m"],
            lane_index=np.array([r.lane_index for r in rows], dtype=np.int64),
            speed_mps=column["speed_mps"],
            heading_rad=column["heading_rad"],
            object_class=tuple(r.object_class for r in rows),
            status=tuple(r.status for r in rows),
            length_m=column["length_m"],
            width_m=column["width_m"],
            received_at=column["received_at"],
        )

    def finish(
        self, site: str, life: TrackLife, smoothed: StoredTrajectory | None, *, ended_at: float
    ) -> bool:
        """Mark a life ended and write its smoothed points, in one transaction; False (and
        nothing written) when it was already ended: a life is never smoothed twice."""
        t = tracks.c
        done = {
            "last_stamp": life.last_stamp,
            "last_received_at": life.last_received_at,
            "ended_at": ended_at,
            "smoothed_points": 0 if smoothed is None else len(smoothed),
        }
        with self.engine.begin() as connection:
            if life.life_id is None:  # its start could not be recorded: recorded now, ended
                life.life_id = _insert_life(connection, site, life, **done)
            else:
                claimed = connection.execute(
                    update(tracks).where(t.id == life.life_id, t.ended_at.is_(None)).values(**done)
                )
                if claimed.rowcount != 1:
                    return False
            if smoothed is not None and len(smoothed):
                connection.execute(insert(track_points), _smoothed_rows(site, smoothed))
        return True


def _insert_life(connection: Connection, site: str, life: TrackLife, **ended: float) -> int:
    """A ``tracks`` row for ``life`` (its start, its process noise, and ``ended`` columns when
    it is recorded already ended); the row's id."""
    row = insert(tracks).values(
        site=site,
        track_id=life.track_id,
        first_stamp=life.first_stamp,
        first_received_at=life.first_received_at,
        **ended,
        **_noise_columns(life.process_noise),
    )
    return int(connection.execute(row.returning(tracks.c.id)).scalar_one())


def _noise_columns(noise: ProcessNoise | None) -> dict[str, float | None]:
    """A track life's process noise as its columns in ``tracks`` (None: not known)."""
    return {
        "sigma_along_mps2": None if noise is None else noise.sigma_along_mps2,
        "sigma_across_mps2": None if noise is None else noise.sigma_across_mps2,
        "heading_min_speed_mps": None if noise is None else noise.heading_min_speed_mps,
    }


def _noise_of(row: Any) -> ProcessNoise | None:
    """The process noise stored with a ``tracks`` row; None where it has none (older rows)."""
    values = (row.sigma_along_mps2, row.sigma_across_mps2, row.heading_min_speed_mps)
    return None if any(v is None for v in values) else ProcessNoise(*values)


def _smoothed_rows(site: str, smoothed: StoredTrajectory) -> list[dict[str, Any]]:
    def optional(value: float) -> float | None:
        return None if math.isnan(value) else value

    return [
        {
            "site": site,
            "track_id": smoothed.track_id,
            "stamp": float(smoothed.stamp[k]),
            "x_m": float(smoothed.x_m[k]),
            "y_m": float(smoothed.y_m[k]),
            "latitude_deg": float(smoothed.latitude_deg[k]),
            "longitude_deg": float(smoothed.longitude_deg[k]),
            "station_m": float(smoothed.station_m[k]),
            "offset_m": float(smoothed.offset_m[k]),
            "lane_index": int(smoothed.lane_index[k]),
            "speed_mps": float(smoothed.speed_mps[k]),
            "heading_rad": float(smoothed.heading_rad[k]),
            "vx_mps": float(smoothed.vx_mps[k]),
            "vy_mps": float(smoothed.vy_mps[k]),
            "object_class": smoothed.object_class[k],
            "status": smoothed.status[k],
            "length_m": optional(float(smoothed.length_m[k])),
            "width_m": optional(float(smoothed.width_m[k])),
            "smoothed": True,
            "received_at": float(smoothed.received_at[k]),
            "covariance": smoothed.covariance[k].astype("<f8").tobytes(),
        }
        for k in range(len(smoothed))
    ]
