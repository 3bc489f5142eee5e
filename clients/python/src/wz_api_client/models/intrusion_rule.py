from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..types import UNSET, Unset


T = TypeVar("T", bound="IntrusionRule")


@_attrs_define
class IntrusionRule:
    """A vehicle in the closed lane inside the buffer or activity area.

    Starts when the track's offset is in the closed lane's band (or its lane is the closed one)
    between the buffer's start and the activity area's end at ``speed >= min_speed_mps``; stays
    open while the offset is in the band widened by ``lateral_hysteresis_m``. Warning in the
    buffer, critical in the activity area.

        Attributes:
            clear_s (float | Unset):  Default: 1.0.
            cooldown_s (float | Unset):  Default: 10.0.
            enabled (bool | Unset):  Default: True.
            hold_s (float | Unset):  Default: 0.3.
            lateral_hysteresis_m (float | Unset):  Default: 0.3.
            min_speed_mps (float | Unset):  Default: 4.5.
    """

    clear_s: float | Unset = 1.0
    cooldown_s: float | Unset = 10.0
    enabled: bool | Unset = True
    hold_s: float | Unset = 0.3
    lateral_hysteresis_m: float | Unset = 0.3
    min_speed_mps: float | Unset = 4.5

    def to_dict(self) -> dict[str, Any]:
        clear_s = self.clear_s

        cooldown_s = self.cooldown_s

        enabled = self.enabled

        hold_s = self.hold_s

        lateral_hysteresis_m = self.lateral_hysteresis_m

        min_speed_mps = self.min_speed_mps

        field_dict: dict[str, Any] = {}

        field_dict.update({})
        if clear_s is not UNSET:
            field_dict["clear_s"] = clear_s
        if cooldown_s is not UNSET:
            field_dict["cooldown_s"] = cooldown_s
        if enabled is not UNSET:
            field_dict["enabled"] = enabled
        if hold_s is not UNSET:
            field_dict["hold_s"] = hold_s
        if lateral_hysteresis_m is not UNSET:
            field_dict["lateral_hysteresis_m"] = lateral_hysteresis_m
        if min_speed_mps is not UNSET:
            field_dict["min_speed_mps"] = min_speed_mps

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        clear_s = d.pop("clear_s", UNSET)

        cooldown_s = d.pop("cooldown_s", UNSET)

        enabled = d.pop("enabled", UNSET)

        hold_s = d.pop("hold_s", UNSET)

        lateral_hysteresis_m = d.pop("lateral_hysteresis_m", UNSET)

        min_speed_mps = d.pop("min_speed_mps", UNSET)

        intrusion_rule = cls(
            clear_s=clear_s,
            cooldown_s=cooldown_s,
            enabled=enabled,
            hold_s=hold_s,
            lateral_hysteresis_m=lateral_hysteresis_m,
            min_speed_mps=min_speed_mps,
        )

        return intrusion_rule
