"""Camera-radar detector service: YOLOv8 image detections (ONNX Runtime) fused with radar."""
