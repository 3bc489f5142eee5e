"""Track points as CSV, GeoJSON and Parquet, alert events as CSV and GeoJSON: pure, no I/O.

CSV: one row per point, the columns of :data:`~wz_gateway.models.TRACK_POINT_FIELDS` (units in
the names), an empty cell for a missing value. GeoJSON (RFC 7946): positions are
``[longitude, latitude]`` in WGS84; a page of points is a FeatureCollection of Point features
whose properties are the other columns; one track's trajectory is a LineString feature.
Parquet: the CSV's columns, typed (:data:`PARQUET_SCHEMA`: 64-bit floats, integers, strings
for the class and status, a boolean ``smoothed``, nulls for a missing size), then a
``geometry`` column (each point as WKB, longitude and latitude) with the GeoParquet 1.1 ``geo``
metadata (encoding WKB, Point, the page's bounding box; no ``crs``: GeoParquet's default,
OGC:CRS84, longitude and latitude on WGS 84), so GIS tools (GeoPandas, QGIS, DuckDB spatial)
open it as points; zstd-compressed; the bytes of one file per page.
"""

from __future__ import annotations

import csv
import io
import json
import struct
from collections.abc import Mapping, Sequence
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from wz_gateway.models import TRACK_POINT_FIELDS, TrackPoint
from wz_shared.messages import Alert
from wz_shared.site import Site

_PROPERTY_FIELDS = tuple(
    f for f in TRACK_POINT_FIELDS if f not in ("latitude_deg", "longitude_deg")
)


#: The GeoJSON FeatureCollection an export answers, for the OpenAPI document.
FEATURE_COLLECTION_SCHEMA: dict[str, Any] = {
    "type": "object",
    "required": ["type", "features"],
    "properties": {
        "type": {"const": "FeatureCollection"},
        "features": {"type": "array", "items": {"type": "object"}},
    },
}


def _csv(fields: Sequence[str], models: Sequence[Any]) -> str:
    """A header line of ``fields``, then one line per model, an empty cell for a missing value
    (``\\r\\n`` line ends, as RFC 4180 asks)."""
    out = io.StringIO()
    writer = csv.writer(out)
    writer.writerow(fields)
    for model in models:
        row = model.model_dump(mode="json")
        writer.writerow("" if row.get(name) is None else row[name] for name in fields)
    return out.getvalue()


def points_csv(points: Sequence[TrackPoint]) -> str:
    """The points as CSV, the columns of :data:`TRACK_POINT_FIELDS`."""
    return _csv(TRACK_POINT_FIELDS, points)


#: The GeoParquet geometry column: each point as WKB.
GEOMETRY_COLUMN = "geometry"
GEOPARQUET_VERSION = "1.1.0"

#: The Parquet columns: those of the CSV, in its order, with their types (only the size may be
#: missing: null), then the geometry.
PARQUET_SCHEMA = pa.schema(
    [
        pa.field(
            name,
            {
                "track_id": pa.int64(),
                "lane_index": pa.int16(),
                "object_class": pa.string(),
                "status": pa.string(),
                "smoothed": pa.bool_(),
            }.get(name, pa.float64()),
            nullable=name in ("length_m", "width_m"),
        )
        for name in TRACK_POINT_FIELDS
    ]
    + [pa.field(GEOMETRY_COLUMN, pa.binary(), nullable=False)]
)


def _wkb_point(longitude_deg: float, latitude_deg: float) -> bytes:
    """A WKB Point (ISO/OGC simple features): little-endian, type 1, x = lon, y = lat."""
    return struct.pack("<BIdd", 1, 1, longitude_deg, latitude_deg)


def geo_metadata(points: Sequence[TrackPoint]) -> dict[str, Any]:
    """The GeoParquet 1.1 ``geo`` file metadata of a page of points."""
    column: dict[str, Any] = {"encoding": "WKB", "geometry_types": ["Point"]}
    if points:
        lons = [p.longitude_deg for p in points]
        lats = [p.latitude_deg for p in points]
        column["bbox"] = [min(lons), min(lats), max(lons), max(lats)]
    return {
        "version": GEOPARQUET_VERSION,
        "primary_column": GEOMETRY_COLUMN,
        "columns": {GEOMETRY_COLUMN: column},
    }


def points_parquet(points: Sequence[TrackPoint]) -> bytes:
    """One Parquet file of the points (a row group; no rows for no points)."""
    rows = [point.model_dump(mode="json") for point in points]
    columns = {name: [row[name] for row in rows] for name in TRACK_POINT_FIELDS}
    columns[GEOMETRY_COLUMN] = [_wkb_point(p.longitude_deg, p.latitude_deg) for p in points]
    table = pa.Table.from_pydict(columns, schema=PARQUET_SCHEMA)
    table = table.replace_schema_metadata({"geo": json.dumps(geo_metadata(points))})
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink, compression="zstd")
    data: bytes = sink.getvalue().to_pybytes()
    return data


def _position(point: TrackPoint) -> list[float]:
    return [point.longitude_deg, point.latitude_deg]


def points_geojson(
    points: Sequence[TrackPoint], *, next_cursor: str | None = None
) -> dict[str, Any]:
    """A FeatureCollection of Point features; ``next_cursor`` as a foreign member."""
    features = []
    for point in points:
        row = point.model_dump(mode="json")
        features.append(
            {
                "type": "Feature",
                "geometry": {"type": "Point", "coordinates": _position(point)},
                "properties": {name: row[name] for name in _PROPERTY_FIELDS},
            }
        )
    return {"type": "FeatureCollection", "features": features, "next_cursor": next_cursor}


def trajectory_geojson(
    site: str, track_id: int, points: Sequence[TrackPoint], *, next_cursor: str | None = None
) -> dict[str, Any]:
    """A FeatureCollection of one feature: the track's path (a LineString, or a Point when
    the page has a single point; no feature when it has none), with per-vertex stamps and
    speeds as properties."""
    features = []
    if points:
        coordinates = [_position(p) for p in points]
        geometry = (
            {"type": "LineString", "coordinates": coordinates}
            if len(coordinates) > 1
            else {"type": "Point", "coordinates": coordinates[0]}
        )
        features.append(
            {
                "type": "Feature",
                "geometry": geometry,
                "properties": {
                    "site": site,
                    "track_id": track_id,
                    "start_stamp": points[0].stamp,
                    "end_stamp": points[-1].stamp,
                    "stamps": [p.stamp for p in points],
                    "speeds_mps": [p.speed_mps for p in points],
                    "smoothed": [p.smoothed for p in points],
                },
            }
        )
    return {"type": "FeatureCollection", "features": features, "next_cursor": next_cursor}


#: The columns of an alert page as CSV, units in the names (the evidence and the track are left
#: to JSON: nested, and per rule).
ALERT_FIELDS = (
    "site",
    "alert_id",
    "episode_id",
    "alert_type",
    "severity",
    "phase",
    "stamp",
    "onset_stamp",
    "track_id",
    "station_m",
    "offset_m",
    "speed_mps",
    "measured_value",
    "threshold_value",
    "value_unit",
    "description",
)


def alerts_csv(alerts: Sequence[Alert]) -> str:
    """The alert events as CSV, the columns of :data:`ALERT_FIELDS`."""
    return _csv(ALERT_FIELDS, alerts)


def alerts_geojson(
    alerts: Sequence[Alert], sites: Mapping[str, Site], *, next_cursor: str | None = None
) -> dict[str, Any]:
    """A FeatureCollection of Point features, one per alert event where the vehicle was (its
    station and offset on its site's road; a site-wide event, such as a queue's, at its
    station on the centreline), the CSV's columns as properties."""
    features = []
    for alert in alerts:
        site = sites.get(alert.site)
        geometry = None
        if site is not None and alert.station_m is not None:
            x, y = site.road_frame.to_site(alert.station_m, alert.offset_m or 0.0)
            latitude, longitude, _ = site.geo_frame.to_wgs84(float(x), float(y))
            geometry = {
                "type": "Point",
                "coordinates": [round(float(longitude), 7), round(float(latitude), 7)],
            }
        row = alert.model_dump(mode="json")
        features.append(
            {
                "type": "Feature",
                "id": alert.alert_id,
                "geometry": geometry,
                "properties": {name: row.get(name) for name in ALERT_FIELDS},
            }
        )
    collection: dict[str, Any] = {"type": "FeatureCollection", "features": features}
    if next_cursor is not None:
        collection["next_cursor"] = next_cursor
    return collection
