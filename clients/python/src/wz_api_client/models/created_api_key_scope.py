from enum import StrEnum


class CreatedApiKeyScope(StrEnum):
    ADMIN = "admin"
    READ = "read"

    def __str__(self) -> str:
        return str(self.value)
