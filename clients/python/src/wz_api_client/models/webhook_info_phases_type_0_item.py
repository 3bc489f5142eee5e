from enum import StrEnum


class WebhookInfoPhasesType0Item(StrEnum):
    CLEAR = "clear"
    START = "start"
    UPDATE = "update"

    def __str__(self) -> str:
        return str(self.value)
