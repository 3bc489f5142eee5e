"""The key-expression registry: every Zenoh key of the stack, built from the site id.

No service writes a key expression by hand; it asks :class:`Keys` for one. The layout follows
docs/architecture.md, "Keys"::

    wz/<site>/raw/lidar/<sensor>      LiDAR frames           (ring)
    wz/<site>/raw/camera/<sensor>     camera frames (JPEG)   (ring)
    wz/<site>/raw/radar/<sensor>      radar scans            (ring)
    wz/<site>/truth/vehicles          ground truth (simulation only)
    wz/<site>/detections/<sensor>     detections             (FIFO)
    wz/<site>/tracks                  fused tracks           (FIFO)
    wz/<site>/alerts/<type>           alerts                 (FIFO, reliable)
    wz/<site>/devices/state           roadside beacon + sign (FIFO, reliable; on change)
    wz/<site>/queue                   per-lane queue state (1 Hz and on a change)
    wz/<site>/points/<sensor>         upstream point speed sensors (each interval)
    wz/<site>/status/<service>        liveliness token + periodic health
    wz/<site>/config/site             queryable: the site description
    wz/<site>/tracks/latest           queryable: the newest track batch
    wz/<site>/alerts/active           queryable: the open alert episodes and the devices

``active`` is not an alert type, so ``alerts/*`` subscribers never see it (nothing is put there);
a query on ``alerts/*`` reaches the queryable, a subscription does not.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

ROOT = "wz"
_CHUNK = re.compile(r"^[a-z0-9][a-z0-9_-]{0,62}$")


def _check_chunk(value: str, what: str) -> str:
    if not _CHUNK.match(value):
        raise ValueError(
            f"{what} {value!r} cannot be part of a key expression: use lower-case letters, "
            "digits, '-' and '_' (no '/', '*', '$', '?', '#')"
        )
    return value


@dataclass(frozen=True)
class Keys:
    """Key expressions of one site; ``Keys("*")`` is not allowed, use :meth:`all_sites`."""

    site: str

    def __post_init__(self) -> None:
        _check_chunk(self.site, "site id")

    @property
    def prefix(self) -> str:
        return f"{ROOT}/{self.site}"

    # raw sensor data
    def raw_lidar(self, sensor_id: str) -> str:
        return f"{self.prefix}/raw/lidar/{_check_chunk(sensor_id, 'sensor id')}"

    def raw_camera(self, sensor_id: str) -> str:
        return f"{self.prefix}/raw/camera/{_check_chunk(sensor_id, 'sensor id')}"

    def raw_radar(self, sensor_id: str) -> str:
        return f"{self.prefix}/raw/radar/{_check_chunk(sensor_id, 'sensor id')}"

    @property
    def raw_all(self) -> str:
        return f"{self.prefix}/raw/**"

    # ground truth
    @property
    def truth(self) -> str:
        return f"{self.prefix}/truth/vehicles"

    # perception and tracking
    def detections(self, sensor_id: str) -> str:
        return f"{self.prefix}/detections/{_check_chunk(sensor_id, 'sensor id')}"

    @property
    def detections_all(self) -> str:
        return f"{self.prefix}/detections/*"

    @property
    def tracks(self) -> str:
        return f"{self.prefix}/tracks"

    @property
    def tracks_latest(self) -> str:
        return f"{self.prefix}/tracks/latest"

    # alerts
    def alerts(self, alert_type: str) -> str:
        return f"{self.prefix}/alerts/{_check_chunk(alert_type, 'alert type')}"

    @property
    def alerts_all(self) -> str:
        return f"{self.prefix}/alerts/*"

    @property
    def alerts_active(self) -> str:
        return f"{self.prefix}/alerts/active"

    # roadside devices driven by the alerts
    @property
    def devices_state(self) -> str:
        return f"{self.prefix}/devices/state"

    # the queue, per lane
    @property
    def queue(self) -> str:
        return f"{self.prefix}/queue"

    # upstream point speed sensors (site file's point_sensors)
    def point_sensor(self, sensor_id: str) -> str:
        return f"{self.prefix}/points/{_check_chunk(sensor_id, 'sensor id')}"

    @property
    def point_sensors_all(self) -> str:
        return f"{self.prefix}/points/*"

    # self-calibration of each sensor (its pose correction and clock offset)
    def calibration(self, sensor_id: str) -> str:
        return f"{self.prefix}/calibration/{_check_chunk(sensor_id, 'sensor id')}"

    @property
    def calibration_all(self) -> str:
        return f"{self.prefix}/calibration/*"

    # health and configuration
    def status(self, service: str) -> str:
        return f"{self.prefix}/status/{_check_chunk(service, 'service name')}"

    @property
    def status_all(self) -> str:
        return f"{self.prefix}/status/*"

    @property
    def config_site(self) -> str:
        return f"{self.prefix}/config/site"

    @property
    def everything(self) -> str:
        return f"{self.prefix}/**"

    @staticmethod
    def all_sites(suffix: str = "**") -> str:
        """A selector across every site, e.g. ``Keys.all_sites("alerts/*")``."""
        return f"{ROOT}/*/{suffix}"


def site_of_key(key_expr: str) -> str | None:
    """The site id of a concrete key, or None if the key is not one of ours."""
    parts = str(key_expr).split("/")
    if len(parts) >= 2 and parts[0] == ROOT and _CHUNK.match(parts[1]):
        return parts[1]
    return None
