from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..types import UNSET, Unset
from typing import Literal, cast


T = TypeVar("T", bound="RadarIntrinsics")


@_attrs_define
class RadarIntrinsics:
    """An automotive-style radar reporting targets (range, azimuth, radial speed, RCS).

    Attributes:
        azimuth_noise_std_deg (float | Unset):  Default: 0.5.
        azimuth_resolution_deg (float | Unset):  Default: 4.0.
        horizontal_fov_deg (float | Unset):  Default: 60.0.
        kind (Literal['radar'] | Unset):  Default: 'radar'.
        max_range_m (float | Unset):  Default: 200.0.
        range_noise_std_m (float | Unset):  Default: 0.25.
        range_resolution_m (float | Unset):  Default: 1.5.
        speed_noise_std_mps (float | Unset):  Default: 0.1.
    """

    azimuth_noise_std_deg: float | Unset = 0.5
    azimuth_resolution_deg: float | Unset = 4.0
    horizontal_fov_deg: float | Unset = 60.0
    kind: Literal["radar"] | Unset = "radar"
    max_range_m: float | Unset = 200.0
    range_noise_std_m: float | Unset = 0.25
    range_resolution_m: float | Unset = 1.5
    speed_noise_std_mps: float | Unset = 0.1

    def to_dict(self) -> dict[str, Any]:
        azimuth_noise_std_deg = self.azimuth_noise_std_deg

        azimuth_resolution_deg = self.azimuth_resolution_deg

        horizontal_fov_deg = self.horizontal_fov_deg

        kind = self.kind

        max_range_m = self.max_range_m

        range_noise_std_m = self.range_noise_std_m

        range_resolution_m = self.range_resolution_m

        speed_noise_std_mps = self.speed_noise_std_mps

        field_dict: dict[str, Any] = {}

        field_dict.update({})
        if azimuth_noise_std_deg is not UNSET:
            field_dict["azimuth_noise_std_deg"] = azimuth_noise_std_deg
        if azimuth_resolution_deg is not UNSET:
            field_dict["azimuth_resolution_deg"] = azimuth_resolution_deg
        if horizontal_fov_deg is not UNSET:
            field_dict["horizontal_fov_deg"] = horizontal_fov_deg
        if kind is not UNSET:
            field_dict["kind"] = kind
        if max_range_m is not UNSET:
            field_dict["max_range_m"] = max_range_m
        if range_noise_std_m is not UNSET:
            field_dict["range_noise_std_m"] = range_noise_std_m
        if range_resolution_m is not UNSET:
            field_dict["range_resolution_m"] = range_resolution_m
        if speed_noise_std_mps is not UNSET:
            field_dict["speed_noise_std_mps"] = speed_noise_std_mps

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        azimuth_noise_std_deg = d.pop("azimuth_noise_std_deg", UNSET)

        azimuth_resolution_deg = d.pop("azimuth_resolution_deg", UNSET)

        horizontal_fov_deg = d.pop("horizontal_fov_deg", UNSET)

        kind = cast(Literal["radar"] | Unset, d.pop("kind", UNSET))
        if kind != "radar" and not isinstance(kind, Unset):
            raise ValueError(f"kind must match const 'radar', got '{kind}'")

        max_range_m = d.pop("max_range_m", UNSET)

        range_noise_std_m = d.pop("range_noise_std_m", UNSET)

        range_resolution_m = d.pop("range_resolution_m", UNSET)

        speed_noise_std_mps = d.pop("speed_noise_std_mps", UNSET)

        radar_intrinsics = cls(
            azimuth_noise_std_deg=azimuth_noise_std_deg,
            azimuth_resolution_deg=azimuth_resolution_deg,
            horizontal_fov_deg=horizontal_fov_deg,
            kind=kind,
            max_range_m=max_range_m,
            range_noise_std_m=range_noise_std_m,
            range_resolution_m=range_resolution_m,
            speed_noise_std_mps=speed_noise_std_mps,
        )

        return radar_intrinsics
