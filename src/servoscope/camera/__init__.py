"""Camera models: intrinsics, Brown–Conrady lens distortion, point (un)distortion, calibration; a rolling shutter's row timing;
the blade's plane (a chessboard held against it: the homography to the plane and the rectified frame)."""

from .calibrate import CalibrationResult, calibrate, parse_board
from .model import CameraModel
from .plane import Plane, PlaneView, calibrate_plane, fit_plane
from .rolling_shutter import angle_sample_times
from .undistort import distortion_centroid_offset, undistort_centroids

__all__ = ["CalibrationResult", "CameraModel", "Plane", "PlaneView", "angle_sample_times", "calibrate", "calibrate_plane",
           "distortion_centroid_offset", "fit_plane", "parse_board", "undistort_centroids"]
