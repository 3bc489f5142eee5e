"""The HTTP API on a real uvicorn server, through httpx: keys and scopes, pages, CSV and
GeoJSON, clear 4xx problems for bad input, body size and rate limits, CORS, dev mode."""

from __future__ import annotations

import csv
import io
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from pydantic import ValidationError

from tests.gateway.helpers import (
    ADMIN_KEY,
    READ_KEY,
    SITE,
    batch,
    car_batches,
    gateway_settings,
    live_server,
    make_track,
    open_storage,
    sample_alert,
)
from wz_gateway.key_store import KeyStore
from wz_gateway.metrics import GatewayMetrics
from wz_gateway.models import TRACK_POINT_FIELDS
from wz_gateway.settings import GatewaySettings
from wz_gateway.storage import Storage
from wz_shared.messages import AlertSeverity, AlertType, Message

READ = {"X-API-Key": READ_KEY}
ADMIN = {"X-API-Key": ADMIN_KEY}
NOW = 1_750_000_000.0


def fill(storage: Storage) -> None:
    """Two cars, 50 batches of two points each, the newest at 4.9 s; four alerts."""
    left = car_batches(1, 800.0, 30.0, 0.0, 50)
    right = car_batches(2, 820.0, 20.0, 0.0, 50, offset_m=1.83)
    messages: list[Message] = [
        batch(a.stamp, [*a.tracks, *b.tracks], a.cycle_index)
        for a, b in zip(left, right, strict=True)
    ]
    messages += [
        sample_alert("a1", 1.0),
        sample_alert("a2", 2.0, alert_type=AlertType.HARD_BRAKING, severity=AlertSeverity.CRITICAL),
        sample_alert("a3", 3.0, alert_type=AlertType.QUEUE, track_id=None),
        sample_alert("a4", 4.0, phase="clear"),
    ]
    storage.ingest(messages, geo=SITE.geo_frame, received_at=NOW)


class Api:
    """A filled gateway on a live server."""

    def __init__(self, base_url: str, storage: Storage, metrics: GatewayMetrics) -> None:
        self.client = httpx.Client(base_url=base_url, timeout=10.0)
        self.storage = storage
        self.metrics = metrics

    def get(
        self, path: str, headers: dict[str, str] | None = READ, **params: Any
    ) -> httpx.Response:
        return self.client.get(path, headers=headers, params=params)


@pytest.fixture(scope="module")
def api(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Api]:
    settings = gateway_settings(
        tmp_path_factory.mktemp("api"),
        max_page_size=500,
        rate_limit_per_s=1000.0,
        rate_limit_burst=1000,
    )
    storage = open_storage(settings)
    fill(storage)
    metrics = GatewayMetrics()
    with live_server(settings, storage, metrics) as url:
        client = Api(url, storage, metrics)
        yield client
        client.client.close()
    storage.close()


def assert_problem(response: httpx.Response, status: int, *fragments: str) -> dict[str, Any]:
    assert response.status_code == status, response.text
    assert response.headers["content-type"] == "application/problem+json"
    body: dict[str, Any] = response.json()
    assert body["status"] == status and body["title"] and body["detail"]
    for fragment in fragments:
        assert fragment in body["detail"], body
    return body


# --- keys and scopes ----------------------------------------------------------------------


def test_reads_need_a_valid_key(api: Api) -> None:
    response = api.get("/v1/tracks/live", headers=None)
    assert_problem(response, 401, "API key is needed", "X-API-Key")
    assert response.headers["www-authenticate"].startswith("Bearer")
    assert_problem(api.get("/v1/tracks/live", headers={"X-API-Key": "wzk_nope"}), 401, "not valid")
    assert api.get("/v1/tracks/live").status_code == 200
    bearer = {"Authorization": f"Bearer {READ_KEY}"}
    assert api.get("/v1/tracks/live", headers=bearer).status_code == 200
    assert api.get("/v1/tracks/live", headers=ADMIN).status_code == 200  # admin reads too


def test_admin_routes_need_the_admin_scope_and_keys_can_be_made_and_revoked(api: Api) -> None:
    assert_problem(api.get("/v1/admin/api-keys"), 403, "scope 'read'", "'admin' is needed")
    made = api.client.post(
        "/v1/admin/api-keys", headers=ADMIN, json={"scope": "read", "name": "dashboard"}
    )
    assert made.status_code == 201, made.text
    key = made.json()
    assert key["scope"] == "read" and key["origin"] == "api" and key["secret"].startswith("wzk_")
    assert api.get("/v1/site", headers={"X-API-Key": key["secret"]}).status_code == 200
    listed = api.get("/v1/admin/api-keys", headers=ADMIN).json()
    assert key["key_id"] in {k["key_id"] for k in listed}
    assert all("secret" not in k for k in listed)
    revoked = api.client.delete(f"/v1/admin/api-keys/{key['key_id']}", headers=ADMIN)
    assert revoked.status_code == 204 and revoked.content == b""
    assert_problem(api.get("/v1/site", headers={"X-API-Key": key["secret"]}), 401, "not valid")
    assert_problem(
        api.client.delete(f"/v1/admin/api-keys/{key['key_id']}", headers=ADMIN), 404, key["key_id"]
    )
    # A bad body is refused and nothing is made.
    before = len(KeyStore(api.storage.engine).all(include_revoked=True))
    bad = api.client.post("/v1/admin/api-keys", headers=ADMIN, json={"scope": "root", "name": ""})
    body = assert_problem(bad, 422, "body field 'scope'")
    assert {e["location"] for e in body["errors"]} == {"body.scope", "body.name"}
    not_json = api.client.post(
        "/v1/admin/api-keys",
        content=b"{not json",
        headers={**ADMIN, "Content-Type": "application/json"},
    )
    assert_problem(not_json, 422, "the request body", "JSON")
    assert len(KeyStore(api.storage.engine).all(include_revoked=True)) == before


def test_oversize_bodies_get_413_announced_or_streamed(api: Api) -> None:
    big = b'{"scope": "read", "name": "' + b"x" * 100_000 + b'"}'
    headers = {**ADMIN, "Content-Type": "application/json"}
    assert_problem(
        api.client.post("/v1/admin/api-keys", headers=headers, content=big), 413, "over the limit"
    )

    def chunks() -> Iterator[bytes]:  # no Content-Length: the limit counts what arrives
        for start in range(0, len(big), 8192):
            yield big[start : start + 8192]

    assert_problem(
        api.client.post("/v1/admin/api-keys", headers=headers, content=chunks()),
        413,
        "over the limit",
    )


# --- reading ------------------------------------------------------------------------------


def test_live_tracks_and_site(api: Api) -> None:
    live = api.get("/v1/tracks/live").json()
    assert live["stamp"] == pytest.approx(4.9) and live["cycle_index"] == 49
    assert [t["track_id"] for t in live["tracks"]] == [1, 2]
    assert live["tracks"][0]["latitude_deg"] == pytest.approx(40.75 + 947.0 / 111_035, abs=2e-5)
    site = api.get("/v1/site").json()
    assert site["site_id"] == SITE.site_id and site["road_names"] == ["US-75"]


def test_trajectory_pages_follow_the_link_header(api: Api) -> None:
    seen: list[tuple[int, float]] = []
    url: str | None = "/v1/trajectories?limit=13"
    pages = 0
    while url is not None:
        response = api.client.get(url, headers=READ)
        assert response.status_code == 200
        body = response.json()
        assert body["count"] == len(body["points"]) <= 13
        seen += [(p["track_id"], p["stamp"]) for p in body["points"]]
        url = response.links.get("next", {}).get("url")
        assert (url is None) == (body["next_cursor"] is None)
        pages += 1
    assert pages == 8 and len(seen) == 100 and len(set(seen)) == 100
    assert seen == sorted(seen, key=lambda p: p[1])


def test_filters_and_one_track(api: Api) -> None:
    fast = api.get("/v1/trajectories", min_speed=25.0).json()["points"]
    assert {p["track_id"] for p in fast} == {1} and len(fast) == 50
    # Car 2 is at 820-918 m: only its points from 850 m on are in [850, 900].
    window = api.get("/v1/trajectories", track_id=2, station_min=850.0, station_max=900.0)
    assert all(850.0 <= p["station_m"] <= 900.0 for p in window.json()["points"])
    assert len(window.json()["points"]) == 26  # 850, 852, ..., 900
    assert api.get("/v1/trajectories", area="transition").json()["points"] == []
    assert len(api.get("/v1/trajectories", area="advance_warning").json()["points"]) == 100
    track = api.get("/v1/tracks/1", start=1.0, end=2.0).json()
    assert track["track_id"] == 1 and track["count"] == 11
    assert_problem(api.get("/v1/tracks/77"), 404, "track 77")


def test_csv_and_geojson_exports(api: Api) -> None:
    response = api.get("/v1/trajectories", limit=20, format="csv")
    assert response.status_code == 200
    assert response.headers["content-type"].startswith("text/csv")
    assert "attachment" in response.headers["content-disposition"]
    rows = list(csv.DictReader(io.StringIO(response.text)))
    assert tuple(rows[0]) == TRACK_POINT_FIELDS and len(rows) == 20
    as_json = api.get("/v1/trajectories", limit=20).json()["points"]
    assert [float(r["speed_mps"]) for r in rows] == [p["speed_mps"] for p in as_json]
    assert rows[0]["length_m"] == ""  # missing values are empty cells
    assert (
        response.headers["x-next-cursor"]
        == api.get("/v1/trajectories", limit=20).json()["next_cursor"]
    )

    geo = api.get("/v1/trajectories", limit=20, format="geojson")
    assert geo.headers["content-type"] == "application/geo+json"
    collection = geo.json()
    assert collection["type"] == "FeatureCollection" and len(collection["features"]) == 20
    first = collection["features"][0]
    assert first["geometry"] == {
        "type": "Point",
        "coordinates": [as_json[0]["longitude_deg"], as_json[0]["latitude_deg"]],
    }
    assert first["properties"]["track_id"] == as_json[0]["track_id"]
    path = api.get("/v1/tracks/2", format="geojson").json()["features"][0]
    assert path["geometry"]["type"] == "LineString"
    assert len(path["geometry"]["coordinates"]) == len(path["properties"]["stamps"]) == 50


def test_alerts_with_filters(api: Api) -> None:
    body = api.get("/v1/alerts").json()
    assert [a["alert_id"] for a in body["alerts"]] == ["a4", "a3", "a2", "a1"]
    response = api.client.get("/v1/alerts?type=queue&type=hard_braking&order=oldest", headers=READ)
    assert [a["alert_id"] for a in response.json()["alerts"]] == ["a2", "a3"]
    assert [a["alert_id"] for a in api.get("/v1/alerts", severity="critical").json()["alerts"]] == [
        "a2"
    ]
    assert [a["alert_id"] for a in api.get("/v1/alerts", phase="clear").json()["alerts"]] == ["a4"]
    page = api.get("/v1/alerts", limit=3)
    assert page.json()["count"] == 3 and "next" in page.links


def test_alerts_as_csv_and_geojson(api: Api) -> None:
    """`?format=csv` is CSV (it was JSON before), `geojson` a FeatureCollection of Points on
    the road where each vehicle was; both keep the page's filters and its next link."""
    response = api.get("/v1/alerts", format="csv", type="speeding", order="oldest")
    assert response.status_code == 200 and response.headers["content-type"].startswith("text/csv")
    rows = list(csv.DictReader(io.StringIO(response.text)))
    assert [r["alert_id"] for r in rows] == ["a1", "a4"]
    assert rows[0]["alert_type"] == "speeding" and float(rows[0]["station_m"]) == 700.0
    (queue,) = csv.DictReader(io.StringIO(api.get("/v1/alerts", format="csv", type="queue").text))
    assert queue["alert_type"] == "queue" and queue["track_id"] == ""  # no track: empty cell
    geo = api.get("/v1/alerts", format="geojson", limit=3)
    assert geo.headers["content-type"].startswith("application/geo+json")
    body = geo.json()
    assert body["type"] == "FeatureCollection" and len(body["features"]) == 3
    assert "next" in geo.links and body["next_cursor"]
    point = body["features"][-1]["geometry"]  # a2, at station 700 m of the default site
    x, y = SITE.road_frame.to_site(700.0, -1.83)
    latitude, longitude, _ = SITE.geo_frame.to_wgs84(float(x), float(y))
    assert point["coordinates"] == pytest.approx([float(longitude), float(latitude)], abs=1e-6)
    bad = api.get("/v1/alerts", format="xml")
    assert bad.status_code == 422


@pytest.mark.parametrize(
    ("path", "params", "fragments"),
    [
        (
            "/v1/trajectories",
            {"limit": 0},
            ("query parameter 'limit'", "greater than or equal to 1"),
        ),
        ("/v1/trajectories", {"limit": "ten"}, ("query parameter 'limit'", "valid integer")),
        ("/v1/trajectories", {"limit": 501}, ("query parameter 'limit'", "at most 500 per page")),
        ("/v1/trajectories", {"start": 5, "end": 1}, ("start (5.0) is greater than end (1.0)",)),
        ("/v1/trajectories", {"start": "nan"}, ("query parameter 'start'",)),
        ("/v1/trajectories", {"bbox": "1,2,3"}, ("query parameter 'bbox'", "pattern")),
        ("/v1/trajectories", {"bbox": "1e999,0,1,1"}, ("query parameter 'bbox'", "pattern")),
        ("/v1/trajectories", {"bbox": "nan,0,1,1"}, ("query parameter 'bbox'", "pattern")),
        ("/v1/trajectories", {"bbox": "1,2,3,4,5"}, ("query parameter 'bbox'", "pattern")),
        ("/v1/trajectories", {"bbox": "10,50,5,60"}, ("minLon <= maxLon",)),
        ("/v1/trajectories", {"bbox": "200,0,300,1"}, ("-180 <= minLon",)),
        ("/v1/trajectories", {"cursor": "bogus"}, ("query parameter 'cursor'", "next_cursor")),
        ("/v1/trajectories", {"cursor": "a b+c"}, ("query parameter 'cursor'", "pattern")),
        ("/v1/trajectories", {"cursor": "\x00"}, ("query parameter 'cursor'", "pattern")),
        ("/v1/trajectories", {"cursor": "A" * 129}, ("query parameter 'cursor'", "at most 128")),
        ("/v1/alerts", {"cursor": "x=="}, ("query parameter 'cursor'", "pattern")),
        ("/v1/trajectories", {"format": "xml"}, ("query parameter 'format'", "'csv'")),
        ("/v1/trajectories", {"area": "parking"}, ("query parameter 'area'", "'buffer'")),
        ("/v1/trajectories", {"min_speed": 30, "max_speed": 10}, ("min_speed (30.0)",)),
        ("/v1/tracks/-1", {}, ("path parameter 'track_id'",)),
        ("/v1/alerts", {"type": "tailgating"}, ("query parameter 'type.0'", "'speeding'")),
        ("/v1/alerts", {"order": "random"}, ("query parameter 'order'",)),
    ],
)
def test_bad_input_gets_a_clear_422(
    api: Api, path: str, params: dict[str, Any], fragments: tuple[str, ...]
) -> None:
    body = assert_problem(api.get(path, **params), 422, *fragments)
    assert body["errors"] and body["instance"] == path


def _string_schema(schema: dict[str, Any]) -> dict[str, Any]:
    """The string branch of an ``X | None`` schema (or the schema itself)."""
    return next((s for s in schema.get("anyOf", [schema]) if s.get("type") == "string"), schema)


def test_openapi_states_the_cursor_bbox_and_webhook_url_formats(api: Api) -> None:
    """The served document carries the patterns and lengths clients (and fuzzers) go by."""
    spec = api.get("/openapi.json", headers=None).json()
    for path in ("/v1/trajectories", "/v1/alerts"):
        operation = spec["paths"][path]["get"]
        params = {p["name"]: _string_schema(p["schema"]) for p in operation["parameters"]}
        assert params["cursor"]["pattern"] == "^[A-Za-z0-9_-]+$"
        assert params["cursor"]["maxLength"] == 128
    bbox = {
        p["name"]: _string_schema(p["schema"])
        for p in spec["paths"]["/v1/trajectories"]["get"]["parameters"]
    }["bbox"]
    assert bbox["maxLength"] == 83
    assert re.fullmatch(bbox["pattern"], "-84.40,33.74,-84.38,33.76")
    assert not re.fullmatch(bbox["pattern"], "inf,0,1,1")
    url = spec["components"]["schemas"]["NewWebhook"]["properties"]["url"]
    assert url["maxLength"] == 2000 and url["pattern"].startswith("^[Hh][Tt][Tt][Pp][Ss]?://")
    assert re.fullmatch(url["pattern"], "https://alerts.example/hook?a=1")
    assert not re.fullmatch(url["pattern"], "ftp://alerts.example/")
    assert not re.fullmatch(url["pattern"], "https://alerts.example/a b")


def test_operations_endpoints_need_no_key(api: Api) -> None:
    assert api.get("/healthz", headers=None).json() == {"status": "ok"}
    ready = api.get("/readyz", headers=None)
    assert ready.status_code == 200 and ready.json() == {
        "status": "ready",
        "checks": {"database": "ok"},
    }
    api.get("/v1/trajectories", limit=1)
    metrics = api.get("/metrics", headers=None)
    assert metrics.headers["content-type"].startswith("text/plain")
    assert (
        'wz_gateway_http_requests_total{method="GET",route="/v1/trajectories",status="200"}'
        in metrics.text
    )
    assert_problem(api.get("/nowhere", headers=None), 404, "/nowhere")
    assert_problem(api.client.put("/v1/site", headers=READ), 405, "PUT")


# --- settings and deployments -------------------------------------------------------------


def test_settings_refuse_to_run_open(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    for name in ("WZ_GATEWAY_API_KEYS", "WZ_GATEWAY_DEV_MODE", "WZ_GATEWAY_HOST"):
        monkeypatch.delenv(name, raising=False)
    with pytest.raises(ValidationError, match="no API key: set WZ_GATEWAY_API_KEYS"):
        GatewaySettings(data_dir=tmp_path)
    with pytest.raises(ValidationError, match="loopback only"):
        GatewaySettings(data_dir=tmp_path, dev_mode=True, host="0.0.0.0")
    with pytest.raises(ValidationError, match="at least 24 are needed"):
        GatewaySettings(data_dir=tmp_path, api_keys=["admin:short"])
    with pytest.raises(ValidationError, match="too repetitive"):
        GatewaySettings(data_dir=tmp_path, api_keys=["admin:" + "ab" * 20])
    with pytest.raises(ValidationError, match="placeholder"):
        GatewaySettings(data_dir=tmp_path, api_keys=["admin:<your-api-key-here>"])
    with pytest.raises(ValidationError, match="scope 'root'"):
        GatewaySettings(data_dir=tmp_path, api_keys=["root:" + READ_KEY])
    monkeypatch.setenv("WZ_GATEWAY_API_KEYS", f"read:{READ_KEY}, admin:{ADMIN_KEY}")
    monkeypatch.setenv("WZ_GATEWAY_CORS_ORIGINS", "https://a.example,https://b.example")
    settings = GatewaySettings(data_dir=tmp_path)
    assert settings.api_keys == [f"read:{READ_KEY}", f"admin:{ADMIN_KEY}"]
    assert settings.cors_origins == ["https://a.example", "https://b.example"]
    assert READ_KEY not in repr(settings)
    assert settings.resolved_database_url() == f"sqlite:///{tmp_path.resolve()}/gateway.sqlite3"


def test_dev_mode_reads_without_a_key_but_not_admin(tmp_path: Path) -> None:
    settings = GatewaySettings(data_dir=tmp_path, dev_mode=True)
    storage = open_storage(settings)
    with live_server(settings, storage) as url:
        assert httpx.get(f"{url}/v1/tracks/live").json()["tracks"] == []
        assert httpx.get(f"{url}/v1/admin/api-keys").status_code == 401
    dev_keys = [k for k in KeyStore(storage.engine).all() if k.origin == "dev"]
    assert len(dev_keys) == 1 and dev_keys[0].scope == "admin"
    storage.close()


def test_rate_limit_per_key(tmp_path: Path) -> None:
    settings = gateway_settings(tmp_path, rate_limit_per_s=0.5, rate_limit_burst=3)
    storage = open_storage(settings)
    storage.ingest([batch(0.0, [make_track(1, 900.0, 10.0)])], geo=SITE.geo_frame, received_at=NOW)
    with live_server(settings, storage) as url:
        codes = [httpx.get(f"{url}/v1/tracks/live", headers=READ).status_code for _ in range(4)]
        assert codes == [200, 200, 200, 429]
        refused = httpx.get(f"{url}/v1/tracks/live", headers=READ)
        assert_problem(refused, 429, "too many requests")
        assert int(refused.headers["retry-after"]) >= 1
        assert httpx.get(f"{url}/v1/tracks/live", headers=ADMIN).status_code == 200  # own bucket
        assert httpx.get(f"{url}/healthz").status_code == 200  # not limited
    storage.close()


def test_cors_only_for_configured_origins(tmp_path: Path) -> None:
    settings = gateway_settings(tmp_path, cors_origins=["https://dash.example"])
    storage = open_storage(settings)
    with live_server(settings, storage) as url:
        preflight = httpx.options(
            f"{url}/v1/alerts",
            headers={
                "Origin": "https://dash.example",
                "Access-Control-Request-Method": "GET",
                "Access-Control-Request-Headers": "x-api-key",
            },
        )
        assert preflight.status_code == 200
        assert preflight.headers["access-control-allow-origin"] == "https://dash.example"
        allowed = httpx.get(f"{url}/v1/alerts", headers={**READ, "Origin": "https://dash.example"})
        assert allowed.headers["access-control-allow-origin"] == "https://dash.example"
        other = httpx.get(f"{url}/v1/alerts", headers={**READ, "Origin": "https://evil.example"})
        assert "access-control-allow-origin" not in other.headers
    storage.close()
