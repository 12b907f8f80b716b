"""Digital twin: simulated footage of a servo-driven rotor blade with a known answer.

* :class:`InputSignal`, :class:`ServoModel` — the true actuator (TF, dead
  time, optional quantization / rate limit / backlash) and its response.
* :class:`Scene` — what the camera sees; :class:`FrameRenderer`,
  :func:`render_frame`, :func:`polygon_coverage` — exact-area rendering with
  lens distortion and sensor noise; :class:`Clutter`, :func:`lamp_gain` —
  static objects and flickering lamps (real-camera options, docs/twin.md).
* :class:`ObliqueView` — a camera that looks at the blade's plane from the side
  (a homography before the lens); :func:`render_board_photo` — a chessboard
  lying in that plane, photographed through it.
* :func:`simulate_campaign` — videos + campaign.toml + camera.json + truth.json.
* :func:`reencode_campaign` — a raw campaign's videos written again with a lossy codec (one render, many codecs).
"""

from .board import render_board_photo
from .campaign import simulate_campaign
from .presets import PRESETS, CampaignPreset, PAPER_SERVO
from .reencode import reencode_campaign
from .render import FrameRenderer, polygon_coverage, render_frame
from .scene import Clutter, Scene, lamp_gain, led_exposure_fraction, marker_angle_rad
from .servo import InputSignal, ServoModel
from .view import ObliqueView

__all__ = [
    "InputSignal",
    "ServoModel",
    "Scene",
    "Clutter",
    "lamp_gain",
    "FrameRenderer",
    "render_frame",
    "polygon_coverage",
    "led_exposure_fraction",
    "marker_angle_rad",
    "simulate_campaign",
    "reencode_campaign",
    "CampaignPreset",
    "PRESETS",
    "PAPER_SERVO",
    "ObliqueView",
    "render_board_photo",
]
