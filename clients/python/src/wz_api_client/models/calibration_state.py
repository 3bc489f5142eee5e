from enum import StrEnum


class CalibrationState(StrEnum):
    BUMPED = "bumped"
    CALIBRATED = "calibrated"
    LEARNING = "learning"
    PRIOR = "prior"

    def __str__(self) -> str:
        return str(self.value)
