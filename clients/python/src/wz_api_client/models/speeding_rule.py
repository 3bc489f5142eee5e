from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..types import UNSET, Unset


T = TypeVar("T", bound="SpeedingRule")


@_attrs_define
class SpeedingRule:
    """Speed over the posted limit at the vehicle's station, within the approach.

    Starts at ``excess >= margin_mph``, stays open while ``excess >= margin_mph -
    hysteresis_mph``; critical from ``critical_excess_mph``. Margins are in mph, like the posted
    limits they are added to.

        Attributes:
            certainty_sigmas (float | Unset):  Default: 0.0.
            clear_s (float | Unset):  Default: 2.0.
            cooldown_s (float | Unset):  Default: 10.0.
            critical_excess_mph (float | Unset):  Default: 15.0.
            enabled (bool | Unset):  Default: True.
            hold_s (float | Unset):  Default: 1.0.
            hysteresis_mph (float | Unset):  Default: 2.0.
            margin_mph (float | Unset):  Default: 5.0.
    """

    certainty_sigmas: float | Unset = 0.0
    clear_s: float | Unset = 2.0
    cooldown_s: float | Unset = 10.0
    critical_excess_mph: float | Unset = 15.0
    enabled: bool | Unset = True
    hold_s: float | Unset = 1.0
    hysteresis_mph: float | Unset = 2.0
    margin_mph: float | Unset = 5.0

    def to_dict(self) -> dict[str, Any]:
        certainty_sigmas = self.certainty_sigmas

        clear_s = self.clear_s

        cooldown_s = self.cooldown_s

        critical_excess_mph = self.critical_excess_mph

        enabled = self.enabled

        hold_s = self.hold_s

        hysteresis_mph = self.hysteresis_mph

        margin_mph = self.margin_mph

        field_dict: dict[str, Any] = {}

        field_dict.update({})
        if certainty_sigmas is not UNSET:
            field_dict["certainty_sigmas"] = certainty_sigmas
        if clear_s is not UNSET:
            field_dict["clear_s"] = clear_s
        if cooldown_s is not UNSET:
            field_dict["cooldown_s"] = cooldown_s
        if critical_excess_mph is not UNSET:
            field_dict["critical_excess_mph"] = critical_excess_mph
        if enabled is not UNSET:
            field_dict["enabled"] = enabled
        if hold_s is not UNSET:
            field_dict["hold_s"] = hold_s
        if hysteresis_mph is not UNSET:
            field_dict["hysteresis_mph"] = hysteresis_mph
        if margin_mph is not UNSET:
            field_dict["margin_mph"] = margin_mph

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        certainty_sigmas = d.pop("certainty_sigmas", UNSET)

        clear_s = d.pop("clear_s", UNSET)

        cooldown_s = d.pop("cooldown_s", UNSET)

        critical_excess_mph = d.pop("critical_excess_mph", UNSET)

        enabled = d.pop("enabled", UNSET)

        hold_s = d.pop("hold_s", UNSET)

        hysteresis_mph = d.pop("hysteresis_mph", UNSET)

        margin_mph = d.pop("margin_mph", UNSET)

        speeding_rule = cls(
            certainty_sigmas=certainty_sigmas,
            clear_s=clear_s,
            cooldown_s=cooldown_s,
            critical_excess_mph=critical_excess_mph,
            enabled=enabled,
            hold_s=hold_s,
            hysteresis_mph=hysteresis_mph,
            margin_mph=margin_mph,
        )

        return speeding_rule
