"""LiDAR detector service: the paper's reference pipeline and a background-model fast path."""
