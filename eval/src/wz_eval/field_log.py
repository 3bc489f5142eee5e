"""Make a field log from simulation: the devices' own formats, with truth known exactly.

``wz field-log OUT_DIR [--seed N]`` simulates the default work zone (SUMO) and writes what a
field crew would bring back from the paper's validation (Section 5: an Ouster LiDAR, a
radar-camera unit and an RTK-GPS probe vehicle), as a :mod:`wz_drivers.log` folder:

- ``lidar/os1-64.pcap.gz`` and ``lidar/os1-64.json``: the simulated LiDAR's sweeps (32 beams,
  512 columns, 10 Hz: Ouster's 512x10 mode) as an Ouster recording (sensor metadata and lidar
  UDP packets, through ouster-sdk: :func:`wz_drivers.ouster.write_ouster_pcap`), gzipped as
  field logs are shipped (25 MB as a pcap, 4 MB gzipped); high rate, no gaps;
- ``radar-camera/objects.csv``: the radar-camera unit's object lists at 5 Hz: every vehicle in
  its field of view, position from the truth with the unit's range and azimuth noise, its speed,
  its class; a lower, gappy rate: one report in ten lost and two outages (1.5 s and 1 s), and
  the unit's clock 0.12 s ahead of the GPS (a unit on its own NTP);
- ``gps/probe.nmea``: one probe vehicle's RTK-GPS at 10 Hz (GGA and RMC with checksums, fix
  quality 4, 2 cm noise) at its antenna, 1.2 m ahead of the vehicle's centre;
- ``site.yaml`` (the default site with the LiDAR an OS1-32 at 10 Hz, the radar the unit) and
  ``log.yaml``; ``truth.csv``: every vehicle's true centre (for the record; the evaluation
  uses the GPS file only).

The probe is the first car to cross station ``mast - 260 m`` after the warm-up; the log starts
2 s earlier (the LiDAR detector learns its background from the first 2 s) and ends when the
probe has passed the mast. Times are Unix seconds from 2026-09-01T14:00:00Z (simulation time
zero). Deterministic for a seed.
"""

from __future__ import annotations

import argparse
import csv
import datetime as dt
import gzip
import math
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from wz_drivers.records import LidarSweep
from wz_shared.messages import VehicleClass, VehicleTruth
from wz_shared.site import DEFAULT_SITE_PATH, LidarIntrinsics, Site, load_site, site_document

#: Unix time of simulation time zero.
T0_UNIX_S = dt.datetime(2026, 9, 1, 14, 0, 0, tzinfo=dt.UTC).timestamp()
LIDAR_ID, UNIT_ID = "lidar-mast", "radar-mast"
LIDAR_CHANNELS, LIDAR_COLUMNS, LIDAR_RATE_HZ = 64, 2048, 10
#: The LiDAR's azimuth window (Ouster encoder angles): +-45 deg about its boresight, the approach.
LIDAR_WINDOW_DEG = (135.0, 225.0)
UNIT_RATE_HZ = 5.0
UNIT_CLOCK_AHEAD_S = 0.12
UNIT_LOSS = 0.1
UNIT_OUTAGES_S = ((3.0, 1.5), (6.5, 1.0))  # (start after the log start, duration)
GPS_RATE_HZ = 10.0
GPS_NOISE_M = 0.02
ANTENNA_FORWARD_M = 1.2
PROBE_START_UPSTREAM_M = 200.0
LEAD_S = 2.0
_CLASS_NAMES = {
    VehicleClass.CAR: "car",
    VehicleClass.TRUCK: "truck",
    VehicleClass.BUS: "bus",
    VehicleClass.MOTORCYCLE: "motorcycle",
}


@dataclass(frozen=True)
class SampleOptions:
    seed: int = 11
    warmup_s: float = 60.0
    max_log_s: float = 20.0
    vehicles_per_hour: float = 1400.0


def log_site(site: Site) -> Site:
    """The default site with the LiDAR an OS1-32 at 10 Hz (45 deg uniform vertical field)."""
    sensors = []
    for mount in site.sensors:
        if mount.sensor_id == LIDAR_ID:
            assert isinstance(mount.intrinsics, LidarIntrinsics)
            intrinsics = mount.intrinsics.model_copy(
                update={
                    "beams": LIDAR_CHANNELS,
                    "azimuth_steps": LIDAR_COLUMNS,
                    "vertical_min_deg": -30.0,
                    "vertical_max_deg": 11.0,
                }
            )
            mount = mount.model_copy(
                update={"intrinsics": intrinsics, "rate_hz": float(LIDAR_RATE_HZ)}
            )
        sensors.append(mount)
    return site.model_copy(update={"sensors": sensors})


def nmea_sentence(body: str) -> str:
    """``$<body>*<checksum>``: the XOR of the body's bytes, two hex digits."""
    checksum = 0
    for byte in body.encode("ascii"):
        checksum ^= byte
    return f"${body}*{checksum:02X}"


def _nmea_angle(value_deg: float, positive: str, negative: str, degree_digits: int) -> str:
    hemisphere = positive if value_deg >= 0 else negative
    value = abs(value_deg)
    degrees = int(value)
    minutes = (value - degrees) * 60.0
    return f"{degrees:0{degree_digits}d}{minutes:010.7f},{hemisphere}"


def nmea_epoch(
    stamp_unix_s: float,
    latitude_deg: float,
    longitude_deg: float,
    altitude_m: float,
    speed_mps: float,
    course_deg: float,
) -> list[str]:
    """GGA (RTK fixed, 14 satellites) and RMC sentences of one fix."""
    moment = dt.datetime.fromtimestamp(stamp_unix_s, tz=dt.UTC)
    hhmmss = moment.strftime("%H%M%S") + f".{moment.microsecond // 10000:02d}"
    lat = _nmea_angle(latitude_deg, "N", "S", 2)
    lon = _nmea_angle(longitude_deg, "E", "W", 3)
    gga = f"GPGGA,{hhmmss},{lat},{lon},4,14,0.7,{altitude_m:.3f},M,-26.0,M,1.0,0000"
    knots = speed_mps / 0.514444
    rmc = (
        f"GPRMC,{hhmmss},A,{lat},{lon},{knots:.3f},{course_deg % 360.0:.2f},"
        f"{moment.strftime('%d%m%y')},,,D"
    )
    return [nmea_sentence(gga), nmea_sentence(rmc)]


def write_sample_log(out: Path, options: SampleOptions | None = None) -> Path:
    """Simulate and write the log folder ``out`` (created; must be empty); its manifest."""
    from wz_drivers.ouster import write_ouster_pcap
    from wz_simulator.sensors.rig import LidarOutput, SensorRig
    from wz_simulator.sensors.scene import WEATHER_PRESETS
    from wz_simulator.settings import SimulatorSettings
    from wz_simulator.traffic.world import TrafficWorld

    options = options or SampleOptions()
    if out.exists() and any(out.iterdir()):
        raise FileExistsError(f"{out} is not empty")
    for folder in ("lidar", "radar-camera", "gps"):
        (out / folder).mkdir(parents=True, exist_ok=True)
    site = log_site(load_site(DEFAULT_SITE_PATH))
    rng = np.random.default_rng(options.seed)
    lidar_mount = next(m for m in site.sensors if m.sensor_id == LIDAR_ID)
    unit_mount = next(m for m in site.sensors if m.sensor_id == UNIT_ID)
    mast_station = float(site.road_frame.to_road(lidar_mount.pose.x_m, lidar_mount.pose.y_m)[0])
    rig = SensorRig(site, WEATHER_PRESETS["day"], options.seed, sensor_ids=[LIDAR_ID])
    sim = SimulatorSettings.model_validate(
        {
            "seed": options.seed,
            "realtime_factor": 0.0,
            "sensors_enabled": False,
            "vehicles_per_hour": options.vehicles_per_hour,
            "duration_s": options.warmup_s + 120.0 + options.max_log_s,
        }
    )
    sweeps: list[LidarSweep] = []
    truth: list[tuple[float, list[VehicleTruth]]] = []
    probe_id: str | None = None
    start_s: float | None = None
    with TrafficWorld(site, sim) as world:
        while not world.finished:
            vehicles = world.step()
            now = world.sim_time_s
            if now < options.warmup_s - LEAD_S:  # the sensors fire from 2 s before the log
                continue
            truth.append((now, vehicles))
            for output in rig.fire(vehicles, now):
                if isinstance(output, LidarOutput):
                    scan = output.scan
                    sweeps.append(
                        LidarSweep(
                            stamp=T0_UNIX_S + scan.meta.stamp,
                            points=scan.points,
                            rows=scan.meta.rows,
                            columns=scan.meta.columns,
                            organized=True,
                            where=f"simulation frame {scan.meta.frame_index}",
                            sweep_duration_s=scan.meta.sweep_duration_s,
                        )
                    )
            if probe_id is None:  # keep the last 2 s until the probe shows up
                truth = [(t, vs) for t, vs in truth if t >= now - LEAD_S - 1e-6]
                sweeps = [w for w in sweeps if w.stamp >= T0_UNIX_S + now - LEAD_S - 1e-6]
                if now < options.warmup_s:
                    continue
                crossing = [
                    v
                    for v in vehicles
                    if v.vehicle_class is VehicleClass.CAR
                    and abs(v.station_m - (mast_station - PROBE_START_UPSTREAM_M)) < 2.0
                ]
                if not crossing:
                    continue
                probe_id = crossing[0].vehicle_id
                start_s = now - LEAD_S
            assert start_s is not None
            probe = next((v for v in vehicles if v.vehicle_id == probe_id), None)
            if (
                probe is None
                or probe.station_m > mast_station + 10.0
                or now - start_s > options.max_log_s
            ):
                break
    if probe_id is None or start_s is None:
        raise RuntimeError("no car crossed the probe's start station; simulate longer")
    pcap = out / "lidar" / "os1-64.pcap"
    write_ouster_pcap(
        sweeps,
        pcap,
        out / "lidar" / "os1-64.json",
        channels=LIDAR_CHANNELS,
        columns_per_frame=LIDAR_COLUMNS,
        vertical_min_deg=-30.0,
        vertical_max_deg=11.0,
        rate_hz=LIDAR_RATE_HZ,
        azimuth_window_deg=LIDAR_WINDOW_DEG,
    )
    with (
        pcap.open("rb") as raw,
        gzip.GzipFile(pcap.with_suffix(".pcap.gz"), "wb", mtime=0) as packed,
    ):
        shutil.copyfileobj(raw, packed)
    pcap.unlink()
    _write_unit(out / "radar-camera" / "objects.csv", truth, unit_mount, start_s, rng)
    _write_gps(out / "gps" / "probe.nmea", truth, probe_id, site, rng)
    _write_truth(out / "truth.csv", truth)
    site_path = out / "site.yaml"
    site_path.write_text(yaml.safe_dump(site_document(site), sort_keys=False))
    manifest = {
        "format": "wz-field-log/1",
        "description": f"Simulated field log (seed {options.seed}): probe {probe_id} through "
        "the default work zone; made by `wz field-log` (wz_eval.field_log).",
        "site": "site.yaml",
        "sources": [
            {
                "sensor_id": LIDAR_ID,
                "kind": "lidar",
                "format": "ouster",
                "path": "lidar/os1-64.pcap.gz",
                "metadata": "lidar/os1-64.json",
            },
            {
                "sensor_id": UNIT_ID,
                "kind": "objects",
                "format": "csv",
                "path": "radar-camera/objects.csv",
            },
        ],
        "truth": {
            "path": "gps/probe.nmea",
            "antenna_forward_m": ANTENNA_FORWARD_M,
            "antenna_left_m": 0.0,
            "vehicle_id": probe_id,
        },
    }
    manifest_path = out / "log.yaml"
    manifest_path.write_text(yaml.safe_dump(manifest, sort_keys=False))
    return manifest_path


def _in_unit_view(
    vehicle: VehicleTruth,
    mount_xy: tuple[float, float],
    heading: float,
    max_range_m: float,
    half_fov_rad: float,
) -> tuple[float, float] | None:
    dx, dy = vehicle.x_m - mount_xy[0], vehicle.y_m - mount_xy[1]
    c, s = math.cos(heading), math.sin(heading)
    forward, left = c * dx + s * dy, -s * dx + c * dy
    rng, azimuth = math.hypot(forward, left), math.atan2(left, forward)
    if rng > max_range_m or abs(azimuth) > half_fov_rad:
        return None
    return rng, azimuth


def _write_unit(
    path: Path,
    truth: list[tuple[float, list[VehicleTruth]]],
    mount: object,
    start_s: float,
    rng: np.random.Generator,
) -> None:
    from wz_shared.site import RadarIntrinsics, SensorMount

    assert isinstance(mount, SensorMount) and isinstance(mount.intrinsics, RadarIntrinsics)
    intrinsics = mount.intrinsics
    heading = mount.pose.ground_heading_rad()
    half_fov = math.radians(intrinsics.horizontal_fov_deg) / 2.0
    ids: dict[str, int] = {}
    period = 1.0 / UNIT_RATE_HZ
    next_t = truth[0][0]
    with path.open("w", newline="") as stream:
        writer = csv.writer(stream)
        writer.writerow(
            ["time_unix_s", "object_id", "range_m", "azimuth_deg", "speed_mps", "class"]
        )
        for t, vehicles in truth:
            if t + 1e-9 < next_t:
                continue
            next_t += period
            since = t - start_s
            if any(a <= since < a + d for a, d in UNIT_OUTAGES_S) or rng.random() < UNIT_LOSS:
                continue
            for v in vehicles:
                seen = _in_unit_view(
                    v, (mount.pose.x_m, mount.pose.y_m), heading, intrinsics.max_range_m, half_fov
                )
                if seen is None:
                    continue
                object_id = ids.setdefault(v.vehicle_id, len(ids) + 1)
                rng_m = seen[0] + rng.normal(0.0, intrinsics.range_noise_std_m)
                azimuth = seen[1] + math.radians(rng.normal(0.0, intrinsics.azimuth_noise_std_deg))
                writer.writerow(
                    [
                        f"{T0_UNIX_S + t + UNIT_CLOCK_AHEAD_S:.3f}",
                        object_id,
                        f"{rng_m:.2f}",
                        f"{math.degrees(azimuth):.3f}",
                        f"{v.speed_mps + rng.normal(0.0, 0.2):.2f}",
                        _CLASS_NAMES.get(v.vehicle_class, "unknown"),
                    ]
                )


def _write_gps(
    path: Path,
    truth: list[tuple[float, list[VehicleTruth]]],
    probe_id: str,
    site: Site,
    rng: np.random.Generator,
) -> None:
    period = 1.0 / GPS_RATE_HZ
    next_t = truth[0][0]
    lines: list[str] = []
    for t, vehicles in truth:
        if t + 1e-9 < next_t:
            continue
        next_t += period
        probe = next((v for v in vehicles if v.vehicle_id == probe_id), None)
        if probe is None:
            continue
        ax = (
            probe.x_m + ANTENNA_FORWARD_M * math.cos(probe.heading_rad) + rng.normal(0, GPS_NOISE_M)
        )
        ay = (
            probe.y_m + ANTENNA_FORWARD_M * math.sin(probe.heading_rad) + rng.normal(0, GPS_NOISE_M)
        )
        latitude, longitude, altitude = site.geo_frame.to_wgs84(ax, ay)
        course = (90.0 - math.degrees(probe.heading_rad)) % 360.0  # clockwise from north
        lines += nmea_epoch(
            T0_UNIX_S + t,
            float(latitude),
            float(longitude),
            float(altitude) + 1.8,
            probe.speed_mps,
            course,
        )
    path.write_text("\r\n".join(lines) + "\r\n")


def _write_truth(path: Path, truth: list[tuple[float, list[VehicleTruth]]]) -> None:
    with path.open("w", newline="") as stream:
        writer = csv.writer(stream)
        writer.writerow(
            ["time_unix_s", "vehicle_id", "x_m", "y_m", "speed_mps", "heading_rad", "class"]
        )
        for t, vehicles in truth:
            for v in vehicles:
                writer.writerow(
                    [
                        f"{T0_UNIX_S + t:.3f}",
                        v.vehicle_id,
                        f"{v.x_m:.3f}",
                        f"{v.y_m:.3f}",
                        f"{v.speed_mps:.3f}",
                        f"{v.heading_rad:.5f}",
                        v.vehicle_class.value,
                    ]
                )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="wz field-log", description=__doc__.split("\n")[0])
    parser.add_argument("out", type=Path, metavar="OUT_DIR")
    parser.add_argument("--seed", type=int, default=SampleOptions.seed)
    args = parser.parse_args(argv)
    manifest = write_sample_log(args.out, SampleOptions(seed=args.seed))
    print(f"wrote {manifest}")  # noqa: T201
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
