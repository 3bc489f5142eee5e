from enum import StrEnum


class AreaKind(StrEnum):
    ACTIVITY = "activity"
    ADVANCE_WARNING = "advance_warning"
    BUFFER = "buffer"
    TERMINATION = "termination"
    TRANSITION = "transition"

    def __str__(self) -> str:
        return str(self.value)
