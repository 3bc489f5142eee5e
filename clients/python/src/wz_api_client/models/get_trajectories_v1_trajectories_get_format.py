from enum import StrEnum


class GetTrajectoriesV1TrajectoriesGetFormat(StrEnum):
    CSV = "csv"
    GEOJSON = "geojson"
    JSON = "json"
    PARQUET = "parquet"

    def __str__(self) -> str:
        return str(self.value)
