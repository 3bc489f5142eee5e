from enum import StrEnum


class SensorCalibrationSensorKind(StrEnum):
    CAMERA = "camera"
    LIDAR = "lidar"
    RADAR = "radar"

    def __str__(self) -> str:
        return str(self.value)
