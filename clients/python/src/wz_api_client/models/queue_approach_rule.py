from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..types import UNSET, Unset


T = TypeVar("T", bound="QueueApproachRule")


@_attrs_define
class QueueApproachRule:
    """Approaching the back of the lane's queue too fast: the deceleration needed to stop
    behind it.

    For a track upstream of its lane's queue (:mod:`wz_alert_service.queues`) and not slow
    itself, with the queue's back ``s_b``, the track at ``s`` and speed ``v``, the queue's mean
    speed ``u``: the room to stop ``D = s_b - s - stop_spacing_m`` and the deceleration needed
    to come down to ``u`` within it, ``a = (v^2 - u^2) / (2 D)``. Starts at ``a >=
    comfortable_decel_mps2`` (or ``D <= 0`` while still closing), stays open down to
    ``comfortable_decel_mps2 - hysteresis_mps2``; critical from ``critical_decel_mps2``. The
    lead time is ``D / (v - u)``: how long until the track reaches the back at its speed.

        Attributes:
            clear_s (float | Unset):  Default: 1.0.
            comfortable_decel_mps2 (float | Unset):  Default: 3.4.
            cooldown_s (float | Unset):  Default: 10.0.
            critical_decel_mps2 (float | Unset):  Default: 4.9.
            enabled (bool | Unset):  Default: True.
            hold_s (float | Unset):  Default: 0.5.
            hysteresis_mps2 (float | Unset):  Default: 0.4.
            stop_spacing_m (float | Unset):  Default: 7.5.
    """

    clear_s: float | Unset = 1.0
    comfortable_decel_mps2: float | Unset = 3.4
    cooldown_s: float | Unset = 10.0
    critical_decel_mps2: float | Unset = 4.9
    enabled: bool | Unset = True
    hold_s: float | Unset = 0.5
    hysteresis_mps2: float | Unset = 0.4
    stop_spacing_m: float | Unset = 7.5

    def to_dict(self) -> dict[str, Any]:
        clear_s = self.clear_s

        comfortable_decel_mps2 = self.comfortable_decel_mps2

        cooldown_s = self.cooldown_s

        critical_decel_mps2 = self.critical_decel_mps2

        enabled = self.enabled

        hold_s = self.hold_s

        hysteresis_mps2 = self.hysteresis_mps2

        stop_spacing_m = self.stop_spacing_m

        field_dict: dict[str, Any] = {}

        field_dict.update({})
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
        if stop_spacing_m is not UNSET:
            field_dict["stop_spacing_m"] = stop_spacing_m

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        clear_s = d.pop("clear_s", UNSET)

        comfortable_decel_mps2 = d.pop("comfortable_decel_mps2", UNSET)

        cooldown_s = d.pop("cooldown_s", UNSET)

        critical_decel_mps2 = d.pop("critical_decel_mps2", UNSET)

        enabled = d.pop("enabled", UNSET)

        hold_s = d.pop("hold_s", UNSET)

        hysteresis_mps2 = d.pop("hysteresis_mps2", UNSET)

        stop_spacing_m = d.pop("stop_spacing_m", UNSET)

        queue_approach_rule = cls(
            clear_s=clear_s,
            comfortable_decel_mps2=comfortable_decel_mps2,
            cooldown_s=cooldown_s,
            critical_decel_mps2=critical_decel_mps2,
            enabled=enabled,
            hold_s=hold_s,
            hysteresis_mps2=hysteresis_mps2,
            stop_spacing_m=stop_spacing_m,
        )

        return queue_approach_rule
