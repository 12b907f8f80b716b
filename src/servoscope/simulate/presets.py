"""Named simulation campaigns: the paper's experiment and a quick one for tests."""

from __future__ import annotations

import math

from dataclasses import dataclass, field, replace
from fractions import Fraction

import numpy as np

from ..camera.model import CameraModel
from ..defaults import EXTRA_COLOURS, SETTLE_S, TIMESTAMP, TIMESTAMPS
from ..errors import ServoscopeError
from .scene import REFERENCE_SIZE, Scene
from ..sysid.inputs import sweep_problems
from .servo import ServoModel
from .view import ObliqueView

__all__ = ["CampaignPreset", "PRESETS", "PAPER_SERVO", "get_preset"]

#: The paper's fit: G(s) = 0.23·37² / (s² + 2·0.65·37·s + 37²), dead time 85 ms.
PAPER_SERVO = ServoModel(num=(0.23 * 37.0**2,), den=(1.0, 2.0 * 0.65 * 37.0, 37.0**2), dead_time_s=0.085)


@dataclass(frozen=True)
class CampaignPreset:
    """Everything that defines a simulated measurement campaign.

    Parameters
    ----------
    name : str
        Preset name, recorded in truth.json.
    servo : ServoModel
        The true actuator.
    frequencies_hz : tuple of float
        Sine dwell frequencies, Hz.
    sine_amplitude, step_amplitude : float
        Input amplitudes, input units.
    input_units : str
        Name of the input units (campaign.toml ``[input] units``).
    include_step : bool
        Whether to record the step test.
    width, height : int
        Frame size, pixels (even).
    fps : float or Fraction
        Frame rate.
    codec : {"h264", "mpeg2", "raw"}
        Video codec (see :class:`servoscope.video.writer.VideoWriter`).
    bit_rate : int
        H.264 or MPEG-2 bit rate, bit/s.
    gop : int or None
        Frames from one intra-coded frame to the next (None: the codec's
        default, see :class:`servoscope.video.writer.VideoWriter`).
    x264_preset : str
        x264 speed preset.
    noise_sigma_dn : float
        Sensor noise, DN.
    exposure_s : float or None
        Exposure time, seconds; None (the default) = one frame interval, a
        camcorder's 1/100 s shutter at 100 frames/s. The LED's partial
        exposure dates the input start to a fraction of a frame only when the
        switch falls inside an exposure; the blade's pose is averaged over it.
    readout_s : float
        Rolling-shutter readout time, seconds: row y of a frame is exposed
        around ``frame_time + readout_s·y/height``. 0 (the default) is a
        global shutter; it must be shorter than the frame interval (a sensor
        reads one frame's rows before the next frame's).
    pre_roll_s : float
        Time with the LED lit before the input starts (t0 is this plus a
        seeded fraction of a frame, so it never falls on a frame boundary).
    settle_s : float
        Sine dwells: time after t0 allowed for the transient (by default what identify skips
        when campaign.toml says none, :data:`servoscope.defaults.SETTLE_S`).
    min_dwell_s, min_periods : float
        Sine dwells record ``max(min_dwell_s, min_periods / f)`` after settling.
    step_after_t0_s : float
        Length of the step test after t0, seconds.
    focal_px : float
        Focal length at the reference size 720×576 (scaled with the image).
    principal_offset_px : (float, float)
        Principal point minus image centre at the reference size.
    dist_coeffs : tuple of float
        Brown–Conrady ``[k1, k2, p1, p2, k3]``.
    scene : Scene or None
        What is filmed; None means ``Scene.for_size(width, height)`` with the
        campaign seed as background seed.
    flicker_hz, flicker_depth : float
        Lamps whose light is ``1 + depth·sin(2π·flicker_hz·t)`` (mains
        lighting: twice the mains frequency), integrated over each exposure
        (each row's, with a rolling shutter); the lit LED shines its own
        light and does not flicker. depth 0 (the default): steady lamps.
        Lamps at a multiple of the frame rate look steady to a global
        shutter (each frame sees the same part of the cycle).
    flicker_phase_rad : float or None
        The lamps' phase at t = 0; None (the default) draws it from the
        campaign seed (the mains is not synchronised with the camera);
        truth.json records it.
    shake_px : float
        Camera shake: RMS of a smooth, seeded translation of the whole
        picture, per axis, recorded pixels (0, the default: a rigid tripod).
    shake_smooth_frames : float
        Correlation length of the shake, frames (Gaussian smoothing of white
        noise).
    t0_frame_phase : float or None
        Where in its frame interval the input (and the LED switch) starts,
        as a fraction in [0, 1), the same for every test; None (the default)
        draws it per test, uniform in [0.02, 0.98).
    manifest_exposure : bool
        Whether campaign.toml says ``exposure_s`` (False: a user who does not
        know the shutter time).
    motion_blur : bool
        Render the real motion blur of the exposure (the mean of sub-exposure
        renders) instead of the exposure-averaged pose; truth stays the
        exposure-averaged pose. Global shutter only.
    blur_step_px : float
        Motion blur: the most a blade point moves between two sub-exposure
        renders, pixels.
    blur_max_samples : int
        Motion blur: at most this many renders per frame.
    timestamp_at : {"middle", "start", "end"}
        Which instant of the exposure the written frame timestamp marks
        (campaign.toml ``[camera] timestamp`` says it when not "middle").
    roll_rad, roll_hz : float
        A camera that rolls (or a phone's stabilisation that turns the
        picture): the whole recorded picture turns about its centre by
        ``roll_rad·sin(2π·roll_hz·t)``, counter-clockwise positive as angles
        are counted, constant over an exposure; truth's ``angle_rad`` stays the
        blade's against the airframe and ``roll_rad`` per frame says the
        picture's. 0 (the default): a steady camera. Global shutter only.
    rock_rad, rock_hz : float
        The airframe rocking on its skids: the blade, its pivot and the
        reference stickers turn by ``rock_rad·sin(2π·rock_hz·t)`` about the
        point below the pivot at the picture's bottom edge; the background
        stays. Truth's ``angle_rad`` stays the blade's against the airframe,
        ``rock_rad`` per frame says the airframe's. Global shutter only.
    reference_stickers : bool
        Two stickers on the airframe (the image's lower corners, colours
        :data:`servoscope.defaults.REFERENCE_COLOURS`, 1.3× the blade's), which
        campaign.toml names as ``[markers] reference``: the blade's angle is then
        measured against the line joining them.
    blade_mode_hz, blade_mode_damping, blade_mode_px_per_rad : float
        The blade flaps: a structural mode (frequency, damping ratio) excited by
        the pitch's acceleration, ``q'' + 2ζω q' + ω² q = −κ·θ''`` with κ
        ``blade_mode_px_per_rad``, seen as the whole blade moving across its chord
        by q px (heave; the stickers with it, so the angle is unchanged). 0 Hz
        (the default): a rigid blade. Global shutter, no motion blur. Truth lists
        the mode (``modes``) and each test's ``heave_px``.
    blade_mode_bend : float
        The mode bends the blade along the stickers' line: a sticker at position
        f of the way from the trail sticker (0) to the lead (1) moves
        ``1 − 4·bend·f·(1 − f)`` of the heave (the lead and trail stickers all of
        it, a sticker halfway ``1 − bend``), seen by extra stickers
        (``extra_stickers``); truth's mode lists its ``shape`` at each sticker. 0 (the
        default): a rigid blade's mode.
    blade_mode2 : (float, float, float, float) or None
        A second mode beside the first (``blade_mode_hz > 0``): its frequency (Hz),
        damping ratio, ``px_per_rad`` and ``bend``, driven and seen as the first;
        the stickers move by the sum of both. None (the default): one mode.
    extra_stickers : tuple of (str, float)
        More stickers on the blade, ``(colour, position)`` with position from the
        trail sticker (0) to the lead (1) (the scene's
        :attr:`~servoscope.simulate.Scene.extra_stickers`); campaign.toml names
        them as ``[markers] extra``. Empty (the default): two stickers.
    sine_amplitudes : tuple of float or None
        Amplitude as a test axis: a dwell at every frequency for each of these
        input amplitudes (frequency by frequency), instead of ``sine_amplitude``
        alone; the linearity check compares their gains.
    monochrome : bool
        A monochrome high-speed camera: each frame is the scene's BT.601 luma
        at ``bit_depth`` bits (sensor noise scaled with it), written as an image
        sequence of gray TIFFs (8-bit files for 8 bits, 16-bit files otherwise,
        the depth in the manifest's ``bits``); the stickers are white dots on the
        dark blade and campaign.toml gives the markers and the LED as
        ``"bright"``. Needs ``frames_format="tiff16"``; global shutter, no blur.
    bit_depth : int
        Monochrome samples' depth: 8, 10, 12 or 16.
    light_level : float
        Monochrome footage's exposure against the rendered scene's (0 < level <= 1):
        the scene's luma is scaled by it before the sensor noise (which stays), as
        a camera at a short shutter or in dim light records; 0.1: lit at 10 % of
        full scale. 1 (the default): as rendered.
    frames_format : {None, "tiff16", "mraw"}
        Write each test as a folder of frames instead of a video (the
        manifest then says ``frames`` and ``fps``): ``"tiff16"``, 16-bit RGB
        TIFFs of the rendered 8-bit frames (``v · 257``), as high-speed
        cameras save; the codec is then unused. ``"mraw"`` (monochrome only):
        a Photron MRAW with its CIH header in the test's folder
        (``frames.cih``; 8-bit samples in bytes, 12-bit packed two in three
        bytes, 16-bit in words).
    view_yaw_deg, view_tilt_deg : float
        An oblique camera (:class:`~servoscope.simulate.view.ObliqueView`): turned
        about the blade plane's vertical axis (positive: to the blade's right) and
        then its own horizontal one (positive: up), degrees, under 80 each, with the
        lens's focal length (:meth:`camera`). The scene is drawn in the plane and
        seen through the view; truth's positions and angles stay in the plane, and
        the campaign gets a chessboard photo (``board.png``). 0 and 0 (the
        default): square-on.
    led_place : {"blade", "stand"}
        Where the status LED is: on the blade (the default) or fixed to the
        stand, at ``led_xy_px`` (recorded-image px; None: above the trail
        sticker, a fifth of the height from the top). Truth says where.
    led_distractors : bool
        Add what the LED is mistaken for: a specular glint by the hub, brighter
        and larger than the LED (in its hue), and a screw head brighter than the
        LED's off level.
    sweep : (float, float, float) or None
        A frequency-sweep test ``(from_hz, to_hz, duration_s)`` after the dwells (before
        the step), of amplitude ``sine_amplitude`` and shape ``sweep_shape``: the LED
        switches at its start, which comes ``pre_roll_s`` (and a fraction of a frame)
        into the video, and the video goes on ``settle_s`` after the sweep ends. None
        (the default): no sweep.
    sweep_shape : {"log", "linear"}
        The sweep's frequency law (:func:`servoscope.sysid.inputs.sweep_command`).
    piloted_sweep : (float, float, float) or None
        A piloted sweep ``(from_hz, to_hz, duration_s)`` after the chirp (before the step): a
        pilot's stick swept over the band in that time, its frequency and swing wandering
        (:func:`servoscope.simulate.pilot.pilot_input`, of mean swing ``sine_amplitude``), recorded
        as ``u.csv`` beside the video and named by the manifest's ``input = "u.csv"``; its LED and
        video as a sweep's. None (the default): none.
    """

    name: str
    servo: ServoModel
    frequencies_hz: tuple[float, ...]
    sine_amplitude: float = 0.1
    step_amplitude: float = 0.5
    input_units: str = "normalized"
    include_step: bool = True
    width: int = 720
    height: int = 576
    fps: float | Fraction = 100
    codec: str = "h264"
    bit_rate: int = 20_000_000
    x264_preset: str = "ultrafast"
    gop: int | None = None
    noise_sigma_dn: float = 1.5
    exposure_s: float | None = None
    readout_s: float = 0.0
    pre_roll_s: float = 0.5
    settle_s: float = SETTLE_S
    min_dwell_s: float = 3.0
    min_periods: float = 4.0
    step_after_t0_s: float = 1.5
    focal_px: float = 1100.0
    principal_offset_px: tuple[float, float] = (3.2, -2.1)
    dist_coeffs: tuple[float, ...] = (-0.08, 0.02, 4e-4, -3e-4, 0.0)
    scene: Scene | None = field(default=None)
    flicker_hz: float = 0.0
    flicker_depth: float = 0.0
    flicker_phase_rad: float | None = None
    shake_px: float = 0.0
    shake_smooth_frames: float = 5.0
    t0_frame_phase: float | None = None
    manifest_exposure: bool = True
    motion_blur: bool = False
    blur_step_px: float = 0.5
    blur_max_samples: int = 32
    timestamp_at: str = TIMESTAMP
    frames_format: str | None = None
    roll_rad: float = 0.0
    roll_hz: float = 3.0
    rock_rad: float = 0.0
    rock_hz: float = 2.0
    reference_stickers: bool = False
    monochrome: bool = False
    bit_depth: int = 8
    light_level: float = 1.0
    sine_amplitudes: tuple[float, ...] | None = None
    blade_mode_hz: float = 0.0
    blade_mode_damping: float = 0.03
    blade_mode_px_per_rad: float = 40.0
    blade_mode_bend: float = 0.0
    blade_mode2: tuple[float, float, float, float] | None = None
    extra_stickers: tuple[tuple[str, float], ...] = ()
    view_yaw_deg: float = 0.0
    view_tilt_deg: float = 0.0
    led_place: str = "blade"
    led_xy_px: tuple[float, float] | None = None
    led_distractors: bool = False
    sweep: tuple[float, float, float] | None = None
    sweep_shape: str = "log"
    piloted_sweep: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        self._check_camera_options()
        if self.piloted_sweep is not None:
            object.__setattr__(self, "piloted_sweep", self._band("piloted_sweep", self.piloted_sweep))
        if self.sweep is not None:
            try:
                lo, hi, dur = (float(v) for v in self.sweep)
            except (TypeError, ValueError):
                raise ServoscopeError(f"sweep must be (from_hz, to_hz, duration_s), not {self.sweep!r}") from None
            problems = sweep_problems(lo, hi, dur, self.sweep_shape)
            if problems:
                raise ServoscopeError("sweep: " + "; ".join(f"{k}: {m}" for k, m in problems))
            object.__setattr__(self, "sweep", (lo, hi, dur))
            fps = float(Fraction(self.fps).limit_denominator(1_000_000))
            if hi >= 0.5 * fps:
                raise ServoscopeError(f"sweep: to_hz ({hi:g} Hz) must be below half the frame rate ({fps:g} frames/s)")
        elif self.sweep_shape not in ("log", "linear"):
            raise ServoscopeError(f"sweep_shape must be 'log' or 'linear', not {self.sweep_shape!r}")
        if self.led_place not in ("blade", "stand"):
            raise ServoscopeError(f"led_place must be 'blade' or 'stand', not {self.led_place!r}")
        if self.led_place == "stand" and (self.readout_s > 0 or self.motion_blur):
            raise ServoscopeError("an LED on the stand (led_place='stand') is rendered with a global shutter and "
                                  "no motion blur")
        if self.led_xy_px is not None:
            xy = tuple(float(v) for v in self.led_xy_px)
            if len(xy) != 2 or not all(math.isfinite(v) for v in xy) or self.led_place != "stand":
                raise ServoscopeError(f"led_xy_px: two finite pixel coordinates, with led_place='stand' "
                                      f"(got {self.led_xy_px!r})")
            object.__setattr__(self, "led_xy_px", xy)
        self.view()  # validates the angles (ServoscopeError)
        freqs = tuple(float(f) for f in np.atleast_1d(self.frequencies_hz))
        if any(not (f > 0 and math.isfinite(f)) for f in freqs):
            raise ServoscopeError("frequencies_hz must be positive")
        object.__setattr__(self, "frequencies_hz", freqs)
        if self.exposure_s is None:
            object.__setattr__(self, "exposure_s", 1.0 / float(Fraction(self.fps).limit_denominator(1_000_000)))
        if not freqs and not self.include_step and self.sweep is None and self.piloted_sweep is None:
            raise ServoscopeError("a campaign needs at least one test")
        if not (self.noise_sigma_dn >= 0 and self.exposure_s >= 0 and self.pre_roll_s >= 0 and self.settle_s >= 0):
            raise ServoscopeError("noise_sigma_dn, exposure_s, pre_roll_s and settle_s must be >= 0")
        if not (self.min_dwell_s > 0 and self.min_periods >= 0 and self.step_after_t0_s > 0):
            raise ServoscopeError("min_dwell_s and step_after_t0_s must be > 0, min_periods >= 0")
        if self.exposure_s * float(Fraction(self.fps).limit_denominator(1_000_000)) > 1.0 + 1e-12:
            raise ServoscopeError("exposure_s cannot exceed the frame interval")
        if not (math.isfinite(self.readout_s) and 0.0 <= self.readout_s
                and self.readout_s * float(Fraction(self.fps).limit_denominator(1_000_000)) < 1.0):
            raise ServoscopeError(f"readout_s must be >= 0 and shorter than the frame interval, not {self.readout_s!r}")
        if self.scene is not None and (self.scene.width, self.scene.height) != (self.width, self.height):
            raise ServoscopeError("the scene's size differs from the video size")

    def _check_camera_options(self) -> None:
        """Validate the real-camera options (flicker, shake, blur, timestamps)."""
        if not (math.isfinite(self.flicker_hz) and self.flicker_hz >= 0):
            raise ServoscopeError(f"flicker_hz must be >= 0, not {self.flicker_hz!r}")
        if self.flicker_phase_rad is not None and not math.isfinite(self.flicker_phase_rad):
            raise ServoscopeError(f"flicker_phase_rad must be finite, not {self.flicker_phase_rad!r}")
        if not 0.0 <= self.flicker_depth < 1.0:
            raise ServoscopeError(f"flicker_depth must be in [0, 1), not {self.flicker_depth!r}")
        if not (math.isfinite(self.shake_px) and self.shake_px >= 0):
            raise ServoscopeError(f"shake_px must be >= 0, not {self.shake_px!r}")
        if not self.shake_smooth_frames > 0:
            raise ServoscopeError(f"shake_smooth_frames must be > 0, not {self.shake_smooth_frames!r}")
        if self.t0_frame_phase is not None and not 0.0 <= self.t0_frame_phase < 1.0:
            raise ServoscopeError(f"t0_frame_phase must be in [0, 1) or None, not {self.t0_frame_phase!r}")
        if not self.blur_step_px > 0 or int(self.blur_max_samples) != self.blur_max_samples \
                or self.blur_max_samples < 1:
            raise ServoscopeError("blur_step_px must be > 0 and blur_max_samples an integer >= 1")
        if self.timestamp_at not in TIMESTAMPS:
            raise ServoscopeError(f"timestamp_at must be one of {', '.join(TIMESTAMPS)}, not {self.timestamp_at!r}")
        if self.frames_format not in (None, "tiff16", "mraw"):
            raise ServoscopeError(f"frames_format must be None, 'tiff16' or 'mraw', not {self.frames_format!r}")
        if self.frames_format == "mraw" and not (self.monochrome and self.bit_depth in (8, 12, 16)):
            raise ServoscopeError("frames_format=\"mraw\" writes a monochrome camera's file of 8, 12 or 16 bits: "
                                  "set monochrome=True and bit_depth")
        if not (0.0 < self.light_level <= 1.0) or (self.light_level != 1.0 and not self.monochrome):
            raise ServoscopeError(f"light_level must be in (0, 1], and other than 1 only for monochrome footage, "
                                  f"not {self.light_level!r}")
        if not (math.isfinite(self.blade_mode_hz) and self.blade_mode_hz >= 0
                and 0 < self.blade_mode_damping < 1 and math.isfinite(self.blade_mode_px_per_rad)
                and math.isfinite(self.blade_mode_bend)):
            raise ServoscopeError("blade_mode_hz must be >= 0, blade_mode_damping in (0, 1) and blade_mode_bend finite")
        if self.blade_mode2 is not None:
            f2, z2, k2, b2 = (float(v) for v in self.blade_mode2)
            if not (self.blade_mode_hz > 0 and f2 > 0 and 0 < z2 < 1 and math.isfinite(f2 + k2 + b2)):
                raise ServoscopeError("blade_mode2 = (frequency_hz > 0, damping ratio in (0, 1), px_per_rad, bend) "
                                      "beside a first mode (blade_mode_hz > 0)")
            object.__setattr__(self, "blade_mode2", (f2, z2, k2, b2))
        if self.blade_mode_hz > 0 and (self.readout_s > 0 or self.motion_blur):
            raise ServoscopeError("a flapping blade (blade_mode_hz > 0) is rendered with a global shutter and no "
                                  "motion blur")
        if self.sine_amplitudes is not None:
            amps = tuple(float(a) for a in self.sine_amplitudes)
            if not amps or any(not (a > 0 and math.isfinite(a)) for a in amps) or len(set(amps)) != len(amps):
                raise ServoscopeError(f"sine_amplitudes must be distinct amplitudes > 0, not {self.sine_amplitudes!r}")
            object.__setattr__(self, "sine_amplitudes", amps)
        for name in ("roll", "rock"):
            amp, hz = getattr(self, f"{name}_rad"), getattr(self, f"{name}_hz")
            if not (math.isfinite(amp) and math.isfinite(hz) and hz > 0 and abs(amp) < 0.5):
                raise ServoscopeError(f"{name}_rad must be finite and under 0.5 rad, {name}_hz > 0 (got {amp!r}, "
                                      f"{hz!r})")
        if self.monochrome and (self.frames_format not in ("tiff16", "mraw") or self.bit_depth not in (8, 10, 12, 16)
                                or self.readout_s > 0 or self.motion_blur):
            raise ServoscopeError("monochrome footage is written as an image sequence or an MRAW (frames_format="
                                  "\"tiff16\" or \"mraw\") "
                                  "of 8, 10, 12 or 16 bits, with a global shutter and no motion blur")
        if self.readout_s > 0:
            # The row-by-row renderer draws one pose per row; blur would need
            # sub-exposures per row, shake (and roll) a per-row move of the background.
            unsupported = [name for name, on in (("motion_blur", self.motion_blur), ("shake_px", self.shake_px > 0),
                                                 ("roll_rad", self.roll_rad != 0), ("rock_rad", self.rock_rad != 0))
                           if on]
            if unsupported:
                raise ServoscopeError(f"{' and '.join(unsupported)} cannot be combined with a rolling shutter "
                                      f"(readout_s > 0): use a global shutter (readout_s=0)")

    @property
    def exposure_centre_offset_s(self) -> float:
        """Exposure middle minus the written frame timestamp, seconds (by ``timestamp_at``)."""
        return {"middle": 0.0, "start": 0.5, "end": -0.5}[self.timestamp_at] * self.exposure_s

    def dwell_duration_s(self, frequency_hz: float, t0_s: float) -> float:
        """Length of the sine dwell at ``frequency_hz`` that starts at ``t0_s``."""
        return t0_s + self.settle_s + max(self.min_dwell_s, self.min_periods / frequency_hz)

    def sweep_video_duration_s(self, t0_s: float, sweep: tuple[float, float, float] | None = None) -> float:
        """Length of the sweep test's video whose input starts at ``t0_s``: the sweep (``sweep``, else the
        chirp's), then ``settle_s``."""
        return t0_s + (sweep or self.sweep)[2] + self.settle_s

    def _band(self, name: str, value) -> tuple[float, float, float]:
        """A ``(from_hz, to_hz, duration_s)`` setting, checked: numbers, ``0 < from < to`` below half the frame rate."""
        try:
            lo, hi, dur = (float(v) for v in value)
        except (TypeError, ValueError):
            raise ServoscopeError(f"{name} must be (from_hz, to_hz, duration_s), not {value!r}") from None
        problems = sweep_problems(lo, hi, dur, "log")
        if problems:
            raise ServoscopeError(f"{name}: " + "; ".join(f"{k}: {m}" for k, m in problems))
        fps = float(Fraction(self.fps).limit_denominator(1_000_000))
        if hi >= 0.5 * fps:
            raise ServoscopeError(f"{name}: to_hz ({hi:g} Hz) must be below half the frame rate ({fps:g} frames/s)")
        return lo, hi, dur

    def camera(self) -> CameraModel:
        """The true camera, its intrinsics scaled from the reference size."""
        s = min(self.width / REFERENCE_SIZE[0], self.height / REFERENCE_SIZE[1])
        f = self.focal_px * s
        cx = (self.width - 1) / 2.0 + self.principal_offset_px[0] * s
        cy = (self.height - 1) / 2.0 + self.principal_offset_px[1] * s
        k = np.array([[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]])
        return CameraModel((self.width, self.height), k, np.asarray(self.dist_coeffs, dtype=float))

    def view(self) -> ObliqueView | None:
        """The oblique view, with the lens's focal length as :meth:`camera` scales it; None when square-on."""
        if self.view_yaw_deg == 0 and self.view_tilt_deg == 0:
            return None
        s = min(self.width / REFERENCE_SIZE[0], self.height / REFERENCE_SIZE[1])
        return ObliqueView(self.view_yaw_deg, self.view_tilt_deg, self.focal_px * s, self.width, self.height)


PRESETS: dict[str, CampaignPreset] = {
    "paper": CampaignPreset(
        name="paper",
        servo=PAPER_SERVO,
        frequencies_hz=tuple(float(f) for f in np.geomspace(0.5, 15.0, 14)),
    ),
    "quick": CampaignPreset(
        name="quick",
        servo=PAPER_SERVO,
        frequencies_hz=tuple(float(f) for f in np.geomspace(1.0, 12.0, 4)),
        pre_roll_s=0.2,
        settle_s=0.2,
        min_dwell_s=0.8,
        min_periods=0.0,
        step_after_t0_s=0.6,
    ),
}
# The paper's blade flapping: a 9 Hz mode with 3 % damping that the pitch's motion excites
# (the paper saw it ring on after the step for seconds); a longer step shows its ring-down.
PRESETS["paper-flap"] = replace(PRESETS["paper"], name="paper-flap", blade_mode_hz=9.0, blade_mode_damping=0.03,
                                step_after_t0_s=2.5)
# The same blade seen by two more stickers (issue 18): halfway and a quarter of the way from the trail
# sticker to the lead, and a mode that bends it (the middle moves half as far as the ends).
PRESETS["paper-bend"] = replace(PRESETS["paper-flap"], name="paper-bend", blade_mode_bend=0.5,
                                extra_stickers=((EXTRA_COLOURS[0], 0.5), (EXTRA_COLOURS[1], 0.25)))
# The paper's puzzle (issue 17): a servo of the paper's linear dynamics (ζ = 0.65, a 7 % overshoot)
# whose linkage has 0.012 rad (0.69°) of play. Its step does not overshoot (the play holds the
# blade at its first peak while the servo swings back), every sine's peaks flatten (the blade
# waits at each turn while the servo takes up the gap), and the small sines' gain and phase
# differ from the large ones': what the paper saw, and what `identify --nonlinear auto` explains.
PRESETS["paper-nonlinear"] = replace(PRESETS["paper"], name="paper-nonlinear",
                                     servo=replace(PAPER_SERVO, backlash=0.012), sine_amplitudes=(0.1, 0.3))
# A sweep instead of the dwells (issue 31): the paper's servo and camera, one 12 s logarithmic sweep
# from 0.5 to 15 Hz (the dwells' span) at the dwells' amplitude, after the same lead-in.
PRESETS["paper-sweep"] = replace(PRESETS["paper"], name="paper-sweep", frequencies_hz=(), include_step=False,
                                 sweep=(0.5, 15.0, 12.0))


def get_preset(name: str) -> CampaignPreset:
    """The preset called ``name``; ServoscopeError if there is none."""
    try:
        return PRESETS[name]
    except KeyError:
        # The rotor's presets (simulate/rotor_campaign.py, which imports this module) are named by hand.
        raise ServoscopeError(f"unknown simulation preset {name!r} (choose from "
                              f"{', '.join(sorted([*PRESETS, 'paper-rotor']))})") from None
