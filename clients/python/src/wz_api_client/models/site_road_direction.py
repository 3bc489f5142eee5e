from enum import StrEnum


class SiteRoadDirection(StrEnum):
    EASTBOUND = "eastbound"
    INNER_LOOP = "inner-loop"
    NORTHBOUND = "northbound"
    OUTER_LOOP = "outer-loop"
    SOUTHBOUND = "southbound"
    UNDEFINED = "undefined"
    UNKNOWN = "unknown"
    WESTBOUND = "westbound"

    def __str__(self) -> str:
        return str(self.value)
