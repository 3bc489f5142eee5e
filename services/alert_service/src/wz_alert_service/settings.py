"""Settings of the alert service (env prefix ``WZ_ALERT_``), units in the names.

The rules' thresholds are not here: they are the ``alerts:`` section of the site file
(:class:`wz_shared.site.AlertRules`), the same for every process of a site.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Annotated

from pydantic import Field, field_validator
from pydantic_settings import SettingsConfigDict

from wz_shared.settings import ServiceSettings

_PREFIX = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.:-]{0,63}$")


class AlertServiceSettings(ServiceSettings):
    """The node's settings (``WZ_ALERT_*``); the rules' thresholds live in the site file."""

    model_config = SettingsConfigDict(env_prefix="WZ_ALERT_", extra="ignore")

    #: Put before every episode id so ids stay unique across restarts; None: the service's
    #: start time, UTC, ``YYYYmmddTHHMMSS``.
    episode_id_prefix: str | None = None
    #: Track batches queued for the engine; beyond it the tracker's publisher waits.
    queue_capacity: Annotated[int, Field(ge=1, le=1_000_000)] = 1024
    #: Alerts of each type kept in memory for subscribers that missed them (store and forward:
    #: a central gateway whose link to the trailer was down fetches them when it comes back).
    #: About 2 kB each; 2000 of each type is hours of alerts at a busy site.
    history_per_type: Annotated[int, Field(ge=1, le=100_000)] = 2000
    #: Where the open episodes are kept across restarts (:mod:`wz_alert_service.recovery`);
    #: None: a restart forgets them (the development stack without a state folder).
    state_file: Path | None = None
    #: Shed track batches that carry no news before decoding them (:mod:`wz_shared.shedding`):
    #: not newer than the last one let in (``stale``: a replay, a duplicate), or newer by less
    #: than ``min_batch_interval_s`` (``superseded``). So a flood of batches, from a faulty or
    #: hostile source, never puts the engine behind: a speeding car inside it is alerted on
    #: within its normal latency. False: every batch queued (the benchmark's comparison).
    shed_stale_batches: bool = True
    #: Least stamp step between two batches the engine takes [s]: a tracker cycles at 10-20 Hz
    #: (50-100 ms); 5 ms lets every real tracker's batch by and at most 200 batches/s of a
    #: flood; the rules hold for a second or more.
    min_batch_interval_s: Annotated[float, Field(ge=0.0, le=0.05)] = 0.005

    @field_validator("episode_id_prefix")
    @classmethod
    def _prefix(cls, value: str | None) -> str | None:
        if value is not None and not _PREFIX.match(value):
            raise ValueError(
                f"{value!r}: use letters, digits and '_', '.', ':', '-' (64 characters at most, "
                "starting with a letter or digit)"
            )
        return value
