from enum import StrEnum


class GetConflictsV1ConflictsGetFormat(StrEnum):
    CSV = "csv"
    JSON = "json"

    def __str__(self) -> str:
        return str(self.value)
