"""A service node on the real runtime whose loop can be made to hang, for the liveness tests.

Usage: python -m tests.cli.stall_node NAME TRIGGER_FILE

Joins the bus as service NAME of the default site (``WZ_BUS_*``) through
:class:`~wz_shared.service.ServiceRuntime` (liveliness token, status thread, health file from
``WZ_HEALTH_FILE``, stall limit from ``WZ_STALL_AFTER_S``) and goes round its loop every
0.1 s, beating the runtime, until TRIGGER_FILE holds its pid: then its loop blocks for good,
as on a hung call, while the process and its status thread live on. A restarted node has
another pid, so it runs normally.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

from wz_shared.service import ServiceRuntime
from wz_shared.settings import BusSettings, ServiceSettings
from wz_shared.site import DEFAULT_SITE_PATH, load_site


def main() -> None:
    name, trigger = sys.argv[1], Path(sys.argv[2])
    settings = ServiceSettings()
    site = load_site(DEFAULT_SITE_PATH).site_id
    with ServiceRuntime(
        name,
        site,
        BusSettings(),
        status_period_s=settings.status_period_s,
        health_file=settings.health_file,
        stall_after_s=settings.stall_after_s,
    ) as runtime:
        print(f"looping: pid {os.getpid()}", flush=True)
        while not runtime.stop.is_set():
            if trigger.exists() and trigger.read_text().strip() == str(os.getpid()):
                print("blocked", flush=True)
                while True:  # a hung call: the loop never comes back
                    time.sleep(1.0)
            runtime.beat(processed=True)
            runtime.stop.wait(0.1)


if __name__ == "__main__":
    main()
