from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..types import UNSET, Unset


T = TypeVar("T", bound="Pose")


@_attrs_define
class Pose:
    """Sensor pose in the site frame: position [m] and yaw/pitch/roll [deg].

    The sensor frame has x forward, y left, z up. yaw is measured counter-clockwise from the
    site x axis (east); pitch is positive nose-up (a sensor looking down at the road has
    negative pitch); roll is positive right side down (about x). See :meth:`rotation`.

        Attributes:
            x_m (float):
            y_m (float):
            z_m (float):
            pitch_deg (float | Unset):  Default: 0.0.
            roll_deg (float | Unset):  Default: 0.0.
            yaw_deg (float | Unset):  Default: 0.0.
    """

    x_m: float
    y_m: float
    z_m: float
    pitch_deg: float | Unset = 0.0
    roll_deg: float | Unset = 0.0
    yaw_deg: float | Unset = 0.0

    def to_dict(self) -> dict[str, Any]:
        x_m = self.x_m

        y_m = self.y_m

        z_m = self.z_m

        pitch_deg = self.pitch_deg

        roll_deg = self.roll_deg

        yaw_deg = self.yaw_deg

        field_dict: dict[str, Any] = {}

        field_dict.update(
            {
                "x_m": x_m,
                "y_m": y_m,
                "z_m": z_m,
            }
        )
        if pitch_deg is not UNSET:
            field_dict["pitch_deg"] = pitch_deg
        if roll_deg is not UNSET:
            field_dict["roll_deg"] = roll_deg
        if yaw_deg is not UNSET:
            field_dict["yaw_deg"] = yaw_deg

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        x_m = d.pop("x_m")

        y_m = d.pop("y_m")

        z_m = d.pop("z_m")

        pitch_deg = d.pop("pitch_deg", UNSET)

        roll_deg = d.pop("roll_deg", UNSET)

        yaw_deg = d.pop("yaw_deg", UNSET)

        pose = cls(
            x_m=x_m,
            y_m=y_m,
            z_m=z_m,
            pitch_deg=pitch_deg,
            roll_deg=roll_deg,
            yaw_deg=yaw_deg,
        )

        return pose
