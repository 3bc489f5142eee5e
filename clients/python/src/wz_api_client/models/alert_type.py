from enum import StrEnum


class AlertType(StrEnum):
    AGGRESSIVE_APPROACH = "aggressive_approach"
    HARD_BRAKING = "hard_braking"
    INTRUSION = "intrusion"
    LATE_MERGE = "late_merge"
    QUEUE = "queue"
    QUEUE_APPROACH = "queue_approach"
    SHORT_TTC = "short_ttc"
    SPEEDING = "speeding"

    def __str__(self) -> str:
        return str(self.value)
