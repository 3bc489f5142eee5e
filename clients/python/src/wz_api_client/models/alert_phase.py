from enum import StrEnum


class AlertPhase(StrEnum):
    CLEAR = "clear"
    START = "start"
    UPDATE = "update"

    def __str__(self) -> str:
        return str(self.value)
