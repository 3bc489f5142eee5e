from enum import StrEnum


class GetAlertsV1AlertsGetPhaseType0Item(StrEnum):
    CLEAR = "clear"
    START = "start"
    UPDATE = "update"

    def __str__(self) -> str:
        return str(self.value)
