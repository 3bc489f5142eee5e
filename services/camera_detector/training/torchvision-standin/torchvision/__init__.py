"""Stand-in for torchvision: only what ultralytics needs to train and export a YOLO detector.

See ``services/camera_detector/training/README.md``. Anything else raises AttributeError.
"""

from torchvision import ops

__version__ = "0.28.0+wz.nms"
__all__ = ["ops"]
