"""A text dashboard of one work zone, from the gateway's API through the generated client.

    python clients/python/examples/dashboard.py --url http://127.0.0.1:8000 --key KEY [--once]

Every ``--every-s`` seconds (once with ``--once``) it prints: the site and its closure, the
gateway's readiness, the vehicles tracked now, the last hour's alerts by type, the WZDx
devices' status (sign message included) and the traffic conflicts of the last ``--window-s``
seconds by SSAM type with the smallest TTC and PET. A reading key (``WZ_API_KEY``) is enough.
Exit status: 0, or 2 when the gateway refuses the key or cannot be reached.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections import Counter
from typing import Any

import httpx
from wz_api_client import AuthenticatedClient
from wz_api_client.api.alerts import get_alerts_v1_alerts_get as alerts_api
from wz_api_client.api.operations import readyz_readyz_get as readyz_api
from wz_api_client.api.site import get_site_v1_site_get as site_api
from wz_api_client.api.tracks import get_conflicts_v1_conflicts_get as conflicts_api
from wz_api_client.api.tracks import get_live_tracks_v1_tracks_live_get as live_api
from wz_api_client.api.wzdx import get_device_feed_v1_wzdx_device_feed_get as devices_api
from wz_api_client.models import AlertPage, ConflictPage, LiveTracks, Problem, Site


class DashboardError(RuntimeError):
    pass


def _ok(value: Any, what: str) -> Any:
    if value is None or isinstance(value, Problem):
        detail = getattr(value, "detail", None) or "no answer"
        raise DashboardError(f"{what}: {detail}")
    return value


def snapshot(client: AuthenticatedClient, window_s: float) -> list[str]:
    """The dashboard's lines, now."""
    site = _ok(site_api.sync(client=client), "site")
    assert isinstance(site, Site)
    lines = [f"site {site.site_id}: {site.name}"]
    ready = readyz_api.sync_detailed(client=client)
    lines.append(f"gateway: {'ready' if ready.status_code == 200 else 'not ready'}")
    live = _ok(live_api.sync(client=client), "live tracks")
    assert isinstance(live, LiveTracks)
    lines.append(f"vehicles tracked now: {len(live.tracks)} (as of stamp {live.stamp})")
    alerts = _ok(alerts_api.sync(client=client, limit=500), "alerts")
    assert isinstance(alerts, AlertPage)
    starts = Counter(a.alert_type.value for a in alerts.alerts if a.phase.value == "start")
    lines.append(
        "alerts (newest 500, starts): "
        + (", ".join(f"{kind} {n}" for kind, n in sorted(starts.items())) or "none")
    )
    feed = devices_api.sync(client=client)
    if feed is not None and not isinstance(feed, Problem):
        for feature in feed.to_dict()["features"]:
            core = feature["properties"]["core_details"]
            message = feature["properties"].get("message_multi_string")
            shown = f" showing {message!r}" if message else ""
            lines.append(f"device {core['device_type']}: {core['device_status']}{shown}")
    end = float(live.stamp or 0.0)
    start = max(0.0, end - window_s)
    if end > start:
        page = _ok(conflicts_api.sync(client=client, start=start, end=end), "conflicts")
        assert isinstance(page, ConflictPage)
        kinds = Counter(c.conflict_type.value for c in page.conflicts)
        ttc = [c.ttc_s for c in page.conflicts]
        pet = [c.pet_s for c in page.conflicts if isinstance(c.pet_s, float)]
        lines.append(
            f"conflicts over {end - start:.0f} s: {page.count}"
            + (f" ({', '.join(f'{k} {n}' for k, n in sorted(kinds.items()))})" if kinds else "")
            + (f", min TTC {min(ttc):.2f} s" if ttc else "")
            + (f", min PET {min(pet):.2f} s" if pet else "")
        )
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--url", default="http://127.0.0.1:8000")
    parser.add_argument("--key", default=os.environ.get("WZ_API_KEY", ""), help="or WZ_API_KEY")
    parser.add_argument("--every-s", type=float, default=5.0)
    parser.add_argument("--window-s", type=float, default=600.0, help="conflicts' window")
    parser.add_argument("--once", action="store_true")
    args = parser.parse_args(argv)
    if not 0.0 < args.window_s <= 3600.0:
        parser.error("--window-s must be in (0, 3600]")
    client = AuthenticatedClient(
        base_url=args.url, token=args.key, prefix="", auth_header_name="X-API-Key", timeout=10.0
    )
    with client:
        while True:
            try:
                lines = snapshot(client, args.window_s)
            except (DashboardError, httpx.HTTPError) as exc:
                sys.stderr.write(f"dashboard: {exc}\n")
                return 2
            sys.stdout.write("\n  ".join([time.strftime("%H:%M:%S"), *lines]) + "\n")
            sys.stdout.flush()
            if args.once:
                return 0
            time.sleep(args.every_s)


if __name__ == "__main__":
    raise SystemExit(main())
