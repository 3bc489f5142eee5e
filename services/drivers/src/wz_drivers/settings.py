"""Settings of the drivers service (env prefix ``WZ_DRIVERS_``), units in the names.

The site is not here: it is the field log's (its manifest names the site file).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

from pydantic import Field
from pydantic_settings import SettingsConfigDict

from wz_shared.settings import ServiceSettings


class DriversSettings(ServiceSettings):
    """``WZ_DRIVERS_*``."""

    model_config = SettingsConfigDict(env_prefix="WZ_DRIVERS_", extra="ignore")

    #: The manifest (a field log's ``log.yaml``, or its folder) of the sources to read.
    sources: Path
    #: Recordings only: their pace (1 = as recorded; 0 = as fast as possible), and looping.
    rate: Annotated[float, Field(ge=0.0, le=100.0)] = 1.0
    loop: bool = False
    #: A live device that failed is opened again after this long [s].
    retry_s: Annotated[float, Field(gt=0.0, le=3600.0)] = 5.0
