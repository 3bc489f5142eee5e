"""`wz alerts` as a process: the open alerts from the alert service's queryable, then each
alert event as it is published; exit 1 when no alert service answers."""

from __future__ import annotations

from tests.cli.procs import run_wz, running, start_wz
from tests.shared.samples import SITE, json_samples
from wz_cli.alerts import alert_line
from wz_shared.bus import Bus
from wz_shared.codec import encode_json
from wz_shared.messages import ActiveAlerts, Alert, AlertType
from wz_shared.settings import BusSettings


def test_alert_line_says_when_what_and_who() -> None:
    alert = next(m for m in json_samples(3) if isinstance(m, Alert))
    assert alert_line(alert) == (
        "10.150  start  speeding  warning  track 3  speeding 74 mph in a 55 mph zone"
    )
    site_wide = alert.model_copy(update={"track_id": None, "alert_type": AlertType.QUEUE})
    assert alert_line(site_wide, phase="open").startswith("10.150  open  queue  warning  site  ")


def test_alerts_prints_the_open_ones_then_each_event(router: str) -> None:
    active = next(m for m in json_samples(1) if isinstance(m, ActiveAlerts))
    event = next(m for m in json_samples(2) if isinstance(m, Alert))
    settings = BusSettings(mode="peer", connect_endpoints=[router], listen_endpoints=[])
    with Bus.open(settings, site=SITE, service="fake-alert-service") as bus:
        bus.serve(bus.keys.alerts_active, lambda: encode_json(active))
        publisher = bus.publisher(bus.keys.alerts("speeding"), Alert)
        command = ("alerts", "--site", SITE, "--count", "1", "--timeout", "60", "--connect", router)
        with running(start_wz(*command)) as watcher:
            assert publisher.wait_for_subscribers(30.0), "wz alerts never subscribed"
            publisher.put(event)
            out, err = watcher.communicate(timeout=60)
    assert watcher.returncode == 0, err
    assert out.splitlines() == [alert_line(active.alerts[0], "open"), alert_line(event)]
    assert "1 open, beacon on, sign 'SLOW DOWN'" in err


def test_alerts_active_without_an_alert_service_exits_1(router: str) -> None:
    result = run_wz("alerts", "--site", SITE, "--active", "--connect", router)
    assert result.returncode == 1
    assert result.stdout == ""
    assert "no alert service answered" in result.stderr
