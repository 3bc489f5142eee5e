"""The generated Python client (clients/python, openapi-python-client on the committed
openapi.json) against a real gateway server on a real SQLite file: the scripted near misses'
conflicts come back through it with their hand-computed TTC and PET, the site, trajectories and
both WZDx feeds parse into its models, a refused request is a Problem; the example dashboard
runs on it. The committed client is what the generator makes of the committed document."""

from __future__ import annotations

import filecmp
import math
import shutil
import subprocess
import sys
import warnings
from collections.abc import Iterator
from pathlib import Path

import pytest
from wz_api_client import AuthenticatedClient
from wz_api_client.api.site import get_site_v1_site_get as site_api
from wz_api_client.api.tracks import get_conflicts_v1_conflicts_get as conflicts_api
from wz_api_client.api.tracks import get_trajectories_v1_trajectories_get as trajectories_api
from wz_api_client.api.wzdx import get_device_feed_v1_wzdx_device_feed_get as device_feed_api
from wz_api_client.api.wzdx import get_work_zone_feed_v1_wzdx_work_zone_feed_get as work_zone_api
from wz_api_client.models import ConflictPage, PointPage, Problem, Site

from tests.gateway.conflict_scenes import TRACK_IDS, scene_batches
from tests.gateway.helpers import READ_KEY, SITE, gateway_settings, live_server, open_storage

ROOT = Path(__file__).resolve().parents[2]
CLIENT = ROOT / "clients" / "python"


@pytest.fixture(scope="module")
def url(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    settings = gateway_settings(tmp_path_factory.mktemp("client"), max_page_size=500)
    storage = open_storage(settings)
    storage.ingest(scene_batches(), geo=SITE.geo_frame, received_at=1_750_000_000.0)
    with live_server(settings, storage) as base_url:
        yield base_url
    storage.close()


def client(url: str, key: str = READ_KEY) -> AuthenticatedClient:
    return AuthenticatedClient(
        base_url=url, token=key, prefix="", auth_header_name="X-API-Key", timeout=30.0
    )


def test_conflicts_through_the_client_match_the_hand_values(url: str) -> None:
    with client(url) as api:
        page = conflicts_api.sync(client=api, start=0.0, end=10.0)
    assert isinstance(page, ConflictPage) and page.count == 2
    rear, cross = page.conflicts
    assert (rear.first_id, rear.second_id, rear.conflict_type.value) == ("1", "2", "rear end")
    assert rear.ttc_s == pytest.approx(math.sqrt(2.0), abs=2e-4)  # the braking follower
    assert rear.pet_s == pytest.approx(0.5, abs=1e-6)
    assert cross.conflict_type.value == "crossing" and cross.pet_s == pytest.approx(1.2, abs=1e-6)


def test_site_trajectories_and_feeds_parse_into_the_models(url: str) -> None:
    with client(url) as api:
        site = site_api.sync(client=api)
        points = trajectories_api.sync(client=api, start=0.0, end=10.0, limit=50)
        devices = device_feed_api.sync(client=api)
        work_zone = work_zone_api.sync(client=api)
    assert isinstance(site, Site) and site.site_id == SITE.site_id
    assert len(site.lanes) == len(SITE.lanes)
    assert isinstance(points, PointPage) and len(points.points) == 50
    assert {p.track_id for p in points.points} <= set(TRACK_IDS.values())
    assert devices is not None and not isinstance(devices, Problem)
    assert devices.to_dict()["feed_info"]["version"] == "4.2"
    assert work_zone is not None and not isinstance(work_zone, Problem)
    assert work_zone.to_dict()["features"][0]["properties"]["core_details"]["event_type"] == (
        "work-zone"
    )


def test_a_refused_request_is_a_problem_not_an_exception(url: str) -> None:
    with client(url) as api:
        too_long = conflicts_api.sync_detailed(client=api, start=0.0, end=7200.0)
    assert too_long.status_code == 422
    assert isinstance(too_long.parsed, Problem) and "3600" in str(too_long.parsed.detail)
    with client(url, key="not-a-key") as api:
        refused = conflicts_api.sync_detailed(client=api, start=0.0, end=10.0)
    assert refused.status_code == 401 and isinstance(refused.parsed, Problem)


def test_the_example_dashboard_runs_on_the_client(url: str) -> None:
    script = CLIENT / "examples" / "dashboard.py"
    args = [sys.executable, str(script), "--url", url, "--once"]
    shown = subprocess.run(
        [*args, "--key", READ_KEY], capture_output=True, text=True, timeout=60, check=False
    )
    assert shown.returncode == 0, shown.stderr
    out = shown.stdout
    assert f"site {SITE.site_id}" in out and "vehicles tracked now:" in out
    assert "device dynamic-message-sign:" in out
    assert "conflicts over" in out and "rear end 1" in out and "crossing 1" in out
    refused = subprocess.run(
        [*args, "--key", "nope"], capture_output=True, text=True, timeout=60, check=False
    )
    assert refused.returncode == 2 and "dashboard: site:" in refused.stderr


def test_the_committed_client_is_what_the_generator_makes(tmp_path: Path) -> None:
    generator = shutil.which("openapi-python-client")
    assert generator, "openapi-python-client (a dev dependency) is missing: uv sync"
    out = tmp_path / "wz_api_client"
    result = subprocess.run(
        [
            generator,
            "generate",
            "--path",
            str(ROOT / "services" / "gateway" / "openapi.json"),
            "--meta",
            "none",
            "--config",
            str(CLIENT / "openapi-python-client.yml"),
            "--output-path",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert "Warning" not in result.stdout, result.stdout
    committed = CLIENT / "src" / "wz_api_client"
    for source in committed.rglob("*.py"):  # compiles without a warning (a SyntaxWarning is
        with warnings.catch_warnings():  # an error here)
            warnings.simplefilter("error")
            compile(source.read_text(), str(source), "exec")
    differ = _differences(filecmp.dircmp(out, committed, ignore=["__pycache__"]))
    assert not differ, f"regenerate clients/python (README): {differ[:5]}"


def _differences(cmp: filecmp.dircmp[str]) -> list[str]:
    found = [*cmp.left_only, *cmp.right_only, *cmp.diff_files]
    for sub in cmp.subdirs.values():
        found += _differences(sub)
    return found
