from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..models.calibration_state import CalibrationState
from ..models.sensor_calibration_sensor_kind import SensorCalibrationSensorKind
from ..types import UNSET, Unset
from typing import cast
from typing import Literal, cast

if TYPE_CHECKING:
    from ..models.pose_correction import PoseCorrection


T = TypeVar("T", bound="SensorCalibration")


@_attrs_define
class SensorCalibration:
    """One sensor's self-calibration: its pose correction, its clock offset, its state.

    Published by the service that makes the sensor's measurements (``source_id`` is the
    sensor), on a change of state and every few seconds; ``stamp`` is the sensor time of the
    newest evidence. The detector applies it where it measures: the published detections are
    already in the corrected pose and on the corrected clock (``stamp - clock_offset_s``).

        Attributes:
            sensor_kind (SensorCalibrationSensorKind):
            site (str):
            source_id (str):
            stamp (float):
            state (CalibrationState): Where a sensor's self-calibration stands.
            state_since_s (float):
            clock_offset_s (float | Unset):  Default: 0.0.
            clock_offset_std_s (float | None | Unset):
            correction (PoseCorrection | Unset): What is added to the site file's pose: angles [deg] and a shift in the site
                frame [m].

                A ``*_std`` of None means the data did not constrain that part (it stays the site file's):
                a straight road tells nothing of a sensor's position along it.
            detail (str | Unset):  Default: ''.
            kind (Literal['sensor_calibration'] | Unset):  Default: 'sensor_calibration'.
            samples (int | Unset):  Default: 0.
            schema_version (Literal[1] | Unset):  Default: 1.
    """

    sensor_kind: SensorCalibrationSensorKind
    site: str
    source_id: str
    stamp: float
    state: CalibrationState
    state_since_s: float
    clock_offset_s: float | Unset = 0.0
    clock_offset_std_s: float | None | Unset = UNSET
    correction: PoseCorrection | Unset = UNSET
    detail: str | Unset = ""
    kind: Literal["sensor_calibration"] | Unset = "sensor_calibration"
    samples: int | Unset = 0
    schema_version: Literal[1] | Unset = 1

    def to_dict(self) -> dict[str, Any]:
        from ..models.pose_correction import PoseCorrection  # noqa: PLC0415

        sensor_kind = self.sensor_kind.value

        site = self.site

        source_id = self.source_id

        stamp = self.stamp

        state = self.state.value

        state_since_s = self.state_since_s

        clock_offset_s = self.clock_offset_s

        clock_offset_std_s: float | None | Unset
        if isinstance(self.clock_offset_std_s, Unset):
            clock_offset_std_s = UNSET
        else:
            clock_offset_std_s = self.clock_offset_std_s

        correction: dict[str, Any] | Unset = UNSET
        if not isinstance(self.correction, Unset):
            correction = self.correction.to_dict()

        detail = self.detail

        kind = self.kind

        samples = self.samples

        schema_version = self.schema_version

        field_dict: dict[str, Any] = {}

        field_dict.update(
            {
                "sensor_kind": sensor_kind,
                "site": site,
                "source_id": source_id,
                "stamp": stamp,
                "state": state,
                "state_since_s": state_since_s,
            }
        )
        if clock_offset_s is not UNSET:
            field_dict["clock_offset_s"] = clock_offset_s
        if clock_offset_std_s is not UNSET:
            field_dict["clock_offset_std_s"] = clock_offset_std_s
        if correction is not UNSET:
            field_dict["correction"] = correction
        if detail is not UNSET:
            field_dict["detail"] = detail
        if kind is not UNSET:
            field_dict["kind"] = kind
        if samples is not UNSET:
            field_dict["samples"] = samples
        if schema_version is not UNSET:
            field_dict["schema_version"] = schema_version

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        from ..models.pose_correction import PoseCorrection  # noqa: PLC0415

        d = dict(src_dict)
        sensor_kind = SensorCalibrationSensorKind(d.pop("sensor_kind"))

        site = d.pop("site")

        source_id = d.pop("source_id")

        stamp = d.pop("stamp")

        state = CalibrationState(d.pop("state"))

        state_since_s = d.pop("state_since_s")

        clock_offset_s = d.pop("clock_offset_s", UNSET)

        def _parse_clock_offset_std_s(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        clock_offset_std_s = _parse_clock_offset_std_s(
            d.pop("clock_offset_std_s", UNSET)
        )

        _correction = d.pop("correction", UNSET)
        correction: PoseCorrection | Unset
        if isinstance(_correction, Unset):
            correction = UNSET
        else:
            correction = PoseCorrection.from_dict(_correction)

        detail = d.pop("detail", UNSET)

        kind = cast(Literal["sensor_calibration"] | Unset, d.pop("kind", UNSET))
        if kind != "sensor_calibration" and not isinstance(kind, Unset):
            raise ValueError(
                f"kind must match const 'sensor_calibration', got '{kind}'"
            )

        samples = d.pop("samples", UNSET)

        schema_version = cast(Literal[1] | Unset, d.pop("schema_version", UNSET))
        if schema_version != 1 and not isinstance(schema_version, Unset):
            raise ValueError(
                f"schema_version must match const 1, got '{schema_version}'"
            )

        sensor_calibration = cls(
            sensor_kind=sensor_kind,
            site=site,
            source_id=source_id,
            stamp=stamp,
            state=state,
            state_since_s=state_since_s,
            clock_offset_s=clock_offset_s,
            clock_offset_std_s=clock_offset_std_s,
            correction=correction,
            detail=detail,
            kind=kind,
            samples=samples,
            schema_version=schema_version,
        )

        return sensor_calibration
