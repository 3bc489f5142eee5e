"""`wz up --site` on a site the project was never tuned on (issue 25): a generated 3-to-2 lane
drop with its own sensor ids and a 1920x1080 camera. Every service publishes on the site's own
keys, the tracks come from both detectors, and the gateway serves tracks and alerts."""

from __future__ import annotations

import time
from pathlib import Path

import httpx
import pytest

from tests.cli.procs import free_port, port_open, running, start_wz_up, wait_for
from wz_eval.site_tool import site_yaml
from wz_shared.bus import Bus
from wz_shared.messages import DetectionBatch, TrackBatch
from wz_shared.settings import BusSettings
from wz_shared.site import CameraIntrinsics, Site
from wz_shared.site_generator import generate_site

#: Runs `wz up`, whose services serve metrics on fixed ports: one such test at a time (pytest-xdist
#: group; the Makefile runs -n auto --dist loadgroup).
pytestmark = pytest.mark.xdist_group("stack")


def a_site_unlike_the_default() -> Site:
    """The first generated site (from seed 3000) with three lanes and a 1920x1080 camera."""
    for seed in range(3000, 3200):
        site = generate_site(seed)
        camera = next(m for m in site.sensors if m.kind == "camera")
        assert isinstance(camera.intrinsics, CameraIntrinsics)
        if len(site.lanes) == 3 and camera.intrinsics.width_px == 1920:
            return site
    raise AssertionError("no such site in 200 seeds")


def test_wz_up_runs_a_generated_site_end_to_end(tmp_path: Path) -> None:
    site = a_site_unlike_the_default()
    ids = {m.kind: m.sensor_id for m in site.sensors}
    assert ids["lidar"] != "lidar-mast" and ids["camera"] != "camera-mast"
    site_file = tmp_path / "site.yaml"
    site_file.write_text(site_yaml(site), encoding="utf-8")
    port, http_port = free_port(), free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    up = start_wz_up(tmp_path, endpoint, http_port, "--site", str(site_file), "--seed", "4")
    settings = BusSettings(mode="client", connect_endpoints=[endpoint], listen_endpoints=[])
    base = f"http://127.0.0.1:{http_port}"
    with running(up):
        wait_for(lambda: port_open(port), 30.0, "the router to listen")
        with Bus.open(settings, site=site.site_id, service="generated-site-test") as bus:
            detections: dict[str, int] = {}
            bus.on(
                bus.keys.detections_all,
                DetectionBatch,
                lambda _key, m: detections.__setitem__(
                    m.source_id, detections.get(m.source_id, 0) + len(m.detections)
                ),
            )
            tracks = bus.subscribe(bus.keys.tracks, TrackBatch, mode="ring", capacity=1)
            sources: set[str] = set()
            alerts: list[dict[str, object]] = []
            stored_tracks = 0
            deadline = time.monotonic() + 300.0
            while time.monotonic() < deadline:
                batch = tracks.recv(1.0)
                if batch is not None:
                    for track in batch.tracks:
                        sources.update(track.sources)
                if {ids["lidar"], ids["camera"]} <= sources and not alerts:
                    reply = httpx.get(f"{base}/v1/alerts", params={"limit": 5}, timeout=10.0)
                    if reply.status_code == 200:
                        alerts = reply.json()["alerts"]
                if alerts:
                    reply = httpx.get(f"{base}/v1/trajectories", params={"limit": 5}, timeout=10.0)
                    stored_tracks = reply.json()["count"] if reply.status_code == 200 else 0
                    if stored_tracks:
                        break
    text = (tmp_path / "up.log").read_text()
    # Both detectors found vehicles on this site's own keys; the tracks fuse them.
    assert detections.get(ids["lidar"], 0) > 0 and detections.get(ids["camera"], 0) > 0, (
        detections,
        text[-3000:],
    )
    assert {ids["lidar"], ids["camera"]} <= sources, (sources, text[-3000:])
    assert alerts, text[-3000:]
    assert all(alert["site"] == site.site_id for alert in alerts)
    assert stored_tracks > 0
    assert "wrong_size" not in text and "does not contain the detector" not in text
    assert "Traceback" not in text, text[-3000:]
