from enum import StrEnum


class ConflictConflictType(StrEnum):
    CROSSING = "crossing"
    LANE_CHANGE = "lane change"
    REAR_END = "rear end"

    def __str__(self) -> str:
        return str(self.value)
