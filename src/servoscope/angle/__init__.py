"""Angle: the blade's angle from the markers' (undistorted) centroids."""

from .geometry import angle_rad_from_centroids, blade_angle

__all__ = ["angle_rad_from_centroids", "blade_angle"]
