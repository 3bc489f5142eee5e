from enum import StrEnum


class VehicleClass(StrEnum):
    BUS = "bus"
    CAR = "car"
    MOTORCYCLE = "motorcycle"
    TRUCK = "truck"
    UNKNOWN = "unknown"

    def __str__(self) -> str:
        return str(self.value)
