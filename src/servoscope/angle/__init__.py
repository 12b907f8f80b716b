"""Angle: the blade's angle from the markers' (undistorted) centroids."""

from .geometry import angle_rad_from_centroids, blade_angle
from .pivot import PivotMotion, axis_moved, heave_px, pivot_motion
from .rigid import RigidMotion, rigid_motion

__all__ = ["PivotMotion", "RigidMotion", "angle_rad_from_centroids", "axis_moved", "blade_angle", "heave_px",
           "pivot_motion", "rigid_motion"]
