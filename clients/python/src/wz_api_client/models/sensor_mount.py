from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from typing import cast

if TYPE_CHECKING:
    from ..models.camera_intrinsics import CameraIntrinsics
    from ..models.lidar_intrinsics import LidarIntrinsics
    from ..models.pose import Pose
    from ..models.radar_intrinsics import RadarIntrinsics


T = TypeVar("T", bound="SensorMount")


@_attrs_define
class SensorMount:
    """One sensor on the mast: its id (used in bus keys), pose, intrinsics and rate.

    Attributes:
        intrinsics (CameraIntrinsics | LidarIntrinsics | RadarIntrinsics):
        pose (Pose): Sensor pose in the site frame: position [m] and yaw/pitch/roll [deg].

            The sensor frame has x forward, y left, z up. yaw is measured counter-clockwise from the
            site x axis (east); pitch is positive nose-up (a sensor looking down at the road has
            negative pitch); roll is positive right side down (about x). See :meth:`rotation`.
        rate_hz (float):
        sensor_id (str):
    """

    intrinsics: CameraIntrinsics | LidarIntrinsics | RadarIntrinsics
    pose: Pose
    rate_hz: float
    sensor_id: str

    def to_dict(self) -> dict[str, Any]:
        from ..models.camera_intrinsics import CameraIntrinsics  # noqa: PLC0415
        from ..models.lidar_intrinsics import LidarIntrinsics  # noqa: PLC0415
        from ..models.pose import Pose  # noqa: PLC0415
        from ..models.radar_intrinsics import RadarIntrinsics  # noqa: PLC0415

        intrinsics: dict[str, Any]
        if isinstance(self.intrinsics, LidarIntrinsics):
            intrinsics = self.intrinsics.to_dict()
        elif isinstance(self.intrinsics, CameraIntrinsics):
            intrinsics = self.intrinsics.to_dict()
        else:
            intrinsics = self.intrinsics.to_dict()

        pose = self.pose.to_dict()

        rate_hz = self.rate_hz

        sensor_id = self.sensor_id

        field_dict: dict[str, Any] = {}

        field_dict.update(
            {
                "intrinsics": intrinsics,
                "pose": pose,
                "rate_hz": rate_hz,
                "sensor_id": sensor_id,
            }
        )

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        from ..models.camera_intrinsics import CameraIntrinsics  # noqa: PLC0415
        from ..models.lidar_intrinsics import LidarIntrinsics  # noqa: PLC0415
        from ..models.pose import Pose  # noqa: PLC0415
        from ..models.radar_intrinsics import RadarIntrinsics  # noqa: PLC0415

        d = dict(src_dict)

        def _parse_intrinsics(
            data: object,
        ) -> CameraIntrinsics | LidarIntrinsics | RadarIntrinsics:
            try:
                if not isinstance(data, dict):
                    raise TypeError()
                intrinsics_type_0 = LidarIntrinsics.from_dict(data)

                return intrinsics_type_0
            except (TypeError, ValueError, AttributeError, KeyError):
                pass
            try:
                if not isinstance(data, dict):
                    raise TypeError()
                intrinsics_type_1 = CameraIntrinsics.from_dict(data)

                return intrinsics_type_1
            except (TypeError, ValueError, AttributeError, KeyError):
                pass
            if not isinstance(data, dict):
                raise TypeError()
            intrinsics_type_2 = RadarIntrinsics.from_dict(data)

            return intrinsics_type_2

        intrinsics = _parse_intrinsics(d.pop("intrinsics"))

        pose = Pose.from_dict(d.pop("pose"))

        rate_hz = d.pop("rate_hz")

        sensor_id = d.pop("sensor_id")

        sensor_mount = cls(
            intrinsics=intrinsics,
            pose=pose,
            rate_hz=rate_hz,
            sensor_id=sensor_id,
        )

        return sensor_mount
