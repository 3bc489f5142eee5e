from enum import StrEnum


class GetQueueHistoryV1QueueHistoryGetOrder(StrEnum):
    NEWEST = "newest"
    OLDEST = "oldest"

    def __str__(self) -> str:
        return str(self.value)
