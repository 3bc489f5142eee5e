from enum import StrEnum


class QueueCondition(StrEnum):
    FREE = "free"
    SLOW = "slow"
    STOPPED = "stopped"

    def __str__(self) -> str:
        return str(self.value)
