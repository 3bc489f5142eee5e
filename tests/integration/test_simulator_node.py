"""The simulator node as a real process: truth over Zenoh, site queryable, health, shutdown."""

from __future__ import annotations

import itertools
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from wz_shared.bus import Bus
from wz_shared.messages import GroundTruth, ServiceStatus
from wz_shared.settings import BusSettings
from wz_shared.site import DEFAULT_SITE_PATH, Site, load_site

ROOT = Path(__file__).resolve().parents[2]


def test_simulator_node_publishes_truth_and_serves_site(port: int, tmp_path: Path) -> None:
    site = load_site(DEFAULT_SITE_PATH)
    settings = BusSettings(listen_endpoints=[f"tcp/127.0.0.1:{port}"], connect_endpoints=[])
    with Bus.open(settings, site=site.site_id, service="node-test") as bus:
        truth = bus.subscribe(bus.keys.truth, GroundTruth)
        status = bus.subscribe(bus.keys.status("simulator"), ServiceStatus)
        env = {
            **os.environ,
            "WZ_BUS_CONNECT_ENDPOINTS": f"tcp/127.0.0.1:{port}",
            "WZ_BUS_LISTEN_ENDPOINTS": "",
            "WZ_SIM_REALTIME_FACTOR": "4",
            "WZ_SIM_WORK_DIR": str(tmp_path),
            "WZ_STATUS_PERIOD_S": "0.5",
        }
        node = subprocess.Popen([sys.executable, "-m", "wz_simulator.node"], cwd=ROOT, env=env)
        try:
            messages: list[GroundTruth] = []
            deadline = time.monotonic() + 60.0
            while time.monotonic() < deadline and not any(m.vehicles for m in messages[-1:]):
                message = truth.recv(5.0)
                assert message is not None, "no truth from the simulator"
                messages.append(message)
            assert messages[-1].vehicles, "no vehicle appeared within 60 s"
            steps = [m.step_index for m in messages]
            assert steps == list(range(steps[0], steps[0] + len(steps)))  # FIFO: none lost
            stamps = [m.stamp for m in messages]
            assert all(abs((b - a) - 0.05) < 1e-6 for a, b in itertools.pairwise(stamps))
            vehicle = messages[-1].vehicles[0]
            assert vehicle.station_m < 300 and vehicle.speed_mps > 10
            health = status.recv(10.0)
            assert health is not None and health.pid == node.pid
            assert bus.alive() == [bus.keys.status("simulator")]
            served = bus.query_bytes(bus.keys.config_site, timeout_s=5.0)
            assert len(served) == 1 and Site.model_validate_json(served[0]) == site
        finally:
            node.send_signal(signal.SIGTERM)
            assert node.wait(15.0) == 0
        # Gone from liveliness once stopped.
        deadline = time.monotonic() + 5.0
        while bus.alive() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert bus.alive() == []
