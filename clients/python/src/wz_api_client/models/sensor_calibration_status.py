from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..models.sensor_calibration_status_sensor_kind import (
    SensorCalibrationStatusSensorKind,
)
from typing import cast

if TYPE_CHECKING:
    from ..models.calibration_state_change import CalibrationStateChange
    from ..models.sensor_calibration import SensorCalibration


T = TypeVar("T", bound="SensorCalibrationStatus")


@_attrs_define
class SensorCalibrationStatus:
    """One sensor's self-calibration: its newest message as its detector published it, when
    it arrived, and its latest changes of state, newest first.

        Attributes:
            age_s (float | None):
            calibration (None | SensorCalibration):
            changes (list[CalibrationStateChange]):
            received_at (float | None):
            sensor_id (str):
            sensor_kind (SensorCalibrationStatusSensorKind):
            stale (bool):
    """

    age_s: float | None
    calibration: None | SensorCalibration
    changes: list[CalibrationStateChange]
    received_at: float | None
    sensor_id: str
    sensor_kind: SensorCalibrationStatusSensorKind
    stale: bool

    def to_dict(self) -> dict[str, Any]:
        from ..models.calibration_state_change import CalibrationStateChange  # noqa: PLC0415
        from ..models.sensor_calibration import SensorCalibration  # noqa: PLC0415

        age_s: float | None
        age_s = self.age_s

        calibration: dict[str, Any] | None
        if isinstance(self.calibration, SensorCalibration):
            calibration = self.calibration.to_dict()
        else:
            calibration = self.calibration

        changes = []
        for changes_item_data in self.changes:
            changes_item = changes_item_data.to_dict()
            changes.append(changes_item)

        received_at: float | None
        received_at = self.received_at

        sensor_id = self.sensor_id

        sensor_kind = self.sensor_kind.value

        stale = self.stale

        field_dict: dict[str, Any] = {}

        field_dict.update(
            {
                "age_s": age_s,
                "calibration": calibration,
                "changes": changes,
                "received_at": received_at,
                "sensor_id": sensor_id,
                "sensor_kind": sensor_kind,
                "stale": stale,
            }
        )

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        from ..models.calibration_state_change import CalibrationStateChange  # noqa: PLC0415
        from ..models.sensor_calibration import SensorCalibration  # noqa: PLC0415

        d = dict(src_dict)

        def _parse_age_s(data: object) -> float | None:
            if data is None:
                return data
            return cast(float | None, data)

        age_s = _parse_age_s(d.pop("age_s"))

        def _parse_calibration(data: object) -> None | SensorCalibration:
            if data is None:
                return data
            try:
                if not isinstance(data, dict):
                    raise TypeError()
                calibration_type_0 = SensorCalibration.from_dict(data)

                return calibration_type_0
            except (TypeError, ValueError, AttributeError, KeyError):
                pass
            return cast(None | SensorCalibration, data)

        calibration = _parse_calibration(d.pop("calibration"))

        changes = []
        _changes = d.pop("changes")
        for changes_item_data in _changes:
            changes_item = CalibrationStateChange.from_dict(changes_item_data)

            changes.append(changes_item)

        def _parse_received_at(data: object) -> float | None:
            if data is None:
                return data
            return cast(float | None, data)

        received_at = _parse_received_at(d.pop("received_at"))

        sensor_id = d.pop("sensor_id")

        sensor_kind = SensorCalibrationStatusSensorKind(d.pop("sensor_kind"))

        stale = d.pop("stale")

        sensor_calibration_status = cls(
            age_s=age_s,
            calibration=calibration,
            changes=changes,
            received_at=received_at,
            sensor_id=sensor_id,
            sensor_kind=sensor_kind,
            stale=stale,
        )

        return sensor_calibration_status
