from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..types import UNSET, Unset


T = TypeVar("T", bound="ShortTtcRule")


@_attrs_define
class ShortTtcRule:
    """Time to collision with the nearest vehicle ahead in the same lane.

    ``TTC = gap / (v_follower - v_leader)``, ``gap = s_leader - s_follower - (L_f + L_l) / 2``.
    Bins after SSAM (whose default conflict threshold is 1.5 s): info at ``TTC <= max_ttc_s``,
    warning at ``<= warning_ttc_s``, critical at ``<= critical_ttc_s``. Stays open while
    ``TTC <= max_ttc_s + hysteresis_s``. The TTC decided on is the longest the two tracks'
    covariances still allow at ``certainty_sigmas``: the gap widened and the closing speed
    lowered by that many of their standard deviations.

        Attributes:
            certainty_sigmas (float | Unset):  Default: 2.0.
            clear_s (float | Unset):  Default: 1.0.
            cooldown_s (float | Unset):  Default: 5.0.
            critical_ttc_s (float | Unset):  Default: 0.5.
            default_vehicle_length_m (float | Unset):  Default: 4.5.
            enabled (bool | Unset):  Default: True.
            hold_s (float | Unset):  Default: 0.2.
            hysteresis_s (float | Unset):  Default: 0.3.
            max_ttc_s (float | Unset):  Default: 1.5.
            min_closing_speed_mps (float | Unset):  Default: 0.5.
            min_track_age_s (float | Unset):  Default: 2.0.
            warning_ttc_s (float | Unset):  Default: 1.0.
    """

    certainty_sigmas: float | Unset = 2.0
    clear_s: float | Unset = 1.0
    cooldown_s: float | Unset = 5.0
    critical_ttc_s: float | Unset = 0.5
    default_vehicle_length_m: float | Unset = 4.5
    enabled: bool | Unset = True
    hold_s: float | Unset = 0.2
    hysteresis_s: float | Unset = 0.3
    max_ttc_s: float | Unset = 1.5
    min_closing_speed_mps: float | Unset = 0.5
    min_track_age_s: float | Unset = 2.0
    warning_ttc_s: float | Unset = 1.0

    def to_dict(self) -> dict[str, Any]:
        certainty_sigmas = self.certainty_sigmas

        clear_s = self.clear_s

        cooldown_s = self.cooldown_s

        critical_ttc_s = self.critical_ttc_s

        default_vehicle_length_m = self.default_vehicle_length_m

        enabled = self.enabled

        hold_s = self.hold_s

        hysteresis_s = self.hysteresis_s

        max_ttc_s = self.max_ttc_s

        min_closing_speed_mps = self.min_closing_speed_mps

        min_track_age_s = self.min_track_age_s

        warning_ttc_s = self.warning_ttc_s

        field_dict: dict[str, Any] = {}

        field_dict.update({})
        if certainty_sigmas is not UNSET:
            field_dict["certainty_sigmas"] = certainty_sigmas
        if clear_s is not UNSET:
            field_dict["clear_s"] = clear_s
        if cooldown_s is not UNSET:
            field_dict["cooldown_s"] = cooldown_s
        if critical_ttc_s is not UNSET:
            field_dict["critical_ttc_s"] = critical_ttc_s
        if default_vehicle_length_m is not UNSET:
            field_dict["default_vehicle_length_m"] = default_vehicle_length_m
        if enabled is not UNSET:
            field_dict["enabled"] = enabled
        if hold_s is not UNSET:
            field_dict["hold_s"] = hold_s
        if hysteresis_s is not UNSET:
            field_dict["hysteresis_s"] = hysteresis_s
        if max_ttc_s is not UNSET:
            field_dict["max_ttc_s"] = max_ttc_s
        if min_closing_speed_mps is not UNSET:
            field_dict["min_closing_speed_mps"] = min_closing_speed_mps
        if min_track_age_s is not UNSET:
            field_dict["min_track_age_s"] = min_track_age_s
        if warning_ttc_s is not UNSET:
            field_dict["warning_ttc_s"] = warning_ttc_s

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        certainty_sigmas = d.pop("certainty_sigmas", UNSET)

        clear_s = d.pop("clear_s", UNSET)

        cooldown_s = d.pop("cooldown_s", UNSET)

        critical_ttc_s = d.pop("critical_ttc_s", UNSET)

        default_vehicle_length_m = d.pop("default_vehicle_length_m", UNSET)

        enabled = d.pop("enabled", UNSET)

        hold_s = d.pop("hold_s", UNSET)

        hysteresis_s = d.pop("hysteresis_s", UNSET)

        max_ttc_s = d.pop("max_ttc_s", UNSET)

        min_closing_speed_mps = d.pop("min_closing_speed_mps", UNSET)

        min_track_age_s = d.pop("min_track_age_s", UNSET)

        warning_ttc_s = d.pop("warning_ttc_s", UNSET)

        short_ttc_rule = cls(
            certainty_sigmas=certainty_sigmas,
            clear_s=clear_s,
            cooldown_s=cooldown_s,
            critical_ttc_s=critical_ttc_s,
            default_vehicle_length_m=default_vehicle_length_m,
            enabled=enabled,
            hold_s=hold_s,
            hysteresis_s=hysteresis_s,
            max_ttc_s=max_ttc_s,
            min_closing_speed_mps=min_closing_speed_mps,
            min_track_age_s=min_track_age_s,
            warning_ttc_s=warning_ttc_s,
        )

        return short_ttc_rule
