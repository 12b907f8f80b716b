"""Camera models: intrinsics, Brown–Conrady lens distortion, point (un)distortion, calibration."""

from .calibrate import CalibrationResult, calibrate, parse_board
from .model import CameraModel

__all__ = ["CalibrationResult", "CameraModel", "calibrate", "parse_board"]
