from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..types import UNSET, Unset


T = TypeVar("T", bound="QueueRule")


@_attrs_define
class QueueRule:
    """Slow or stopped traffic: ``min_vehicles`` slow vehicles within ``span_m`` of station.

    A vehicle is slow below ``slow_speed_mps`` (below ``slow_speed_mps + speed_hysteresis_mps``
    while a queue is open). One site-level episode, reported at the queue's tail (its most
    upstream slow vehicle); critical when the tail is ``critical_backup_m`` or more upstream of
    the taper start.

        Attributes:
            clear_s (float | Unset):  Default: 10.0.
            cooldown_s (float | Unset):  Default: 30.0.
            critical_backup_m (float | Unset):  Default: 300.0.
            enabled (bool | Unset):  Default: True.
            hold_s (float | Unset):  Default: 3.0.
            min_vehicles (int | Unset):  Default: 3.
            slow_speed_mps (float | Unset):  Default: 8.9.
            span_m (float | Unset):  Default: 100.0.
            speed_hysteresis_mps (float | Unset):  Default: 2.0.
            stopped_speed_mps (float | Unset):  Default: 2.2.
    """

    clear_s: float | Unset = 10.0
    cooldown_s: float | Unset = 30.0
    critical_backup_m: float | Unset = 300.0
    enabled: bool | Unset = True
    hold_s: float | Unset = 3.0
    min_vehicles: int | Unset = 3
    slow_speed_mps: float | Unset = 8.9
    span_m: float | Unset = 100.0
    speed_hysteresis_mps: float | Unset = 2.0
    stopped_speed_mps: float | Unset = 2.2

    def to_dict(self) -> dict[str, Any]:
        clear_s = self.clear_s

        cooldown_s = self.cooldown_s

        critical_backup_m = self.critical_backup_m

        enabled = self.enabled

        hold_s = self.hold_s

        min_vehicles = self.min_vehicles

        slow_speed_mps = self.slow_speed_mps

        span_m = self.span_m

        speed_hysteresis_mps = self.speed_hysteresis_mps

        stopped_speed_mps = self.stopped_speed_mps

        field_dict: dict[str, Any] = {}

        field_dict.update({})
        if clear_s is not UNSET:
            field_dict["clear_s"] = clear_s
        if cooldown_s is not UNSET:
            field_dict["cooldown_s"] = cooldown_s
        if critical_backup_m is not UNSET:
            field_dict["critical_backup_m"] = critical_backup_m
        if enabled is not UNSET:
            field_dict["enabled"] = enabled
        if hold_s is not UNSET:
            field_dict["hold_s"] = hold_s
        if min_vehicles is not UNSET:
            field_dict["min_vehicles"] = min_vehicles
        if slow_speed_mps is not UNSET:
            field_dict["slow_speed_mps"] = slow_speed_mps
        if span_m is not UNSET:
            field_dict["span_m"] = span_m
        if speed_hysteresis_mps is not UNSET:
            field_dict["speed_hysteresis_mps"] = speed_hysteresis_mps
        if stopped_speed_mps is not UNSET:
            field_dict["stopped_speed_mps"] = stopped_speed_mps

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        clear_s = d.pop("clear_s", UNSET)

        cooldown_s = d.pop("cooldown_s", UNSET)

        critical_backup_m = d.pop("critical_backup_m", UNSET)

        enabled = d.pop("enabled", UNSET)

        hold_s = d.pop("hold_s", UNSET)

        min_vehicles = d.pop("min_vehicles", UNSET)

        slow_speed_mps = d.pop("slow_speed_mps", UNSET)

        span_m = d.pop("span_m", UNSET)

        speed_hysteresis_mps = d.pop("speed_hysteresis_mps", UNSET)

        stopped_speed_mps = d.pop("stopped_speed_mps", UNSET)

        queue_rule = cls(
            clear_s=clear_s,
            cooldown_s=cooldown_s,
            critical_backup_m=critical_backup_m,
            enabled=enabled,
            hold_s=hold_s,
            min_vehicles=min_vehicles,
            slow_speed_mps=slow_speed_mps,
            span_m=span_m,
            speed_hysteresis_mps=speed_hysteresis_mps,
            stopped_speed_mps=stopped_speed_mps,
        )

        return queue_rule
