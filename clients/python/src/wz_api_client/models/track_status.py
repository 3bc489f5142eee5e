from enum import StrEnum


class TrackStatus(StrEnum):
    COASTING = "coasting"
    CONFIRMED = "confirmed"
    TENTATIVE = "tentative"

    def __str__(self) -> str:
        return str(self.value)
