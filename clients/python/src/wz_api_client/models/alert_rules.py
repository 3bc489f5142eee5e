from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..types import UNSET, Unset
from typing import cast

if TYPE_CHECKING:
    from ..models.aggressive_approach_rule import AggressiveApproachRule
    from ..models.device_rules import DeviceRules
    from ..models.hard_braking_rule import HardBrakingRule
    from ..models.intrusion_rule import IntrusionRule
    from ..models.late_merge_rule import LateMergeRule
    from ..models.queue_approach_rule import QueueApproachRule
    from ..models.queue_rule import QueueRule
    from ..models.short_ttc_rule import ShortTtcRule
    from ..models.speeding_rule import SpeedingRule


T = TypeVar("T", bound="AlertRules")


@_attrs_define
class AlertRules:
    """Thresholds of the alert service, with units; every rule works in the road frame.

    The approach is the station window ``[activity end - approach_length_m, activity end)``:
    speeding, aggressive approach, hard braking, late merge, short TTC, queue and queue approach look only
    there. Each rule has its own :class:`EpisodeTiming` (hold, clear, cool-down).

        Attributes:
            aggressive_approach (AggressiveApproachRule | Unset): Too fast, too close to the taper: the deceleration still
                needed, or not slowing at all.

                Required deceleration to reach the zone limit ``v_zone`` by the taper start, ``D`` metres
                ahead: ``a = (v^2 - v_zone^2) / (2 D)`` [m/s^2]. Starts at ``a >= comfortable_decel_mps2``
                (stays open down to ``comfortable_decel_mps2 - hysteresis_mps2``), critical from
                ``critical_decel_mps2``; or, past the advance-warning point, when the speed is above the
                zone limit by ``speed_margin_mph`` and its trend over ``trend_window_s`` is above
                ``-not_slowing_decel_mps2`` (the driver has not lifted off).
            approach_length_m (float | Unset):  Default: 1500.0.
            devices (DeviceRules | Unset): Roadside devices driven by the alerts: a flashing beacon and a message sign.
            hard_braking (HardBrakingRule | Unset): Deceleration from the least-squares slope of the track's speed over
                ``window_s``.

                Starts at ``-dv/dt >= decel_g * g``, stays open down to ``(decel_g - hysteresis_g) * g``;
                critical from ``critical_decel_g * g`` (g = 9.80665 m/s^2).
            intrusion (IntrusionRule | Unset): A vehicle in the closed lane inside the buffer or activity area.

                Starts when the track's offset is in the closed lane's band (or its lane is the closed one)
                between the buffer's start and the activity area's end at ``speed >= min_speed_mps``; stays
                open while the offset is in the band widened by ``lateral_hysteresis_m``. Warning in the
                buffer, critical in the activity area.
            late_merge (LateMergeRule | Unset): Still in the closed lane within ``distance_m`` of the taper start (or in the
                taper).

                Starts when the track's lane is the closed one (or its offset is in the closed lane's band)
                at ``speed >= min_speed_mps``; stays open while the offset is within the band widened by
                ``lateral_hysteresis_m`` and ``speed >= min_speed_mps - speed_hysteresis_mps``. Warning
                before the taper, critical inside it.
            queue (QueueRule | Unset): Slow or stopped traffic: ``min_vehicles`` slow vehicles within ``span_m`` of station.

                A vehicle is slow below ``slow_speed_mps`` (below ``slow_speed_mps + speed_hysteresis_mps``
                while a queue is open). One site-level episode, reported at the queue's tail (its most
                upstream slow vehicle); critical when the tail is ``critical_backup_m`` or more upstream of
                the taper start.
            queue_approach (QueueApproachRule | Unset): Approaching the back of the lane's queue too fast: the deceleration
                needed to stop
                behind it.

                For a track upstream of its lane's queue (:mod:`wz_alert_service.queues`) and not slow
                itself, with the queue's back ``s_b``, the track at ``s`` and speed ``v``, the queue's mean
                speed ``u``: the room to stop ``D = s_b - s - stop_spacing_m`` and the deceleration needed
                to come down to ``u`` within it, ``a = (v^2 - u^2) / (2 D)``. Starts at ``a >=
                comfortable_decel_mps2`` (or ``D <= 0`` while still closing), stays open down to
                ``comfortable_decel_mps2 - hysteresis_mps2``; critical from ``critical_decel_mps2``. The
                lead time is ``D / (v - u)``: how long until the track reaches the back at its speed.
            short_ttc (ShortTtcRule | Unset): Time to collision with the nearest vehicle ahead in the same lane.

                ``TTC = gap / (v_follower - v_leader)``, ``gap = s_leader - s_follower - (L_f + L_l) / 2``.
                Bins after SSAM (whose default conflict threshold is 1.5 s): info at ``TTC <= max_ttc_s``,
                warning at ``<= warning_ttc_s``, critical at ``<= critical_ttc_s``. Stays open while
                ``TTC <= max_ttc_s + hysteresis_s``. The TTC decided on is the longest the two tracks'
                covariances still allow at ``certainty_sigmas``: the gap widened and the closing speed
                lowered by that many of their standard deviations.
            speeding (SpeedingRule | Unset): Speed over the posted limit at the vehicle's station, within the approach.

                Starts at ``excess >= margin_mph``, stays open while ``excess >= margin_mph -
                hysteresis_mph``; critical from ``critical_excess_mph``. Margins are in mph, like the posted
                limits they are added to.
    """

    aggressive_approach: AggressiveApproachRule | Unset = UNSET
    approach_length_m: float | Unset = 1500.0
    devices: DeviceRules | Unset = UNSET
    hard_braking: HardBrakingRule | Unset = UNSET
    intrusion: IntrusionRule | Unset = UNSET
    late_merge: LateMergeRule | Unset = UNSET
    queue: QueueRule | Unset = UNSET
    queue_approach: QueueApproachRule | Unset = UNSET
    short_ttc: ShortTtcRule | Unset = UNSET
    speeding: SpeedingRule | Unset = UNSET

    def to_dict(self) -> dict[str, Any]:
        from ..models.aggressive_approach_rule import AggressiveApproachRule  # noqa: PLC0415
        from ..models.device_rules import DeviceRules  # noqa: PLC0415
        from ..models.hard_braking_rule import HardBrakingRule  # noqa: PLC0415
        from ..models.intrusion_rule import IntrusionRule  # noqa: PLC0415
        from ..models.late_merge_rule import LateMergeRule  # noqa: PLC0415
        from ..models.queue_approach_rule import QueueApproachRule  # noqa: PLC0415
        from ..models.queue_rule import QueueRule  # noqa: PLC0415
        from ..models.short_ttc_rule import ShortTtcRule  # noqa: PLC0415
        from ..models.speeding_rule import SpeedingRule  # noqa: PLC0415

        aggressive_approach: dict[str, Any] | Unset = UNSET
        if not isinstance(self.aggressive_approach, Unset):
            aggressive_approach = self.aggressive_approach.to_dict()

        approach_length_m = self.approach_length_m

        devices: dict[str, Any] | Unset = UNSET
        if not isinstance(self.devices, Unset):
            devices = self.devices.to_dict()

        hard_braking: dict[str, Any] | Unset = UNSET
        if not isinstance(self.hard_braking, Unset):
            hard_braking = self.hard_braking.to_dict()

        intrusion: dict[str, Any] | Unset = UNSET
        if not isinstance(self.intrusion, Unset):
            intrusion = self.intrusion.to_dict()

        late_merge: dict[str, Any] | Unset = UNSET
        if not isinstance(self.late_merge, Unset):
            late_merge = self.late_merge.to_dict()

        queue: dict[str, Any] | Unset = UNSET
        if not isinstance(self.queue, Unset):
            queue = self.queue.to_dict()

        queue_approach: dict[str, Any] | Unset = UNSET
        if not isinstance(self.queue_approach, Unset):
            queue_approach = self.queue_approach.to_dict()

        short_ttc: dict[str, Any] | Unset = UNSET
        if not isinstance(self.short_ttc, Unset):
            short_ttc = self.short_ttc.to_dict()

        speeding: dict[str, Any] | Unset = UNSET
        if not isinstance(self.speeding, Unset):
            speeding = self.speeding.to_dict()

        field_dict: dict[str, Any] = {}

        field_dict.update({})
        if aggressive_approach is not UNSET:
            field_dict["aggressive_approach"] = aggressive_approach
        if approach_length_m is not UNSET:
            field_dict["approach_length_m"] = approach_length_m
        if devices is not UNSET:
            field_dict["devices"] = devices
        if hard_braking is not UNSET:
            field_dict["hard_braking"] = hard_braking
        if intrusion is not UNSET:
            field_dict["intrusion"] = intrusion
        if late_merge is not UNSET:
            field_dict["late_merge"] = late_merge
        if queue is not UNSET:
            field_dict["queue"] = queue
        if queue_approach is not UNSET:
            field_dict["queue_approach"] = queue_approach
        if short_ttc is not UNSET:
            field_dict["short_ttc"] = short_ttc
        if speeding is not UNSET:
            field_dict["speeding"] = speeding

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        from ..models.aggressive_approach_rule import AggressiveApproachRule  # noqa: PLC0415
        from ..models.device_rules import DeviceRules  # noqa: PLC0415
        from ..models.hard_braking_rule import HardBrakingRule  # noqa: PLC0415
        from ..models.intrusion_rule import IntrusionRule  # noqa: PLC0415
        from ..models.late_merge_rule import LateMergeRule  # noqa: PLC0415
        from ..models.queue_approach_rule import QueueApproachRule  # noqa: PLC0415
        from ..models.queue_rule import QueueRule  # noqa: PLC0415
        from ..models.short_ttc_rule import ShortTtcRule  # noqa: PLC0415
        from ..models.speeding_rule import SpeedingRule  # noqa: PLC0415

        d = dict(src_dict)
        _aggressive_approach = d.pop("aggressive_approach", UNSET)
        aggressive_approach: AggressiveApproachRule | Unset
        if isinstance(_aggressive_approach, Unset):
            aggressive_approach = UNSET
        else:
            aggressive_approach = AggressiveApproachRule.from_dict(_aggressive_approach)

        approach_length_m = d.pop("approach_length_m", UNSET)

        _devices = d.pop("devices", UNSET)
        devices: DeviceRules | Unset
        if isinstance(_devices, Unset):
            devices = UNSET
        else:
            devices = DeviceRules.from_dict(_devices)

        _hard_braking = d.pop("hard_braking", UNSET)
        hard_braking: HardBrakingRule | Unset
        if isinstance(_hard_braking, Unset):
            hard_braking = UNSET
        else:
            hard_braking = HardBrakingRule.from_dict(_hard_braking)

        _intrusion = d.pop("intrusion", UNSET)
        intrusion: IntrusionRule | Unset
        if isinstance(_intrusion, Unset):
            intrusion = UNSET
        else:
            intrusion = IntrusionRule.from_dict(_intrusion)

        _late_merge = d.pop("late_merge", UNSET)
        late_merge: LateMergeRule | Unset
        if isinstance(_late_merge, Unset):
            late_merge = UNSET
        else:
            late_merge = LateMergeRule.from_dict(_late_merge)

        _queue = d.pop("queue", UNSET)
        queue: QueueRule | Unset
        if isinstance(_queue, Unset):
            queue = UNSET
        else:
            queue = QueueRule.from_dict(_queue)

        _queue_approach = d.pop("queue_approach", UNSET)
        queue_approach: QueueApproachRule | Unset
        if isinstance(_queue_approach, Unset):
            queue_approach = UNSET
        else:
            queue_approach = QueueApproachRule.from_dict(_queue_approach)

        _short_ttc = d.pop("short_ttc", UNSET)
        short_ttc: ShortTtcRule | Unset
        if isinstance(_short_ttc, Unset):
            short_ttc = UNSET
        else:
            short_ttc = ShortTtcRule.from_dict(_short_ttc)

        _speeding = d.pop("speeding", UNSET)
        speeding: SpeedingRule | Unset
        if isinstance(_speeding, Unset):
            speeding = UNSET
        else:
            speeding = SpeedingRule.from_dict(_speeding)

        alert_rules = cls(
            aggressive_approach=aggressive_approach,
            approach_length_m=approach_length_m,
            devices=devices,
            hard_braking=hard_braking,
            intrusion=intrusion,
            late_merge=late_merge,
            queue=queue,
            queue_approach=queue_approach,
            short_ttc=short_ttc,
            speeding=speeding,
        )

        return alert_rules
