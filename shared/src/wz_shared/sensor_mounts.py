"""Finding a service's sensor in the site file, with errors a field engineer can act on."""

from __future__ import annotations

from typing import TypeVar

from wz_shared.site import CameraIntrinsics, LidarIntrinsics, RadarIntrinsics, SensorMount, Site

IntrinsicsT = TypeVar("IntrinsicsT", CameraIntrinsics, LidarIntrinsics, RadarIntrinsics)


def mount_of_kind(
    site: Site, sensor_id: str | None, kind: str, env: str, *, kind_name: str | None = None
) -> SensorMount:
    """The mount of ``sensor_id``, or the site's first sensor of ``kind`` when it is None.

    Parameters
    ----------
    site
        The site file's model.
    sensor_id
        The configured sensor id, or None for the first of its kind.
    kind
        The mount kind wanted ("lidar", "camera", "radar").
    env
        The environment variable that sets ``sensor_id`` (named in the error).
    kind_name
        How the messages name the kind (default: ``kind``; e.g. "LiDAR").

    Raises
    ------
    ValueError
        When the site has no such sensor, or it is not of ``kind``, in words for the operator.
    """
    name = kind if kind_name is None else kind_name
    mounts = [mount for mount in site.sensors if mount.kind == kind]
    if sensor_id is None:
        if not mounts:
            raise ValueError(f"site {site.site_id} has no {name}: set {env}")
        return mounts[0]
    try:
        mount = site.sensor(sensor_id)
    except KeyError:
        known = ", ".join(m.sensor_id for m in mounts) or "none"
        raise ValueError(
            f"site {site.site_id} has no sensor {sensor_id!r} (its {name}s: {known})"
        ) from None
    if mount.kind != kind:
        raise ValueError(
            f"sensor {sensor_id!r} of site {site.site_id} is a {mount.kind}, not a {name}"
        )
    return mount


def intrinsics_of(mount: SensorMount, kind: type[IntrinsicsT], why: str) -> IntrinsicsT:
    """The mount's intrinsics when they are of ``kind``, else a ValueError naming the sensor.

    ``why`` ends the message: who needs these intrinsics (e.g. "RadarModel needs radar
    intrinsics"), so the operator sees both what the sensor is and what wanted another kind.
    """
    if not isinstance(mount.intrinsics, kind):
        wanted = kind.model_fields["kind"].default
        raise ValueError(f"sensor {mount.sensor_id!r} is a {mount.kind}, not a {wanted}: {why}")
    return mount.intrinsics
