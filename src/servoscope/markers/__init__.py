"""Markers: colour models, soft centroids, the tracking engines, error analysis.

The stage's modules (it imports video and nothing of the camera or angle stages):

* the result and its settings: :mod:`.track` (:class:`Track`), :mod:`.settings`
  (:class:`TrackerSettings`, the engine it resolves to);
* the driver is not here: :func:`servoscope.pipeline.track_video`
  (:mod:`servoscope.pipeline.tracker`) runs an engine of this stage, then the
  frame checks, the camera stage, the angle stage and the LED's t0;
* the engines, each reporting one :class:`~.frame_record.FrameRecord` a frame
  into one :class:`~.frame_record.TrackLog`: :mod:`.yuv_engine` ("numba",
  "numpy": the kernels of :mod:`.kernels`) and :mod:`.rgb_engine`
  ("reference-rgb");
* what the engines share: :mod:`.first_frame` (which blobs are the markers;
  :mod:`.selection`, :mod:`.candidates`), :mod:`.marker_state` (one marker's
  learned colour, shape and motion), :mod:`.colour`, :mod:`.centroid`,
  :mod:`.moments`, :mod:`.illumination`, :mod:`.led_level` and
  :mod:`.led_timing` (the LED), :mod:`.frame_checks` (duplicated frames),
  :mod:`.timebase`;
* :mod:`.error_analysis` (the angle's error budget) and :mod:`.gpu` (a
  whole-frame batch classifier on CUDA, measured by ``servoscope bench``; not
  a tracking engine).
"""

from .candidates import Candidate, draw_candidates, find_candidates
from .centroid import SoftCentroid, soft_centroid
from .colour import ColourModel, parse_colour
from .error_analysis import angle_error_analysis, plot_angle_error, worst_case_angle_error_rad
from .moments import Moments, weighted_moments
from .timebase import FrameTiming, frame_timing
from .settings import TrackerSettings
from .track import Track

__all__ = [
    "Candidate",
    "ColourModel",
    "FrameTiming",
    "Moments",
    "SoftCentroid",
    "Track",
    "TrackerSettings",
    "angle_error_analysis",
    "draw_candidates",
    "find_candidates",
    "frame_timing",
    "parse_colour",
    "plot_angle_error",
    "soft_centroid",
    "weighted_moments",
    "worst_case_angle_error_rad",
]
