from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..types import UNSET, Unset


T = TypeVar("T", bound="HardBrakingRule")


@_attrs_define
class HardBrakingRule:
    """Deceleration from the least-squares slope of the track's speed over ``window_s``.

    Starts at ``-dv/dt >= decel_g * g``, stays open down to ``(decel_g - hysteresis_g) * g``;
    critical from ``critical_decel_g * g`` (g = 9.80665 m/s^2).

        Attributes:
            certainty_sigmas (float | Unset):  Default: 2.0.
            clear_s (float | Unset):  Default: 1.0.
            cooldown_s (float | Unset):  Default: 5.0.
            critical_decel_g (float | Unset):  Default: 0.6.
            decel_g (float | Unset):  Default: 0.4.
            enabled (bool | Unset):  Default: True.
            hold_s (float | Unset):  Default: 0.3.
            hysteresis_g (float | Unset):  Default: 0.05.
            min_samples (int | Unset):  Default: 5.
            window_s (float | Unset):  Default: 0.8.
    """

    certainty_sigmas: float | Unset = 2.0
    clear_s: float | Unset = 1.0
    cooldown_s: float | Unset = 5.0
    critical_decel_g: float | Unset = 0.6
    decel_g: float | Unset = 0.4
    enabled: bool | Unset = True
    hold_s: float | Unset = 0.3
    hysteresis_g: float | Unset = 0.05
    min_samples: int | Unset = 5
    window_s: float | Unset = 0.8

    def to_dict(self) -> dict[str, Any]:
        certainty_sigmas = self.certainty_sigmas

        clear_s = self.clear_s

        cooldown_s = self.cooldown_s

        critical_decel_g = self.critical_decel_g

        decel_g = self.decel_g

        enabled = self.enabled

        hold_s = self.hold_s

        hysteresis_g = self.hysteresis_g

        min_samples = self.min_samples

        window_s = self.window_s

        field_dict: dict[str, Any] = {}

        field_dict.update({})
        if certainty_sigmas is not UNSET:
            field_dict["certainty_sigmas"] = certainty_sigmas
        if clear_s is not UNSET:
            field_dict["clear_s"] = clear_s
        if cooldown_s is not UNSET:
            field_dict["cooldown_s"] = cooldown_s
        if critical_decel_g is not UNSET:
            field_dict["critical_decel_g"] = critical_decel_g
        if decel_g is not UNSET:
            field_dict["decel_g"] = decel_g
        if enabled is not UNSET:
            field_dict["enabled"] = enabled
        if hold_s is not UNSET:
            field_dict["hold_s"] = hold_s
        if hysteresis_g is not UNSET:
            field_dict["hysteresis_g"] = hysteresis_g
        if min_samples is not UNSET:
            field_dict["min_samples"] = min_samples
        if window_s is not UNSET:
            field_dict["window_s"] = window_s

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        certainty_sigmas = d.pop("certainty_sigmas", UNSET)

        clear_s = d.pop("clear_s", UNSET)

        cooldown_s = d.pop("cooldown_s", UNSET)

        critical_decel_g = d.pop("critical_decel_g", UNSET)

        decel_g = d.pop("decel_g", UNSET)

        enabled = d.pop("enabled", UNSET)

        hold_s = d.pop("hold_s", UNSET)

        hysteresis_g = d.pop("hysteresis_g", UNSET)

        min_samples = d.pop("min_samples", UNSET)

        window_s = d.pop("window_s", UNSET)

        hard_braking_rule = cls(
            certainty_sigmas=certainty_sigmas,
            clear_s=clear_s,
            cooldown_s=cooldown_s,
            critical_decel_g=critical_decel_g,
            decel_g=decel_g,
            enabled=enabled,
            hold_s=hold_s,
            hysteresis_g=hysteresis_g,
            min_samples=min_samples,
            window_s=window_s,
        )

        return hard_braking_rule
