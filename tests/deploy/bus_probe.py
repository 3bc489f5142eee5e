"""An attacker's (or a misconfigured service's) session on the trailer's network.

Usage: python -m tests.deploy.bus_probe ENDPOINT SITE TLS_DIR [--no-cert]

Opens a Zenoh client session to ENDPOINT with the credentials in TLS_DIR (``--no-cert``: only
its CA, to trust the router, and no certificate of its own), then for 5 s puts a forged
message of each kind the bus carries (an alert, a detection batch, a track batch, the devices'
state, a LiDAR frame, another service's status, the site's description) every 50 ms, each payload naming the kind, and answers queries on the
open-alerts key with a forged reply. Prints ``connected`` or ``refused: <why>`` (exit 3).
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import zenoh

from wz_shared.bus import zenoh_config
from wz_shared.settings import BusSettings

#: Kind -> site-relative key a forged message is put on.
KINDS = {
    "alert": "alerts/speeding",
    "detection": "detections/lidar-mast",
    "tracks": "tracks",
    "devices": "devices/state",
    "raw": "raw/lidar/lidar-mast",
    "points": "points/speed-1",
    "status": "status/alert-service",
    "config": "config/site",
}
PUT_S = 5.0


def main() -> int:
    endpoint, site = sys.argv[1], sys.argv[2]
    settings = BusSettings(mode="client", connect_endpoints=[endpoint], listen_endpoints=[])
    tls_dir = Path(sys.argv[3])
    if "--no-cert" in sys.argv[4:]:
        config = zenoh_config(settings)
        ca = json.dumps(str(tls_dir / "ca.pem"))
        config.insert_json5("transport/link/tls/root_ca_certificate", ca)
    else:
        config = zenoh_config(settings.model_copy(update={"tls_dir": tls_dir}))
    try:
        session = zenoh.open(config)
    except zenoh.ZError as exc:
        print(f"refused: {exc}", flush=True)
        return 3
    print("connected", flush=True)
    queryable = session.declare_queryable(
        f"wz/{site}/alerts/active", lambda query: query.reply(query.key_expr, b"forged")
    )
    deadline = time.monotonic() + PUT_S
    while time.monotonic() < deadline:
        for kind, suffix in KINDS.items():
            session.put(f"wz/{site}/{suffix}", kind.encode())
        time.sleep(0.05)
    queryable.undeclare()
    session.close()  # type: ignore[no-untyped-call]
    return 0


if __name__ == "__main__":
    sys.exit(main())
