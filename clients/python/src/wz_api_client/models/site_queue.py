from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from typing import cast

if TYPE_CHECKING:
    from ..models.queue_state import QueueState


T = TypeVar("T", bound="SiteQueue")


@_attrs_define
class SiteQueue:
    """A site's queue now: the newest per-lane state its alert service published (once a
    second of track stamps), when it arrived, and whether that is longer ago than
    ``stale_after_s`` (the alert service or the tracks stopped: the state may be old).

        Attributes:
            age_s (float | None):
            queue (None | QueueState):
            received_at (float | None):
            site (str):
            stale (bool):
    """

    age_s: float | None
    queue: None | QueueState
    received_at: float | None
    site: str
    stale: bool

    def to_dict(self) -> dict[str, Any]:
        from ..models.queue_state import QueueState  # noqa: PLC0415

        age_s: float | None
        age_s = self.age_s

        queue: dict[str, Any] | None
        if isinstance(self.queue, QueueState):
            queue = self.queue.to_dict()
        else:
            queue = self.queue

        received_at: float | None
        received_at = self.received_at

        site = self.site

        stale = self.stale

        field_dict: dict[str, Any] = {}

        field_dict.update(
            {
                "age_s": age_s,
                "queue": queue,
                "received_at": received_at,
                "site": site,
                "stale": stale,
            }
        )

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        from ..models.queue_state import QueueState  # noqa: PLC0415

        d = dict(src_dict)

        def _parse_age_s(data: object) -> float | None:
            if data is None:
                return data
            return cast(float | None, data)

        age_s = _parse_age_s(d.pop("age_s"))

        def _parse_queue(data: object) -> None | QueueState:
            if data is None:
                return data
            try:
                if not isinstance(data, dict):
                    raise TypeError()
                queue_type_0 = QueueState.from_dict(data)

                return queue_type_0
            except (TypeError, ValueError, AttributeError, KeyError):
                pass
            return cast(None | QueueState, data)

        queue = _parse_queue(d.pop("queue"))

        def _parse_received_at(data: object) -> float | None:
            if data is None:
                return data
            return cast(float | None, data)

        received_at = _parse_received_at(d.pop("received_at"))

        site = d.pop("site")

        stale = d.pop("stale")

        site_queue = cls(
            age_s=age_s,
            queue=queue,
            received_at=received_at,
            site=site,
            stale=stale,
        )

        return site_queue
