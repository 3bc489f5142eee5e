from enum import StrEnum


class GetAlertsV1AlertsGetOrder(StrEnum):
    NEWEST = "newest"
    OLDEST = "oldest"

    def __str__(self) -> str:
        return str(self.value)
