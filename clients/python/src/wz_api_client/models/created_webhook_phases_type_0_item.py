from enum import StrEnum


class CreatedWebhookPhasesType0Item(StrEnum):
    CLEAR = "clear"
    START = "start"
    UPDATE = "update"

    def __str__(self) -> str:
        return str(self.value)
