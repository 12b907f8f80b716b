"""Markers: colour models, moments, and tracking through video."""

from .colour import ColourModel, parse_colour
from .moments import Moments, weighted_moments
from .tracker import Track, TrackerSettings, angle_rad_from_centroids, track_video

__all__ = [
    "ColourModel",
    "Moments",
    "Track",
    "TrackerSettings",
    "angle_rad_from_centroids",
    "parse_colour",
    "track_video",
    "weighted_moments",
]
