"""Parquet exports of /v1/trajectories and /v1/tracks/{id}, read back with pyarrow: the CSV's
columns with their types, the same values as the JSON, pages with their cursor in the headers."""

from __future__ import annotations

import csv
import io
import json
import struct
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from tests.gateway.helpers import (
    READ_KEY,
    SITE,
    car_batches,
    gateway_settings,
    live_server,
    open_storage,
)
from wz_gateway.export import PARQUET_SCHEMA, points_parquet
from wz_gateway.models import TRACK_POINT_FIELDS

PARQUET = "application/vnd.apache.parquet"


@pytest.fixture(scope="module")
def http(tmp_path_factory: pytest.TempPathFactory) -> Iterator[httpx.Client]:
    settings = gateway_settings(
        tmp_path_factory.mktemp("parquet"), rate_limit_per_s=1e6, rate_limit_burst=1_000_000
    )
    storage = open_storage(settings)
    batches = [
        *car_batches(1, 900.0, 25.0, 0.0, 40),
        *car_batches(2, 905.0, 20.0, 0.0, 40, offset_m=1.83),
    ]
    # the size on the second half of track 1 only: nulls in the other rows
    batches = [
        b.model_copy(
            update={
                "tracks": [
                    t.model_copy(update={"length_m": 4.5})
                    if t.track_id == 1 and b.stamp >= 2.0
                    else t
                    for t in b.tracks
                ]
            }
        )
        for b in batches
    ]
    storage.ingest(batches, geo=SITE.geo_frame, received_at=1_750_000_000.0)
    with (
        live_server(settings, storage) as base,
        httpx.Client(base_url=base, headers={"X-API-Key": READ_KEY}, timeout=10.0) as client,
    ):
        yield client
    storage.close()


def read_parquet(response: httpx.Response) -> pa.Table:
    assert response.status_code == 200, response.text
    assert response.headers["content-type"] == PARQUET
    table: pa.Table = pq.read_table(io.BytesIO(response.content))
    return table


def test_trajectories_as_parquet_hold_the_csv_columns_typed_and_the_json_values(
    http: httpx.Client,
) -> None:
    response = http.get("/v1/trajectories", params={"format": "parquet", "limit": 100})
    table = read_parquet(response)
    assert 'filename="trajectories.parquet"' in response.headers["content-disposition"]
    header = next(
        csv.reader(
            io.StringIO(http.get("/v1/trajectories", params={"format": "csv", "limit": 1}).text)
        )
    )
    assert table.column_names == [*header, "geometry"] == [*TRACK_POINT_FIELDS, "geometry"]
    assert table.schema.equals(PARQUET_SCHEMA)
    types = {field.name: field.type for field in table.schema}
    assert types["track_id"] == pa.int64() and types["stamp"] == pa.float64()
    assert types["lane_index"] == pa.int16() and types["smoothed"] == pa.bool_()
    assert types["object_class"] == pa.string() and types["speed_mps"] == pa.float64()
    rows: list[dict[str, Any]] = table.drop_columns(["geometry"]).to_pylist()
    expected = http.get("/v1/trajectories", params={"limit": 100}).json()["points"]
    assert rows == expected  # the same numbers to the last bit, None where JSON has null
    # GeoParquet 1.1: each row's point as WKB (lon, lat), the file's metadata says so.
    geo = json.loads(table.schema.metadata[b"geo"])
    assert geo["version"] == "1.1.0" and geo["primary_column"] == "geometry"
    column = geo["columns"]["geometry"]
    assert column["encoding"] == "WKB" and column["geometry_types"] == ["Point"]
    assert "crs" not in column  # the default: OGC:CRS84, longitude and latitude
    for row, wkb in zip(rows, table.column("geometry").to_pylist(), strict=True):
        order, kind, x, y = struct.unpack("<BIdd", wkb)
        assert (order, kind) == (1, 1)
        assert (x, y) == (row["longitude_deg"], row["latitude_deg"])
    lons = [r["longitude_deg"] for r in rows]
    lats = [r["latitude_deg"] for r in rows]
    assert column["bbox"] == [min(lons), min(lats), max(lons), max(lats)]
    assert {r["length_m"] for r in rows if r["track_id"] == 1} == {None, 4.5}


def test_parquet_pages_carry_the_cursor_in_the_headers(http: httpx.Client) -> None:
    collected: list[dict[str, Any]] = []
    params: dict[str, str | int] = {"format": "parquet", "limit": 30}
    pages = 0
    while True:
        response = http.get("/v1/trajectories", params=params)
        collected += read_parquet(response).drop_columns(["geometry"]).to_pylist()
        pages += 1
        cursor = response.headers.get("x-next-cursor")
        if cursor is None:
            assert "link" not in response.headers
            break
        assert (
            response.headers["link"].endswith('; rel="next"')
            and f"cursor={cursor}" in response.headers["link"]
        )
        params = {**params, "cursor": cursor}
    assert pages == 3  # 80 points by 30
    everything = http.get("/v1/trajectories", params={"limit": 1000}).json()["points"]
    assert collected == everything


def test_one_track_as_parquet(http: httpx.Client) -> None:
    response = http.get("/v1/tracks/2", params={"format": "parquet", "smoothed": "false"})
    table = read_parquet(response)
    assert 'filename="track-2.parquet"' in response.headers["content-disposition"]
    assert table.num_rows == 40 and set(table.column("track_id").to_pylist()) == {2}
    assert table.column("stamp").to_pylist() == sorted(table.column("stamp").to_pylist())


def test_an_empty_page_is_a_parquet_file_with_the_columns_and_no_rows(
    http: httpx.Client, tmp_path: Path
) -> None:
    response = http.get("/v1/trajectories", params={"format": "parquet", "start": 1000.0})
    table = read_parquet(response)
    assert table.num_rows == 0 and table.schema.equals(PARQUET_SCHEMA)
    path = tmp_path / "empty.parquet"  # a file other tools open as such
    path.write_bytes(points_parquet([]))
    assert pq.read_schema(path).names == [*TRACK_POINT_FIELDS, "geometry"]
