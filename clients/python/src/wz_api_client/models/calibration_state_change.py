from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..models.calibration_state import CalibrationState
from typing import cast


T = TypeVar("T", bound="CalibrationStateChange")


@_attrs_define
class CalibrationStateChange:
    """A sensor's self-calibration entering a state, as the gateway stored it.

    Attributes:
        detail (str):
        previous_state (CalibrationState | None):
        received_at (float):
        stamp (float):
        state (CalibrationState): Where a sensor's self-calibration stands.
        state_since_s (float):
    """

    detail: str
    previous_state: CalibrationState | None
    received_at: float
    stamp: float
    state: CalibrationState
    state_since_s: float

    def to_dict(self) -> dict[str, Any]:
        detail = self.detail

        previous_state: None | str
        if isinstance(self.previous_state, CalibrationState):
            previous_state = self.previous_state.value
        else:
            previous_state = self.previous_state

        received_at = self.received_at

        stamp = self.stamp

        state = self.state.value

        state_since_s = self.state_since_s

        field_dict: dict[str, Any] = {}

        field_dict.update(
            {
                "detail": detail,
                "previous_state": previous_state,
                "received_at": received_at,
                "stamp": stamp,
                "state": state,
                "state_since_s": state_since_s,
            }
        )

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        detail = d.pop("detail")

        def _parse_previous_state(data: object) -> CalibrationState | None:
            if data is None:
                return data
            try:
                if not isinstance(data, str):
                    raise TypeError()
                previous_state_type_0 = CalibrationState(data)

                return previous_state_type_0
            except (TypeError, ValueError, AttributeError, KeyError):
                pass
            return cast(CalibrationState | None, data)

        previous_state = _parse_previous_state(d.pop("previous_state"))

        received_at = d.pop("received_at")

        stamp = d.pop("stamp")

        state = CalibrationState(d.pop("state"))

        state_since_s = d.pop("state_since_s")

        calibration_state_change = cls(
            detail=detail,
            previous_state=previous_state,
            received_at=received_at,
            stamp=stamp,
            state=state,
            state_since_s=state_since_s,
        )

        return calibration_state_change
