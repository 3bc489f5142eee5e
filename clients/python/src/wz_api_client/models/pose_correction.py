from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..types import UNSET, Unset
from typing import cast


T = TypeVar("T", bound="PoseCorrection")


@_attrs_define
class PoseCorrection:
    """What is added to the site file's pose: angles [deg] and a shift in the site frame [m].

    A ``*_std`` of None means the data did not constrain that part (it stays the site file's):
    a straight road tells nothing of a sensor's position along it.

        Attributes:
            pitch_deg (float | Unset):  Default: 0.0.
            pitch_std_deg (float | None | Unset):
            roll_deg (float | Unset):  Default: 0.0.
            roll_std_deg (float | None | Unset):
            x_m (float | Unset):  Default: 0.0.
            x_std_m (float | None | Unset):
            y_m (float | Unset):  Default: 0.0.
            y_std_m (float | None | Unset):
            yaw_deg (float | Unset):  Default: 0.0.
            yaw_std_deg (float | None | Unset):
            z_m (float | Unset):  Default: 0.0.
            z_std_m (float | None | Unset):
    """

    pitch_deg: float | Unset = 0.0
    pitch_std_deg: float | None | Unset = UNSET
    roll_deg: float | Unset = 0.0
    roll_std_deg: float | None | Unset = UNSET
    x_m: float | Unset = 0.0
    x_std_m: float | None | Unset = UNSET
    y_m: float | Unset = 0.0
    y_std_m: float | None | Unset = UNSET
    yaw_deg: float | Unset = 0.0
    yaw_std_deg: float | None | Unset = UNSET
    z_m: float | Unset = 0.0
    z_std_m: float | None | Unset = UNSET

    def to_dict(self) -> dict[str, Any]:
        pitch_deg = self.pitch_deg

        pitch_std_deg: float | None | Unset
        if isinstance(self.pitch_std_deg, Unset):
            pitch_std_deg = UNSET
        else:
            pitch_std_deg = self.pitch_std_deg

        roll_deg = self.roll_deg

        roll_std_deg: float | None | Unset
        if isinstance(self.roll_std_deg, Unset):
            roll_std_deg = UNSET
        else:
            roll_std_deg = self.roll_std_deg

        x_m = self.x_m

        x_std_m: float | None | Unset
        if isinstance(self.x_std_m, Unset):
            x_std_m = UNSET
        else:
            x_std_m = self.x_std_m

        y_m = self.y_m

        y_std_m: float | None | Unset
        if isinstance(self.y_std_m, Unset):
            y_std_m = UNSET
        else:
            y_std_m = self.y_std_m

        yaw_deg = self.yaw_deg

        yaw_std_deg: float | None | Unset
        if isinstance(self.yaw_std_deg, Unset):
            yaw_std_deg = UNSET
        else:
            yaw_std_deg = self.yaw_std_deg

        z_m = self.z_m

        z_std_m: float | None | Unset
        if isinstance(self.z_std_m, Unset):
            z_std_m = UNSET
        else:
            z_std_m = self.z_std_m

        field_dict: dict[str, Any] = {}

        field_dict.update({})
        if pitch_deg is not UNSET:
            field_dict["pitch_deg"] = pitch_deg
        if pitch_std_deg is not UNSET:
            field_dict["pitch_std_deg"] = pitch_std_deg
        if roll_deg is not UNSET:
            field_dict["roll_deg"] = roll_deg
        if roll_std_deg is not UNSET:
            field_dict["roll_std_deg"] = roll_std_deg
        if x_m is not UNSET:
            field_dict["x_m"] = x_m
        if x_std_m is not UNSET:
            field_dict["x_std_m"] = x_std_m
        if y_m is not UNSET:
            field_dict["y_m"] = y_m
        if y_std_m is not UNSET:
            field_dict["y_std_m"] = y_std_m
        if yaw_deg is not UNSET:
            field_dict["yaw_deg"] = yaw_deg
        if yaw_std_deg is not UNSET:
            field_dict["yaw_std_deg"] = yaw_std_deg
        if z_m is not UNSET:
            field_dict["z_m"] = z_m
        if z_std_m is not UNSET:
            field_dict["z_std_m"] = z_std_m

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        pitch_deg = d.pop("pitch_deg", UNSET)

        def _parse_pitch_std_deg(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        pitch_std_deg = _parse_pitch_std_deg(d.pop("pitch_std_deg", UNSET))

        roll_deg = d.pop("roll_deg", UNSET)

        def _parse_roll_std_deg(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        roll_std_deg = _parse_roll_std_deg(d.pop("roll_std_deg", UNSET))

        x_m = d.pop("x_m", UNSET)

        def _parse_x_std_m(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        x_std_m = _parse_x_std_m(d.pop("x_std_m", UNSET))

        y_m = d.pop("y_m", UNSET)

        def _parse_y_std_m(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        y_std_m = _parse_y_std_m(d.pop("y_std_m", UNSET))

        yaw_deg = d.pop("yaw_deg", UNSET)

        def _parse_yaw_std_deg(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        yaw_std_deg = _parse_yaw_std_deg(d.pop("yaw_std_deg", UNSET))

        z_m = d.pop("z_m", UNSET)

        def _parse_z_std_m(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        z_std_m = _parse_z_std_m(d.pop("z_std_m", UNSET))

        pose_correction = cls(
            pitch_deg=pitch_deg,
            pitch_std_deg=pitch_std_deg,
            roll_deg=roll_deg,
            roll_std_deg=roll_std_deg,
            x_m=x_m,
            x_std_m=x_std_m,
            y_m=y_m,
            y_std_m=y_std_m,
            yaw_deg=yaw_deg,
            yaw_std_deg=yaw_std_deg,
            z_m=z_m,
            z_std_m=z_std_m,
        )

        return pose_correction
