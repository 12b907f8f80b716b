"""Camera models: intrinsics, Brown–Conrady lens distortion, point (un)distortion, calibration; a rolling shutter's row timing."""

from .calibrate import CalibrationResult, calibrate, parse_board
from .model import CameraModel
from .rolling_shutter import angle_sample_times
from .undistort import distortion_centroid_offset, undistort_centroids

__all__ = ["CalibrationResult", "CameraModel", "angle_sample_times", "calibrate", "distortion_centroid_offset",
           "parse_board", "undistort_centroids"]
