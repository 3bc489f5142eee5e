"""``GET /v1/conflicts`` on a real server and SQLite file: the scripted near misses
(:mod:`tests.gateway.conflict_scenes`) stored as track batches come back with their
hand-computed TTC and PET, as JSON and as SSAM's CSV, a page at a time; bad windows are 422."""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Iterator
from typing import Any

import httpx
import pytest

from tests.gateway.conflict_scenes import scene_batches
from tests.gateway.helpers import READ_KEY, SITE, gateway_settings, live_server, open_storage
from wz_gateway.conflicts import SSAM_COLUMNS

READ = {"X-API-Key": READ_KEY}


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> Iterator[httpx.Client]:
    settings = gateway_settings(tmp_path_factory.mktemp("conflicts"), max_page_size=500)
    storage = open_storage(settings)
    storage.ingest(scene_batches(), geo=SITE.geo_frame, received_at=1_750_000_000.0)
    with live_server(settings, storage) as url, httpx.Client(base_url=url, timeout=30.0) as c:
        yield c
    storage.close()


def _get(client: httpx.Client, **params: Any) -> httpx.Response:
    return client.get("/v1/conflicts", headers=READ, params={"start": 0, "end": 10, **params})


def test_conflicts_as_json_match_the_hand_values(client: httpx.Client) -> None:
    response = _get(client)
    assert response.status_code == 200, response.text
    body = response.json()
    assert body["count"] == 2 and body["next_cursor"] is None
    rear, cross = body["conflicts"]  # by tMinTTC: 0.6 s, then 1.3 s
    assert (rear["first_id"], rear["second_id"], rear["conflict_type"]) == ("1", "2", "rear end")
    assert rear["ttc_s"] == pytest.approx(math.sqrt(2.0), abs=2e-4)
    assert rear["pet_s"] == pytest.approx(0.5, abs=1e-6)
    assert rear["drac_mps2"] == pytest.approx(10.0 / 3.0)
    assert (cross["first_id"], cross["second_id"], cross["conflict_type"]) == ("3", "4", "crossing")
    assert cross["pet_s"] == pytest.approx(1.2, abs=1e-6)


def test_conflicts_as_ssam_csv_a_page_at_a_time(client: httpx.Client) -> None:
    first = _get(client, format="csv", limit=1)
    assert first.status_code == 200 and first.headers["content-type"].startswith("text/csv")
    rows = list(csv.reader(io.StringIO(first.text)))
    assert tuple(rows[0]) == SSAM_COLUMNS
    assert len(rows) == 2 and float(rows[1][SSAM_COLUMNS.index("TTC")]) == pytest.approx(
        math.sqrt(2.0), abs=1e-3
    )
    cursor = first.headers["X-Next-Cursor"]
    second = _get(client, format="csv", limit=1, cursor=cursor)
    rows = list(csv.reader(io.StringIO(second.text)))
    assert len(rows) == 2 and rows[1][SSAM_COLUMNS.index("PET")] == "1.200"
    assert "X-Next-Cursor" not in second.headers


def test_thresholds_and_a_quiet_window(client: httpx.Client) -> None:
    assert _get(client, max_pet=1.0).json()["count"] == 1  # the crossing's PET is 1.2 s
    assert _get(client, start=20, end=30).json()["count"] == 0


@pytest.mark.parametrize(
    ("params", "fragment"),
    [
        ({"start": 0, "end": 3601}, "at most 3600 s"),
        ({"start": 10, "end": 5}, "start (10.0) is greater than end"),
        ({"format": "geojson"}, "query parameter 'format'"),
        ({"max_ttc": 0}, "query parameter 'max_ttc'"),
        ({"cursor": "AAAA"}, "cursor"),
    ],
)
def test_bad_queries_get_a_clear_4xx(
    client: httpx.Client, params: dict[str, Any], fragment: str
) -> None:
    response = _get(client, **params)
    assert 400 <= response.status_code < 500, response.text
    assert response.headers["content-type"] == "application/problem+json"
    assert fragment in response.json()["detail"]


def test_the_window_is_required_and_reads_need_a_key(client: httpx.Client) -> None:
    response = client.get("/v1/conflicts", headers=READ, params={"start": 0})
    assert response.status_code == 422 and "query parameter 'end'" in response.json()["detail"]
    assert client.get("/v1/conflicts", params={"start": 0, "end": 1}).status_code == 401
