"""Sensor models (pure cores): the scene, a spinning LiDAR, a pinhole camera, a radar."""
