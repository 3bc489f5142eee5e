from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..models.alert_phase import AlertPhase
from ..models.alert_severity import AlertSeverity
from ..models.alert_type import AlertType
from ..types import UNSET, Unset
from typing import cast
from typing import Literal, cast

if TYPE_CHECKING:
    from ..models.alert_evidence import AlertEvidence
    from ..models.track import Track


T = TypeVar("T", bound="Alert")


@_attrs_define
class Alert:
    """One event of an alert episode: its start, an update (severity rose) or its clear.

    An episode is one stretch of time over which one rule's condition held for one track (or,
    for a queue, for the site: ``track_id`` None). Its messages share ``episode_id``; each has
    its own ``alert_id``. ``stamp`` is the capture time of the track batch that decided this
    event; ``onset_stamp`` the capture time at which the condition first held (a start comes
    the rule's hold time after it). Published reliably, never dropped.

    ``measured_value`` and ``threshold_value`` are in ``value_unit`` (m/s, m/s^2, s, m or
    vehicles); ``evidence`` holds the rule's other numbers, each key ending in its unit
    (``speed_limit_mps``, ``gap_m``...); ``track`` is a snapshot of the track at ``stamp``.
    A clear carries the episode's peak severity and its last measurements.

        Attributes:
            alert_id (str):
            alert_type (AlertType):
            description (str):
            measured_value (float):
            offset_m (float):
            severity (AlertSeverity):
            site (str):
            source_id (str):
            stamp (float):
            station_m (float):
            threshold_value (float):
            episode_id (None | str | Unset):
            evidence (AlertEvidence | Unset):
            kind (Literal['alert'] | Unset):  Default: 'alert'.
            onset_stamp (float | None | Unset):
            phase (AlertPhase | Unset):  Default: AlertPhase.START.
            schema_version (Literal[1] | Unset):  Default: 1.
            speed_mps (float | None | Unset):
            track (None | Track | Unset):
            track_id (int | None | Unset):
            value_unit (str | Unset):  Default: ''.
    """

    alert_id: str
    alert_type: AlertType
    description: str
    measured_value: float
    offset_m: float
    severity: AlertSeverity
    site: str
    source_id: str
    stamp: float
    station_m: float
    threshold_value: float
    episode_id: None | str | Unset = UNSET
    evidence: AlertEvidence | Unset = UNSET
    kind: Literal["alert"] | Unset = "alert"
    onset_stamp: float | None | Unset = UNSET
    phase: AlertPhase | Unset = AlertPhase.START
    schema_version: Literal[1] | Unset = 1
    speed_mps: float | None | Unset = UNSET
    track: None | Track | Unset = UNSET
    track_id: int | None | Unset = UNSET
    value_unit: str | Unset = ""

    def to_dict(self) -> dict[str, Any]:
        from ..models.alert_evidence import AlertEvidence  # noqa: PLC0415
        from ..models.track import Track  # noqa: PLC0415

        alert_id = self.alert_id

        alert_type = self.alert_type.value

        description = self.description

        measured_value = self.measured_value

        offset_m = self.offset_m

        severity = self.severity.value

        site = self.site

        source_id = self.source_id

        stamp = self.stamp

        station_m = self.station_m

        threshold_value = self.threshold_value

        episode_id: None | str | Unset
        if isinstance(self.episode_id, Unset):
            episode_id = UNSET
        else:
            episode_id = self.episode_id

        evidence: dict[str, Any] | Unset = UNSET
        if not isinstance(self.evidence, Unset):
            evidence = self.evidence.to_dict()

        kind = self.kind

        onset_stamp: float | None | Unset
        if isinstance(self.onset_stamp, Unset):
            onset_stamp = UNSET
        else:
            onset_stamp = self.onset_stamp

        phase: str | Unset = UNSET
        if not isinstance(self.phase, Unset):
            phase = self.phase.value

        schema_version = self.schema_version

        speed_mps: float | None | Unset
        if isinstance(self.speed_mps, Unset):
            speed_mps = UNSET
        else:
            speed_mps = self.speed_mps

        track: dict[str, Any] | None | Unset
        if isinstance(self.track, Unset):
            track = UNSET
        elif isinstance(self.track, Track):
            track = self.track.to_dict()
        else:
            track = self.track

        track_id: int | None | Unset
        if isinstance(self.track_id, Unset):
            track_id = UNSET
        else:
            track_id = self.track_id

        value_unit = self.value_unit

        field_dict: dict[str, Any] = {}

        field_dict.update(
            {
                "alert_id": alert_id,
                "alert_type": alert_type,
                "description": description,
                "measured_value": measured_value,
                "offset_m": offset_m,
                "severity": severity,
                "site": site,
                "source_id": source_id,
                "stamp": stamp,
                "station_m": station_m,
                "threshold_value": threshold_value,
            }
        )
        if episode_id is not UNSET:
            field_dict["episode_id"] = episode_id
        if evidence is not UNSET:
            field_dict["evidence"] = evidence
        if kind is not UNSET:
            field_dict["kind"] = kind
        if onset_stamp is not UNSET:
            field_dict["onset_stamp"] = onset_stamp
        if phase is not UNSET:
            field_dict["phase"] = phase
        if schema_version is not UNSET:
            field_dict["schema_version"] = schema_version
        if speed_mps is not UNSET:
            field_dict["speed_mps"] = speed_mps
        if track is not UNSET:
            field_dict["track"] = track
        if track_id is not UNSET:
            field_dict["track_id"] = track_id
        if value_unit is not UNSET:
            field_dict["value_unit"] = value_unit

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        from ..models.alert_evidence import AlertEvidence  # noqa: PLC0415
        from ..models.track import Track  # noqa: PLC0415

        d = dict(src_dict)
        alert_id = d.pop("alert_id")

        alert_type = AlertType(d.pop("alert_type"))

        description = d.pop("description")

        measured_value = d.pop("measured_value")

        offset_m = d.pop("offset_m")

        severity = AlertSeverity(d.pop("severity"))

        site = d.pop("site")

        source_id = d.pop("source_id")

        stamp = d.pop("stamp")

        station_m = d.pop("station_m")

        threshold_value = d.pop("threshold_value")

        def _parse_episode_id(data: object) -> None | str | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(None | str | Unset, data)

        episode_id = _parse_episode_id(d.pop("episode_id", UNSET))

        _evidence = d.pop("evidence", UNSET)
        evidence: AlertEvidence | Unset
        if isinstance(_evidence, Unset):
            evidence = UNSET
        else:
            evidence = AlertEvidence.from_dict(_evidence)

        kind = cast(Literal["alert"] | Unset, d.pop("kind", UNSET))
        if kind != "alert" and not isinstance(kind, Unset):
            raise ValueError(f"kind must match const 'alert', got '{kind}'")

        def _parse_onset_stamp(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        onset_stamp = _parse_onset_stamp(d.pop("onset_stamp", UNSET))

        _phase = d.pop("phase", UNSET)
        phase: AlertPhase | Unset
        if isinstance(_phase, Unset):
            phase = UNSET
        else:
            phase = AlertPhase(_phase)

        schema_version = cast(Literal[1] | Unset, d.pop("schema_version", UNSET))
        if schema_version != 1 and not isinstance(schema_version, Unset):
            raise ValueError(
                f"schema_version must match const 1, got '{schema_version}'"
            )

        def _parse_speed_mps(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        speed_mps = _parse_speed_mps(d.pop("speed_mps", UNSET))

        def _parse_track(data: object) -> None | Track | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            try:
                if not isinstance(data, dict):
                    raise TypeError()
                track_type_0 = Track.from_dict(data)

                return track_type_0
            except (TypeError, ValueError, AttributeError, KeyError):
                pass
            return cast(None | Track | Unset, data)

        track = _parse_track(d.pop("track", UNSET))

        def _parse_track_id(data: object) -> int | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(int | None | Unset, data)

        track_id = _parse_track_id(d.pop("track_id", UNSET))

        value_unit = d.pop("value_unit", UNSET)

        alert = cls(
            alert_id=alert_id,
            alert_type=alert_type,
            description=description,
            measured_value=measured_value,
            offset_m=offset_m,
            severity=severity,
            site=site,
            source_id=source_id,
            stamp=stamp,
            station_m=station_m,
            threshold_value=threshold_value,
            episode_id=episode_id,
            evidence=evidence,
            kind=kind,
            onset_stamp=onset_stamp,
            phase=phase,
            schema_version=schema_version,
            speed_mps=speed_mps,
            track=track,
            track_id=track_id,
            value_unit=value_unit,
        )

        return alert
