from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..models.conflict_conflict_type import ConflictConflictType
from typing import cast


T = TypeVar("T", bound="Conflict")


@_attrs_define
class Conflict:
    """One conflict between two vehicles (module docstring): SSAM's measures, units in names.

    Attributes:
        clock_angle (str):
        conflict_angle_deg (float):
        conflict_type (ConflictConflictType):
        delta_speed_mps (float):
        dr_mps2 (float):
        drac_mps2 (float | None):
        end_stamp (float):
        first_delta_v_mps (float):
        first_end_x_m (float):
        first_end_y_m (float):
        first_heading_deg (float):
        first_id (str):
        first_lane (int):
        first_length_m (float):
        first_speed_mps (float):
        first_start_x_m (float):
        first_start_y_m (float):
        first_width_m (float):
        max_d_mps2 (float):
        max_delta_v_mps (float):
        max_speed_mps (float):
        min_pet_stamp (float | None):
        min_pet_x_m (float):
        min_pet_y_m (float):
        min_ttc_stamp (float):
        pet_s (float | None):
        post_crash_heading_deg (float):
        post_crash_speed_mps (float):
        second_delta_v_mps (float):
        second_end_x_m (float):
        second_end_y_m (float):
        second_heading_deg (float):
        second_id (str):
        second_lane (int):
        second_length_m (float):
        second_speed_mps (float):
        second_start_x_m (float):
        second_start_y_m (float):
        second_width_m (float):
        start_stamp (float):
        ttc_s (float):
    """

    clock_angle: str
    conflict_angle_deg: float
    conflict_type: ConflictConflictType
    delta_speed_mps: float
    dr_mps2: float
    drac_mps2: float | None
    end_stamp: float
    first_delta_v_mps: float
    first_end_x_m: float
    first_end_y_m: float
    first_heading_deg: float
    first_id: str
    first_lane: int
    first_length_m: float
    first_speed_mps: float
    first_start_x_m: float
    first_start_y_m: float
    first_width_m: float
    max_d_mps2: float
    max_delta_v_mps: float
    max_speed_mps: float
    min_pet_stamp: float | None
    min_pet_x_m: float
    min_pet_y_m: float
    min_ttc_stamp: float
    pet_s: float | None
    post_crash_heading_deg: float
    post_crash_speed_mps: float
    second_delta_v_mps: float
    second_end_x_m: float
    second_end_y_m: float
    second_heading_deg: float
    second_id: str
    second_lane: int
    second_length_m: float
    second_speed_mps: float
    second_start_x_m: float
    second_start_y_m: float
    second_width_m: float
    start_stamp: float
    ttc_s: float

    def to_dict(self) -> dict[str, Any]:
        clock_angle = self.clock_angle

        conflict_angle_deg = self.conflict_angle_deg

        conflict_type = self.conflict_type.value

        delta_speed_mps = self.delta_speed_mps

        dr_mps2 = self.dr_mps2

        drac_mps2: float | None
        drac_mps2 = self.drac_mps2

        end_stamp = self.end_stamp

        first_delta_v_mps = self.first_delta_v_mps

        first_end_x_m = self.first_end_x_m

        first_end_y_m = self.first_end_y_m

        first_heading_deg = self.first_heading_deg

        first_id = self.first_id

        first_lane = self.first_lane

        first_length_m = self.first_length_m

        first_speed_mps = self.first_speed_mps

        first_start_x_m = self.first_start_x_m

        first_start_y_m = self.first_start_y_m

        first_width_m = self.first_width_m

        max_d_mps2 = self.max_d_mps2

        max_delta_v_mps = self.max_delta_v_mps

        max_speed_mps = self.max_speed_mps

        min_pet_stamp: float | None
        min_pet_stamp = self.min_pet_stamp

        min_pet_x_m = self.min_pet_x_m

        min_pet_y_m = self.min_pet_y_m

        min_ttc_stamp = self.min_ttc_stamp

        pet_s: float | None
        pet_s = self.pet_s

        post_crash_heading_deg = self.post_crash_heading_deg

        post_crash_speed_mps = self.post_crash_speed_mps

        second_delta_v_mps = self.second_delta_v_mps

        second_end_x_m = self.second_end_x_m

        second_end_y_m = self.second_end_y_m

        second_heading_deg = self.second_heading_deg

        second_id = self.second_id

        second_lane = self.second_lane

        second_length_m = self.second_length_m

        second_speed_mps = self.second_speed_mps

        second_start_x_m = self.second_start_x_m

        second_start_y_m = self.second_start_y_m

        second_width_m = self.second_width_m

        start_stamp = self.start_stamp

        ttc_s = self.ttc_s

        field_dict: dict[str, Any] = {}

        field_dict.update(
            {
                "clock_angle": clock_angle,
                "conflict_angle_deg": conflict_angle_deg,
                "conflict_type": conflict_type,
                "delta_speed_mps": delta_speed_mps,
                "dr_mps2": dr_mps2,
                "drac_mps2": drac_mps2,
                "end_stamp": end_stamp,
                "first_delta_v_mps": first_delta_v_mps,
                "first_end_x_m": first_end_x_m,
                "first_end_y_m": first_end_y_m,
                "first_heading_deg": first_heading_deg,
                "first_id": first_id,
                "first_lane": first_lane,
                "first_length_m": first_length_m,
                "first_speed_mps": first_speed_mps,
                "first_start_x_m": first_start_x_m,
                "first_start_y_m": first_start_y_m,
                "first_width_m": first_width_m,
                "max_d_mps2": max_d_mps2,
                "max_delta_v_mps": max_delta_v_mps,
                "max_speed_mps": max_speed_mps,
                "min_pet_stamp": min_pet_stamp,
                "min_pet_x_m": min_pet_x_m,
                "min_pet_y_m": min_pet_y_m,
                "min_ttc_stamp": min_ttc_stamp,
                "pet_s": pet_s,
                "post_crash_heading_deg": post_crash_heading_deg,
                "post_crash_speed_mps": post_crash_speed_mps,
                "second_delta_v_mps": second_delta_v_mps,
                "second_end_x_m": second_end_x_m,
                "second_end_y_m": second_end_y_m,
                "second_heading_deg": second_heading_deg,
                "second_id": second_id,
                "second_lane": second_lane,
                "second_length_m": second_length_m,
                "second_speed_mps": second_speed_mps,
                "second_start_x_m": second_start_x_m,
                "second_start_y_m": second_start_y_m,
                "second_width_m": second_width_m,
                "start_stamp": start_stamp,
                "ttc_s": ttc_s,
            }
        )

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        clock_angle = d.pop("clock_angle")

        conflict_angle_deg = d.pop("conflict_angle_deg")

        conflict_type = ConflictConflictType(d.pop("conflict_type"))

        delta_speed_mps = d.pop("delta_speed_mps")

        dr_mps2 = d.pop("dr_mps2")

        def _parse_drac_mps2(data: object) -> float | None:
            if data is None:
                return data
            return cast(float | None, data)

        drac_mps2 = _parse_drac_mps2(d.pop("drac_mps2"))

        end_stamp = d.pop("end_stamp")

        first_delta_v_mps = d.pop("first_delta_v_mps")

        first_end_x_m = d.pop("first_end_x_m")

        first_end_y_m = d.pop("first_end_y_m")

        first_heading_deg = d.pop("first_heading_deg")

        first_id = d.pop("first_id")

        first_lane = d.pop("first_lane")

        first_length_m = d.pop("first_length_m")

        first_speed_mps = d.pop("first_speed_mps")

        first_start_x_m = d.pop("first_start_x_m")

        first_start_y_m = d.pop("first_start_y_m")

        first_width_m = d.pop("first_width_m")

        max_d_mps2 = d.pop("max_d_mps2")

        max_delta_v_mps = d.pop("max_delta_v_mps")

        max_speed_mps = d.pop("max_speed_mps")

        def _parse_min_pet_stamp(data: object) -> float | None:
            if data is None:
                return data
            return cast(float | None, data)

        min_pet_stamp = _parse_min_pet_stamp(d.pop("min_pet_stamp"))

        min_pet_x_m = d.pop("min_pet_x_m")

        min_pet_y_m = d.pop("min_pet_y_m")

        min_ttc_stamp = d.pop("min_ttc_stamp")

        def _parse_pet_s(data: object) -> float | None:
            if data is None:
                return data
            return cast(float | None, data)

        pet_s = _parse_pet_s(d.pop("pet_s"))

        post_crash_heading_deg = d.pop("post_crash_heading_deg")

        post_crash_speed_mps = d.pop("post_crash_speed_mps")

        second_delta_v_mps = d.pop("second_delta_v_mps")

        second_end_x_m = d.pop("second_end_x_m")

        second_end_y_m = d.pop("second_end_y_m")

        second_heading_deg = d.pop("second_heading_deg")

        second_id = d.pop("second_id")

        second_lane = d.pop("second_lane")

        second_length_m = d.pop("second_length_m")

        second_speed_mps = d.pop("second_speed_mps")

        second_start_x_m = d.pop("second_start_x_m")

        second_start_y_m = d.pop("second_start_y_m")

        second_width_m = d.pop("second_width_m")

        start_stamp = d.pop("start_stamp")

        ttc_s = d.pop("ttc_s")

        conflict = cls(
            clock_angle=clock_angle,
            conflict_angle_deg=conflict_angle_deg,
            conflict_type=conflict_type,
            delta_speed_mps=delta_speed_mps,
            dr_mps2=dr_mps2,
            drac_mps2=drac_mps2,
            end_stamp=end_stamp,
            first_delta_v_mps=first_delta_v_mps,
            first_end_x_m=first_end_x_m,
            first_end_y_m=first_end_y_m,
            first_heading_deg=first_heading_deg,
            first_id=first_id,
            first_lane=first_lane,
            first_length_m=first_length_m,
            first_speed_mps=first_speed_mps,
            first_start_x_m=first_start_x_m,
            first_start_y_m=first_start_y_m,
            first_width_m=first_width_m,
            max_d_mps2=max_d_mps2,
            max_delta_v_mps=max_delta_v_mps,
            max_speed_mps=max_speed_mps,
            min_pet_stamp=min_pet_stamp,
            min_pet_x_m=min_pet_x_m,
            min_pet_y_m=min_pet_y_m,
            min_ttc_stamp=min_ttc_stamp,
            pet_s=pet_s,
            post_crash_heading_deg=post_crash_heading_deg,
            post_crash_speed_mps=post_crash_speed_mps,
            second_delta_v_mps=second_delta_v_mps,
            second_end_x_m=second_end_x_m,
            second_end_y_m=second_end_y_m,
            second_heading_deg=second_heading_deg,
            second_id=second_id,
            second_lane=second_lane,
            second_length_m=second_length_m,
            second_speed_mps=second_speed_mps,
            second_start_x_m=second_start_x_m,
            second_start_y_m=second_start_y_m,
            second_width_m=second_width_m,
            start_stamp=start_stamp,
            ttc_s=ttc_s,
        )

        return conflict
