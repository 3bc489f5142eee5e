from enum import StrEnum


class CreatedApiKeyOrigin(StrEnum):
    API = "api"
    DEV = "dev"
    SETTINGS = "settings"

    def __str__(self) -> str:
        return str(self.value)
