from enum import StrEnum


class NewWebhookPhasesType0Item(StrEnum):
    CLEAR = "clear"
    START = "start"
    UPDATE = "update"

    def __str__(self) -> str:
        return str(self.value)
