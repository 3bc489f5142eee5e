from enum import StrEnum


class GetStreamV1StreamGetEventType0Item(StrEnum):
    ALERT = "alert"
    CALIBRATION = "calibration"
    TRACKS = "tracks"

    def __str__(self) -> str:
        return str(self.value)
