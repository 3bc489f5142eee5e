from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..types import UNSET, Unset


T = TypeVar("T", bound="LateMergeRule")


@_attrs_define
class LateMergeRule:
    """Still in the closed lane within ``distance_m`` of the taper start (or in the taper).

    Starts when the track's lane is the closed one (or its offset is in the closed lane's band)
    at ``speed >= min_speed_mps``; stays open while the offset is within the band widened by
    ``lateral_hysteresis_m`` and ``speed >= min_speed_mps - speed_hysteresis_mps``. Warning
    before the taper, critical inside it.

        Attributes:
            clear_s (float | Unset):  Default: 1.0.
            cooldown_s (float | Unset):  Default: 10.0.
            distance_m (float | Unset):  Default: 150.0.
            enabled (bool | Unset):  Default: True.
            hold_s (float | Unset):  Default: 0.5.
            lateral_hysteresis_m (float | Unset):  Default: 0.3.
            min_speed_mps (float | Unset):  Default: 13.4.
            speed_hysteresis_mps (float | Unset):  Default: 1.0.
    """

    clear_s: float | Unset = 1.0
    cooldown_s: float | Unset = 10.0
    distance_m: float | Unset = 150.0
    enabled: bool | Unset = True
    hold_s: float | Unset = 0.5
    lateral_hysteresis_m: float | Unset = 0.3
    min_speed_mps: float | Unset = 13.4
    speed_hysteresis_mps: float | Unset = 1.0

    def to_dict(self) -> dict[str, Any]:
        clear_s = self.clear_s

        cooldown_s = self.cooldown_s

        distance_m = self.distance_m

        enabled = self.enabled

        hold_s = self.hold_s

        lateral_hysteresis_m = self.lateral_hysteresis_m

        min_speed_mps = self.min_speed_mps

        speed_hysteresis_mps = self.speed_hysteresis_mps

        field_dict: dict[str, Any] = {}

        field_dict.update({})
        if clear_s is not UNSET:
            field_dict["clear_s"] = clear_s
        if cooldown_s is not UNSET:
            field_dict["cooldown_s"] = cooldown_s
        if distance_m is not UNSET:
            field_dict["distance_m"] = distance_m
        if enabled is not UNSET:
            field_dict["enabled"] = enabled
        if hold_s is not UNSET:
            field_dict["hold_s"] = hold_s
        if lateral_hysteresis_m is not UNSET:
            field_dict["lateral_hysteresis_m"] = lateral_hysteresis_m
        if min_speed_mps is not UNSET:
            field_dict["min_speed_mps"] = min_speed_mps
        if speed_hysteresis_mps is not UNSET:
            field_dict["speed_hysteresis_mps"] = speed_hysteresis_mps

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        clear_s = d.pop("clear_s", UNSET)

        cooldown_s = d.pop("cooldown_s", UNSET)

        distance_m = d.pop("distance_m", UNSET)

        enabled = d.pop("enabled", UNSET)

        hold_s = d.pop("hold_s", UNSET)

        lateral_hysteresis_m = d.pop("lateral_hysteresis_m", UNSET)

        min_speed_mps = d.pop("min_speed_mps", UNSET)

        speed_hysteresis_mps = d.pop("speed_hysteresis_mps", UNSET)

        late_merge_rule = cls(
            clear_s=clear_s,
            cooldown_s=cooldown_s,
            distance_m=distance_m,
            enabled=enabled,
            hold_s=hold_s,
            lateral_hysteresis_m=lateral_hysteresis_m,
            min_speed_mps=min_speed_mps,
            speed_hysteresis_mps=speed_hysteresis_mps,
        )

        return late_merge_rule
