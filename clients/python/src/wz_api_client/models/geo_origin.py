from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..types import UNSET, Unset


T = TypeVar("T", bound="GeoOrigin")


@_attrs_define
class GeoOrigin:
    """WGS84 anchor of the site frame's origin (x = y = 0, z = 0 at ``altitude_m``).

    Attributes:
        latitude_deg (float):
        longitude_deg (float):
        altitude_m (float | Unset):  Default: 0.0.
    """

    latitude_deg: float
    longitude_deg: float
    altitude_m: float | Unset = 0.0

    def to_dict(self) -> dict[str, Any]:
        latitude_deg = self.latitude_deg

        longitude_deg = self.longitude_deg

        altitude_m = self.altitude_m

        field_dict: dict[str, Any] = {}

        field_dict.update(
            {
                "latitude_deg": latitude_deg,
                "longitude_deg": longitude_deg,
            }
        )
        if altitude_m is not UNSET:
            field_dict["altitude_m"] = altitude_m

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        latitude_deg = d.pop("latitude_deg")

        longitude_deg = d.pop("longitude_deg")

        altitude_m = d.pop("altitude_m", UNSET)

        geo_origin = cls(
            latitude_deg=latitude_deg,
            longitude_deg=longitude_deg,
            altitude_m=altitude_m,
        )

        return geo_origin
