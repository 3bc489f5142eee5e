from enum import StrEnum


class ApiKeyInfoScope(StrEnum):
    ADMIN = "admin"
    READ = "read"

    def __str__(self) -> str:
        return str(self.value)
