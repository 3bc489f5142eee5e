"""wz_shared.sensor_mounts: a mount's intrinsics of the kind a model needs, or an error that
names the sensor, what it is and who needed what."""

from __future__ import annotations

import pytest

from wz_shared.sensor_mounts import intrinsics_of
from wz_shared.site import LidarIntrinsics, Pose, RadarIntrinsics, SensorMount


def _lidar() -> SensorMount:
    return SensorMount(
        sensor_id="l1", pose=Pose(x_m=0, y_m=0, z_m=2), intrinsics=LidarIntrinsics(), rate_hz=10.0
    )


def test_the_intrinsics_of_the_wanted_kind_come_back_as_they_are() -> None:
    mount = _lidar()
    assert intrinsics_of(mount, LidarIntrinsics, "unused") is mount.intrinsics


def test_another_kind_is_refused_in_words() -> None:
    with pytest.raises(ValueError) as caught:
        intrinsics_of(_lidar(), RadarIntrinsics, "RadarModel needs radar intrinsics")
    assert str(caught.value) == (
        "sensor 'l1' is a lidar, not a radar: RadarModel needs radar intrinsics"
    )
