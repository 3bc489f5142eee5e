from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..types import UNSET, Unset
from typing import cast


T = TypeVar("T", bound="DeviceRules")


@_attrs_define
class DeviceRules:
    """Roadside devices driven by the alerts: a flashing beacon and a message sign.

    Attributes:
        message_hold_s (float | Unset):  Default: 5.0.
        sign_station_m (float | None | Unset):
    """

    message_hold_s: float | Unset = 5.0
    sign_station_m: float | None | Unset = UNSET

    def to_dict(self) -> dict[str, Any]:
        message_hold_s = self.message_hold_s

        sign_station_m: float | None | Unset
        if isinstance(self.sign_station_m, Unset):
            sign_station_m = UNSET
        else:
            sign_station_m = self.sign_station_m

        field_dict: dict[str, Any] = {}

        field_dict.update({})
        if message_hold_s is not UNSET:
            field_dict["message_hold_s"] = message_hold_s
        if sign_station_m is not UNSET:
            field_dict["sign_station_m"] = sign_station_m

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        message_hold_s = d.pop("message_hold_s", UNSET)

        def _parse_sign_station_m(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        sign_station_m = _parse_sign_station_m(d.pop("sign_station_m", UNSET))

        device_rules = cls(
            message_hold_s=message_hold_s,
            sign_station_m=sign_station_m,
        )

        return device_rules
