from enum import StrEnum


class GetStreamV1StreamGetEventType0Item(StrEnum):
    ALERT = "alert"
    TRACKS = "tracks"

    def __str__(self) -> str:
        return str(self.value)
