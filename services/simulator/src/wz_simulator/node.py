"""The simulator node: steps the SUMO work zone and publishes ground truth on the bus.

Run it as ``python -m wz_simulator.node`` (``wz up`` does). Settings come from the environment
(``WZ_SIM_*`` for the simulation, ``WZ_BUS_*`` for the bus). It publishes

- ``wz/<site>/truth/vehicles``: a :class:`GroundTruth` every simulation step (20 Hz by default),
  stamped with simulation time;
- ``wz/<site>/status/simulator``: liveliness and health (see :mod:`wz_shared.service`);

and answers queries on ``wz/<site>/config/site`` with the site description as JSON.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

from wz_shared.logs import configure_logging
from wz_shared.messages import GroundTruth
from wz_shared.service import ServiceRuntime
from wz_shared.settings import BusSettings
from wz_shared.site import load_site
from wz_shared.timebase import Pacer, SimClock

from wz_simulator.settings import SimulatorSettings
from wz_simulator.traffic.world import TrafficWorld

SERVICE = "simulator"
log = logging.getLogger(__name__)


def run_loop(
    world: TrafficWorld,
    publish_truth: Callable[[GroundTruth], None],
    clock: SimClock,
    pacer: Pacer,
    stop: threading.Event,
) -> int:
    """Step the world until ``stop`` or its duration; publish truth each step.

    Returns the number of steps taken.
    """
    site_id = world.site.site_id
    steps = 0
    while not stop.is_set() and not world.finished:
        vehicles = world.step()
        now_s = world.sim_time_s
        clock.advance_to(now_s)
        publish_truth(
            GroundTruth(
                site=site_id,
                source_id=SERVICE,
                stamp=now_s,
                step_index=world.step_index,
                vehicles=vehicles,
            )
        )
        steps += 1
        pacer.wait_until(now_s, stop)
    return steps


def main() -> None:
    settings = SimulatorSettings()
    site = load_site(settings.site_file)
    configure_logging(service=SERVICE, site=site.site_id, level=settings.log_level)
    clock = SimClock()
    site_json = site.model_dump_json().encode()
    with (
        ServiceRuntime(
            SERVICE,
            site.site_id,
            BusSettings(),
            status_period_s=settings.status_period_s,
            clock_stamp=clock.now,
        ) as runtime,
        TrafficWorld(site, settings) as world,
    ):
        bus = runtime.bus
        truth = bus.publisher(bus.keys.truth, GroundTruth)
        bus.serve(bus.keys.config_site, lambda: site_json)
        steps = run_loop(world, truth.put, clock, Pacer(settings.realtime_factor), runtime.stop)
        log.info(
            "simulation ended after %d steps (%.1f s simulated): %s",
            steps,
            world.sim_time_s,
            world.counters,
        )


if __name__ == "__main__":
    main()
