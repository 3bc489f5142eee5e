from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..types import UNSET, Unset
from typing import cast
from typing import Literal, cast

if TYPE_CHECKING:
    from ..models.lane_queue import LaneQueue


T = TypeVar("T", bound="QueueState")


@_attrs_define
class QueueState:
    """Every lane's queue at one instant, from the alert service's tracks: on
    ``wz/<site>/queue`` once a second of track stamps, and at once when a lane's condition
    changes. ``stamp`` is the track batch's capture time.

        Attributes:
            lanes (list[LaneQueue]):
            site (str):
            source_id (str):
            stamp (float):
            kind (Literal['queue_state'] | Unset):  Default: 'queue_state'.
            schema_version (Literal[1] | Unset):  Default: 1.
    """

    lanes: list[LaneQueue]
    site: str
    source_id: str
    stamp: float
    kind: Literal["queue_state"] | Unset = "queue_state"
    schema_version: Literal[1] | Unset = 1

    def to_dict(self) -> dict[str, Any]:
        from ..models.lane_queue import LaneQueue  # noqa: PLC0415

        lanes = []
        for lanes_item_data in self.lanes:
            lanes_item = lanes_item_data.to_dict()
            lanes.append(lanes_item)

        site = self.site

        source_id = self.source_id

        stamp = self.stamp

        kind = self.kind

        schema_version = self.schema_version

        field_dict: dict[str, Any] = {}

        field_dict.update(
            {
                "lanes": lanes,
                "site": site,
                "source_id": source_id,
                "stamp": stamp,
            }
        )
        if kind is not UNSET:
            field_dict["kind"] = kind
        if schema_version is not UNSET:
            field_dict["schema_version"] = schema_version

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        from ..models.lane_queue import LaneQueue  # noqa: PLC0415

        d = dict(src_dict)
        lanes = []
        _lanes = d.pop("lanes")
        for lanes_item_data in _lanes:
            lanes_item = LaneQueue.from_dict(lanes_item_data)

            lanes.append(lanes_item)

        site = d.pop("site")

        source_id = d.pop("source_id")

        stamp = d.pop("stamp")

        kind = cast(Literal["queue_state"] | Unset, d.pop("kind", UNSET))
        if kind != "queue_state" and not isinstance(kind, Unset):
            raise ValueError(f"kind must match const 'queue_state', got '{kind}'")

        schema_version = cast(Literal[1] | Unset, d.pop("schema_version", UNSET))
        if schema_version != 1 and not isinstance(schema_version, Unset):
            raise ValueError(
                f"schema_version must match const 1, got '{schema_version}'"
            )

        queue_state = cls(
            lanes=lanes,
            site=site,
            source_id=source_id,
            stamp=stamp,
            kind=kind,
            schema_version=schema_version,
        )

        return queue_state
