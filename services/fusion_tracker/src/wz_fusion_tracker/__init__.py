"""Fusion tracker: Kalman late fusion of asynchronous sensors (pure core) and its node."""
