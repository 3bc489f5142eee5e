from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..types import UNSET, Unset
from typing import cast


T = TypeVar("T", bound="AggressiveApproachRule")


@_attrs_define
class AggressiveApproachRule:
    """Too fast, too close to the taper: the deceleration still needed, or not slowing at all.

    Required deceleration to reach the zone limit ``v_zone`` by the taper start, ``D`` metres
    ahead: ``a = (v^2 - v_zone^2) / (2 D)`` [m/s^2]. Starts at ``a >= comfortable_decel_mps2``
    (stays open down to ``comfortable_decel_mps2 - hysteresis_mps2``), critical from
    ``critical_decel_mps2``; or, past the advance-warning point, when the speed is above the
    zone limit by ``speed_margin_mph`` and its trend over ``trend_window_s`` is above
    ``-not_slowing_decel_mps2`` (the driver has not lifted off).

        Attributes:
            advance_warning_station_m (float | None | Unset):
            clear_s (float | Unset):  Default: 2.0.
            comfortable_decel_mps2 (float | Unset):  Default: 3.4.
            cooldown_s (float | Unset):  Default: 10.0.
            critical_decel_mps2 (float | Unset):  Default: 4.9.
            enabled (bool | Unset):  Default: True.
            hold_s (float | Unset):  Default: 1.0.
            hysteresis_mps2 (float | Unset):  Default: 0.4.
            not_slowing_decel_mps2 (float | Unset):  Default: 0.3.
            speed_margin_mph (float | Unset):  Default: 5.0.
            trend_window_s (float | Unset):  Default: 1.0.
    """

    advance_warning_station_m: float | None | Unset = UNSET
    clear_s: float | Unset = 2.0
    comfortable_decel_mps2: float | Unset = 3.4
    cooldown_s: float | Unset = 10.0
    critical_decel_mps2: float | Unset = 4.9
    enabled: bool | Unset = True
    hold_s: float | Unset = 1.0
    hysteresis_mps2: float | Unset = 0.4
    not_slowing_decel_mps2: float | Unset = 0.3
    speed_margin_mph: float | Unset = 5.0
    trend_window_s: float | Unset = 1.0

    def to_dict(self) -> dict[str, Any]:
        advance_warning_station_m: float | None | Unset
        if isinstance(self.advance_warning_station_m, Unset):
            advance_warning_station_m = UNSET
        else:
            advance_warning_station_m = self.advance_warning_station_m

        clear_s = self.clear_s

        comfortable_decel_mps2 = self.comfortable_decel_mps2

        cooldown_s = self.cooldown_s

        critical_decel_mps2 = self.critical_decel_mps2

        enabled = self.enabled

        hold_s = self.hold_s

        hysteresis_mps2 = self.hysteresis_mps2

        not_slowing_decel_mps2 = self.not_slowing_decel_mps2

        speed_margin_mph = self.speed_margin_mph

        trend_window_s = self.trend_window_s

        field_dict: dict[str, Any] = {}

        field_dict.update({})
        if advance_warning_station_m is not UNSET:
            field_dict["advance_warning_station_m"] = advance_warning_station_m
        if clear_s is not UNSET:
            field_dict["clear_s"] = clear_s
        if comfortable_decel_mps2 is not UNSET:
            field_dict["comfortable_decel_mps2"] = comfortable_decel_mps2
        if cooldown_s is not UNSET:
            field_dict["cooldown_s"] = cooldown_s
        if critical_decel_mps2 is not UNSET:
            field_dict["critical_decel_mps2"] = critical_decel_mps2
        if enabled is not UNSET:
            field_dict["enabled"] = enabled
        if hold_s is not UNSET:
            field_dict["hold_s"] = hold_s
        if hysteresis_mps2 is not UNSET:
            field_dict["hysteresis_mps2"] = hysteresis_mps2
        if not_slowing_decel_mps2 is not UNSET:
            field_dict["not_slowing_decel_mps2"] = not_slowing_decel_mps2
        if speed_margin_mph is not UNSET:
            field_dict["speed_margin_mph"] = speed_margin_mph
        if trend_window_s is not UNSET:
            field_dict["trend_window_s"] = trend_window_s

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)

        def _parse_advance_warning_station_m(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        advance_warning_station_m = _parse_advance_warning_station_m(
            d.pop("advance_warning_station_m", UNSET)
        )

        clear_s = d.pop("clear_s", UNSET)

        comfortable_decel_mps2 = d.pop("comfortable_decel_mps2", UNSET)

        cooldown_s = d.pop("cooldown_s", UNSET)

        critical_decel_mps2 = d.pop("critical_decel_mps2", UNSET)

        enabled = d.pop("enabled", UNSET)

        hold_s = d.pop("hold_s", UNSET)

        hysteresis_mps2 = d.pop("hysteresis_mps2", UNSET)

        not_slowing_decel_mps2 = d.pop("not_slowing_decel_mps2", UNSET)

        speed_margin_mph = d.pop("speed_margin_mph", UNSET)

        trend_window_s = d.pop("trend_window_s", UNSET)

        aggressive_approach_rule = cls(
            advance_warning_station_m=advance_warning_station_m,
            clear_s=clear_s,
            comfortable_decel_mps2=comfortable_decel_mps2,
            cooldown_s=cooldown_s,
            critical_decel_mps2=critical_decel_mps2,
            enabled=enabled,
            hold_s=hold_s,
            hysteresis_mps2=hysteresis_mps2,
            not_slowing_decel_mps2=not_slowing_decel_mps2,
            speed_margin_mph=speed_margin_mph,
            trend_window_s=trend_window_s,
        )

        return aggressive_approach_rule
