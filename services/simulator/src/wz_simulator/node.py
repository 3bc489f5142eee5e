"""The simulator node: steps the SUMO work zone and publishes ground truth on the bus.

Run it as ``python -m wz_simulator.node`` (``wz up`` does). Settings come from the environment
(``WZ_SIM_*`` for the simulation, ``WZ_BUS_*`` for the bus). It publishes

- ``wz/<site>/truth/vehicles``: a :class:`GroundTruth` every simulation step (20 Hz by default),
  stamped with simulation time;
- ``wz/<site>/raw/lidar/<id>``, ``raw/camera/<id>``, ``raw/radar/<id>``: each sensor of the site
  at its own rate (frames as binary envelopes, radar scans as JSON), stamped with the firing
  time (see :mod:`wz_simulator.sensors.rig`);
- ``wz/<site>/points/<id>``: each upstream point speed sensor of the site (its SUMO induction
  loops, :mod:`wz_simulator.traffic.loops`) at the end of each of its intervals;
- ``wz/<site>/status/simulator``: liveliness and health (see :mod:`wz_shared.service`);
  ``starting`` until it publishes (SUMO, the sensor models, and the warm-up: ``warmup_s`` of
  traffic simulated as fast as possible, nothing published, so that the stream starts on a
  road in steady traffic), then ``running``;

and answers queries on ``wz/<site>/config/site`` with the site description as JSON.

With ``WZ_SIM_MOUNT_ERRORS=true`` the sensors are a real mast's (:mod:`wz_simulator.sensors.mast`:
set-up errors, late clocks, sway, settling, ``WZ_SIM_BUMP_*``): the frames are rendered from
the true poses and the node logs the drawn errors at start, but what it publishes, the site
on ``config/site`` included, keeps the site file's nominal poses.
"""

from __future__ import annotations

import gc
import logging
import threading
import time
from collections.abc import Callable

from wz_shared.bus import Bus, Publisher
from wz_shared.codec import encode_camera_frame, encode_lidar_frame
from wz_shared.messages import (
    CameraFrameMeta,
    GroundTruth,
    LidarFrameMeta,
    PointSensorReading,
    RadarScan,
    ServiceState,
)
from wz_shared.service import NodeApp, ServiceRuntime
from wz_shared.site import Site
from wz_shared.timebase import Pacer, SimClock
from wz_simulator.sensors.mast import Bump, MastModel
from wz_simulator.sensors.rig import (
    CameraOutput,
    LidarOutput,
    SensorOutput,
    SensorRig,
)
from wz_simulator.sensors.scene import WEATHER_PRESETS
from wz_simulator.settings import SimulatorSettings
from wz_simulator.traffic.world import TrafficWorld

SERVICE = "simulator"
log = logging.getLogger(__name__)


class SensorPublisher:
    """Encodes each sensor's output and publishes it on that sensor's raw key."""

    def __init__(self, bus: Bus, site: Site) -> None:
        keys = bus.keys
        self._lidar: dict[str, Publisher[LidarFrameMeta]] = {}
        self._camera: dict[str, Publisher[CameraFrameMeta]] = {}
        self._radar: dict[str, Publisher[RadarScan]] = {}
        for mount in site.sensors:
            if mount.kind == "lidar":
                self._lidar[mount.sensor_id] = bus.publisher(
                    keys.raw_lidar(mount.sensor_id), LidarFrameMeta
                )
            elif mount.kind == "camera":
                self._camera[mount.sensor_id] = bus.publisher(
                    keys.raw_camera(mount.sensor_id), CameraFrameMeta
                )
            else:
                self._radar[mount.sensor_id] = bus.publisher(
                    keys.raw_radar(mount.sensor_id), RadarScan
                )

    def publish(self, output: SensorOutput) -> None:
        if isinstance(output, LidarOutput):
            scan = output.scan
            self._lidar[output.sensor_id].put_bytes(encode_lidar_frame(scan.meta, scan.points))
        elif isinstance(output, CameraOutput):
            envelope = encode_camera_frame(output.meta, output.jpeg)
            self._camera[output.sensor_id].put_bytes(envelope)
        else:
            self._radar[output.sensor_id].put(output.result.scan)


def run_loop(
    world: TrafficWorld,
    publish_truth: Callable[[GroundTruth], None],
    clock: SimClock,
    pacer: Pacer,
    stop: threading.Event,
    rig: SensorRig | None = None,
    publish_sensor: Callable[[SensorOutput], None] | None = None,
    beat: Callable[[], None] = lambda: None,
    publish_point: Callable[[PointSensorReading], None] | None = None,
) -> int:
    """Step the world until ``stop`` or its duration; publish truth, due sensor frames and
    the point sensors' readings; ``beat()`` after each step (the node's liveness).

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
        if rig is not None and publish_sensor is not None:
            for output in rig.fire(vehicles, now_s):
                publish_sensor(output)
        if publish_point is not None:
            for reading in world.point_readings():
                publish_point(reading)
        steps += 1
        beat()
        pacer.wait_until(now_s, stop)
    return steps


def sensor_rig(site: Site, settings: SimulatorSettings) -> SensorRig:
    """The site's sensors as the settings say, a real mast's when ``mount_errors`` (its draws
    logged, one line each: for the people running it; no service reads the log)."""
    mast = None
    if settings.mount_errors:
        bump = None
        if settings.bump_sensor is not None and settings.bump_at_s is not None:
            bump = Bump(settings.bump_sensor, settings.bump_at_s, settings.bump_yaw_deg)
        mast = MastModel.draw(site, settings.seed, bump)
        for line in mast.lines():
            log.info("mount errors (seed %d): %s", settings.seed, line)
    return SensorRig(
        site,
        WEATHER_PRESETS[settings.weather],
        settings.seed,
        jpeg_quality=settings.jpeg_quality,
        mast=mast,
    )


def warm_up(world: TrafficWorld, until_s: float, stop: threading.Event) -> int:
    """Step the world to ``until_s`` as fast as possible, publishing nothing; the steps taken."""
    steps = 0
    while world.sim_time_s < until_s - 1e-9 and not world.finished and not stop.is_set():
        world.step()
        steps += 1
    return steps


def main() -> None:
    node = NodeApp(SERVICE, SimulatorSettings)
    site = node.load_site()
    site_json = site.model_dump_json().encode()

    def loop(runtime: ServiceRuntime) -> None:
        runtime.state = ServiceState.STARTING  # until it publishes
        with TrafficWorld(site, node.settings) as world:
            simulate(runtime, site, node.settings, world, node.clock, site_json)

    node.serve(loop)


def simulate(
    runtime: ServiceRuntime,
    site: Site,
    settings: SimulatorSettings,
    world: TrafficWorld,
    clock: SimClock,
    site_json: bytes,
) -> None:
    """Publish the world until ``runtime.stop`` or its duration: sensors built, warmed up."""
    bus = runtime.bus
    truth = bus.publisher(bus.keys.truth, GroundTruth)
    bus.serve(bus.keys.config_site, lambda: site_json)
    rig = None
    publish_sensor = None
    if settings.sensors_enabled and site.sensors:
        rig = sensor_rig(site, settings)
        publish_sensor = SensorPublisher(bus, site).publish
        log.info("sensors: %s (%s)", [m.sensor_id for m in rig.mounts], settings.weather)
    if settings.warmup_s > 0:
        started = time.monotonic()
        steps = warm_up(world, settings.warmup_s, runtime.stop)
        clock.advance_to(world.sim_time_s)
        if rig is not None:
            rig.skip_until(world.sim_time_s)
        log.info(
            "warmed up: %.1f s simulated in %.2f s (%d steps), %d vehicles on the road",
            world.sim_time_s,
            time.monotonic() - started,
            steps,
            world.counters.departed - world.counters.arrived,
        )
    publish_point = None
    if site.point_sensors:
        points = {
            point.sensor_id: bus.publisher(
                bus.keys.point_sensor(point.sensor_id), PointSensorReading
            )
            for point in site.point_sensors
        }

        def publish_point(reading: PointSensorReading) -> None:
            points[reading.source_id].put(reading)

        log.info("point sensors: %s", sorted(points))
    # The scene, the models and their caches live for the whole run: move them out of the
    # collector's generations so full collections stay short (they paused single camera
    # frames for 70-85 ms; BENCHMARKS.md, sensors).
    gc.collect()
    gc.freeze()
    runtime.state = ServiceState.RUNNING
    steps = run_loop(
        world,
        truth.put,
        clock,
        Pacer(settings.realtime_factor),
        runtime.stop,
        rig,
        publish_sensor,
        beat=lambda: runtime.beat(processed=True),
        publish_point=publish_point,
    )
    log.info(
        "simulation ended after %d steps (%.1f s simulated): %s",
        steps,
        world.sim_time_s,
        world.counters,
    )


if __name__ == "__main__":
    main()
