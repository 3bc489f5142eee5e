from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..types import UNSET, Unset
from typing import Literal, cast


T = TypeVar("T", bound="LidarIntrinsics")


@_attrs_define
class LidarIntrinsics:
    """A spinning multi-beam LiDAR.

    Attributes:
        azimuth_steps (int | Unset):  Default: 2048.
        beams (int | Unset):  Default: 64.
        kind (Literal['lidar'] | Unset):  Default: 'lidar'.
        max_range_m (float | Unset):  Default: 200.0.
        range_noise_std_m (float | Unset):  Default: 0.02.
        vertical_max_deg (float | Unset):  Default: 11.0.
        vertical_min_deg (float | Unset):  Default: -30.0.
    """

    azimuth_steps: int | Unset = 2048
    beams: int | Unset = 64
    kind: Literal["lidar"] | Unset = "lidar"
    max_range_m: float | Unset = 200.0
    range_noise_std_m: float | Unset = 0.02
    vertical_max_deg: float | Unset = 11.0
    vertical_min_deg: float | Unset = -30.0

    def to_dict(self) -> dict[str, Any]:
        azimuth_steps = self.azimuth_steps

        beams = self.beams

        kind = self.kind

        max_range_m = self.max_range_m

        range_noise_std_m = self.range_noise_std_m

        vertical_max_deg = self.vertical_max_deg

        vertical_min_deg = self.vertical_min_deg

        field_dict: dict[str, Any] = {}

        field_dict.update({})
        if azimuth_steps is not UNSET:
            field_dict["azimuth_steps"] = azimuth_steps
        if beams is not UNSET:
            field_dict["beams"] = beams
        if kind is not UNSET:
            field_dict["kind"] = kind
        if max_range_m is not UNSET:
            field_dict["max_range_m"] = max_range_m
        if range_noise_std_m is not UNSET:
            field_dict["range_noise_std_m"] = range_noise_std_m
        if vertical_max_deg is not UNSET:
            field_dict["vertical_max_deg"] = vertical_max_deg
        if vertical_min_deg is not UNSET:
            field_dict["vertical_min_deg"] = vertical_min_deg

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        azimuth_steps = d.pop("azimuth_steps", UNSET)

        beams = d.pop("beams", UNSET)

        kind = cast(Literal["lidar"] | Unset, d.pop("kind", UNSET))
        if kind != "lidar" and not isinstance(kind, Unset):
            raise ValueError(f"kind must match const 'lidar', got '{kind}'")

        max_range_m = d.pop("max_range_m", UNSET)

        range_noise_std_m = d.pop("range_noise_std_m", UNSET)

        vertical_max_deg = d.pop("vertical_max_deg", UNSET)

        vertical_min_deg = d.pop("vertical_min_deg", UNSET)

        lidar_intrinsics = cls(
            azimuth_steps=azimuth_steps,
            beams=beams,
            kind=kind,
            max_range_m=max_range_m,
            range_noise_std_m=range_noise_std_m,
            vertical_max_deg=vertical_max_deg,
            vertical_min_deg=vertical_min_deg,
        )

        return lidar_intrinsics
