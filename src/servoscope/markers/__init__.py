"""Markers: colour models, soft centroids, tracking through video, error analysis."""

from .candidates import Candidate, draw_candidates, find_candidates
from .centroid import SoftCentroid, soft_centroid
from .colour import ColourModel, parse_colour
from .error_analysis import angle_error_analysis, plot_angle_error, worst_case_angle_error_rad
from .moments import Moments, weighted_moments
from .timebase import FrameTiming, frame_timing
from ..angle.geometry import angle_rad_from_centroids
from .settings import TrackerSettings
from .track import Track
from .tracker import track_video

__all__ = [
    "Candidate",
    "ColourModel",
    "FrameTiming",
    "Moments",
    "SoftCentroid",
    "Track",
    "TrackerSettings",
    "angle_error_analysis",
    "angle_rad_from_centroids",
    "draw_candidates",
    "find_candidates",
    "frame_timing",
    "parse_colour",
    "plot_angle_error",
    "soft_centroid",
    "track_video",
    "weighted_moments",
    "worst_case_angle_error_rad",
]
