"""Write a complete simulated campaign: videos, campaign.toml, camera.json, truth.json.

The footage has a known answer: ``truth.json`` records the model, the
camera, and for every frame the blade pitch, the true sticker centres (ideal,
undistorted pixel coordinates; in the blade's plane, plane px, when the camera
looks at it obliquely) and the LED level.
"""

from __future__ import annotations

import cmath
import functools
import json
import math

from collections.abc import Callable
from dataclasses import fields, replace
from fractions import Fraction
from pathlib import Path

import control
import cv2
import numpy as np

from ..errors import ServoscopeError
from ..video.sequence_writer import MrawWriter, TiffSequenceWriter
from ..video.writer import LOSSY, VideoWriter, container_suffixes
from .presets import CampaignPreset, get_preset
from .render import FrameRenderer
from .render_parts import gray_frame
from ..defaults import REFERENCE_COLOURS
from ..markers.colour import luma_bt601
from .scene import Clutter, Scene, lamp_gain, led_exposure_fraction, marker_angle_rad
from .pilot import pilot_input, record_pilot
from .servo import InputSignal, ServoModel
from .._io import atomic_path, write_text_atomic
from .board import PLANE_MM_PER_PX, render_board_photo
from .blade_modes import shape_along_chord, blade_modes_of, mode_heaves_px, mode_shape, steady_heave
from .manifest import TWIN_HEADER, twin_campaign
from .rotor_campaign import ROTOR_PRESETS, simulate_rotor_campaign

#: A preset's default real-camera options, to tell which ones a campaign set.
_DEFAULT = CampaignPreset(name="default", servo=None, frequencies_hz=(1.0,))

__all__ = ["simulate_campaign", "frame_times_s", "step_metrics", "render_test"]


def frame_times_s(n_frames: int, fps: Fraction) -> np.ndarray:
    """``i / fps`` for i < n_frames, each correctly rounded (one division)."""
    fps = Fraction(fps)
    return (np.arange(n_frames, dtype=np.float64) * fps.denominator) / fps.numerator


def step_metrics(servo: ServoModel) -> dict[str, float | None]:
    """Rise time (10–90 %), overshoot and 2 % settling time of G's step response.

    Uses ``control.step_info`` on a fine time grid (dead time excluded); None
    where undefined (unstable or integrating models).
    """
    return dict(_step_metrics(tuple(map(float, servo.num)), tuple(map(float, servo.den))))


@functools.lru_cache(maxsize=64)
def _step_metrics(num: tuple[float, ...], den: tuple[float, ...]) -> tuple[tuple[str, float | None], ...]:
    # Cached by the coefficients: python-control's simulation loops over 20,001 samples in Python
    # (~0.1 s), and a session renders many campaigns of a few servos.
    g = control.tf(list(num), list(den))
    poles = np.roots(den)
    if poles.size and np.max(poles.real) >= 0:
        return (("rise_time_s", None), ("overshoot_pct", None), ("settling_time_s", None))
    slowest = np.min(np.abs(poles.real)) if poles.size else 1.0
    t = np.linspace(0.0, 12.0 / slowest, 20_001)
    info = control.step_info(g, t)

    def clean(v: float) -> float | None:
        return float(v) if v is not None and math.isfinite(v) else None

    return (("rise_time_s", clean(info["RiseTime"])), ("overshoot_pct", clean(info["Overshoot"])),
            ("settling_time_s", clean(info["SettlingTime"])))


def exposure_averaged_response(servo, signal: InputSignal, time_s: np.ndarray, exposure_s: float,
                               samples: int = 12) -> np.ndarray:
    """The servo's output averaged over each frame's exposure window [t − e/2, t + e/2].

    Gauss–Legendre quadrature on ``samples`` nodes (exact for polynomials of
    degree 2·samples − 1; the input's switch at t0 costs a little accuracy in
    the one frame it falls in); with e = 0 the instantaneous output.
    """
    if exposure_s <= 0:
        return servo.response(signal, time_s)
    nodes, weights = np.polynomial.legendre.leggauss(samples)
    grid = (np.asarray(time_s)[:, None] + 0.5 * exposure_s * nodes[None, :]).ravel()
    values = servo.response(signal, grid).reshape(len(time_s), samples)
    return values @ (0.5 * weights)


def _rolling_pitch(preset: CampaignPreset, signal: InputSignal, time_s: np.ndarray,
                   grid_step_s: float = 2e-4) -> Callable[[np.ndarray], np.ndarray]:
    """The exposure-averaged pitch as a function of time, for a rolling shutter's row times.

    A rolling-shutter frame needs the pose at hundreds of row times; the
    exact response costs ~5 µs a sample, so it is evaluated on a grid of
    ``grid_step_s`` spanning every row time and interpolated linearly. The
    interpolation error, at most ``grid_step_s²·max|p̈|/8``, is 8e-7 rad for
    the paper servo's step (|p̈| ≤ 160 rad/s²) and far less for the dwells —
    a hundredth of the angle noise (~5e-5 rad).
    """
    t_lo = float(time_s[0]) - grid_step_s
    t_hi = float(time_s[-1]) + preset.readout_s + grid_step_s
    grid = t_lo + grid_step_s * np.arange(int(math.ceil((t_hi - t_lo) / grid_step_s)) + 1)
    values = exposure_averaged_response(preset.servo, signal, grid, preset.exposure_s)
    return lambda t: np.interp(t, grid, values)


def _row_time_s(frame_time_s: np.ndarray, y_px: np.ndarray, preset: CampaignPreset) -> np.ndarray:
    """When a rolling shutter exposes image row ``y_px`` (recorded image) of the frame at ``frame_time_s``."""
    return frame_time_s + preset.readout_s * y_px / preset.height


def _rolling_truth(preset: CampaignPreset, scene: Scene, camera, pitch_at, time_s: np.ndarray,
                   uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Time at which a rolling shutter sees a blade point, and where it is (ideal px; plane px under a view) then.

    The row depends on the pose and the pose on the row's time: two fixed-point
    passes from the frame-time pose (a point moves by < 0.1 px in the ~0.1 ms
    that its own motion shifts its row time).
    """
    when = time_s.copy()
    view = preset.view()
    for _ in range(3):
        xy = scene.to_image(uv, pitch_at(when))
        # The row is the recorded one: through the oblique view, then the lens.
        xy = xy if view is None else view.apply(xy)
        recorded = camera.distort_points(xy) if camera.has_distortion else xy
        when = _row_time_s(time_s, recorded[:, 1], preset)
    return when, scene.to_image(uv, pitch_at(when))


def render_test(path: Path, preset: CampaignPreset, scene: Scene, signal: InputSignal, duration_s: float,
                noise_seed: int) -> dict:
    """Render and encode one test video; return its truth record (without the video name).

    Parameters
    ----------
    path : Path
        Output video file.
    preset : CampaignPreset
        Campaign settings (servo, video, camera).
    scene : Scene
        What is filmed.
    signal : InputSignal
        The test input (its t0_s also switches the LED off).
    duration_s : float
        Length of the video; frames at ``i / fps < duration_s``.
    noise_seed : int
        Seed of this video's sensor noise.

    Long because it renders one video's frames with every real-camera option (flicker,
    shake, blur, rolling shutter) in one loop over frames that share the renderer's
    state.
    """
    fps = Fraction(preset.fps).limit_denominator(1_000_000)
    n = int(math.ceil(duration_s * fps))
    time_s = frame_times_s(n, fps)
    written_s = time_s
    centre_offset = preset.exposure_centre_offset_s
    if centre_offset != 0.0:
        # The written timestamp marks the exposure's start or end: the
        # physics happens around the exposure's middle.
        time_s = time_s + centre_offset
    pitch_instant = preset.servo.response(signal, time_s)
    pitch = exposure_averaged_response(preset.servo, signal, time_s, preset.exposure_s)
    # The blade moves during the exposure; a sensor integrates the moving
    # stickers, whose centroid is then the pose averaged over the exposure.
    # Rendering the averaged pose reproduces that centroid (to within r·δ²/2,
    # δ the rotation during one exposure: < 1e-3 px here), and so the
    # amplitude loss sinc(π·f·e) that real footage shows.
    lead, trail = scene.sticker_centres_px(pitch)
    angle = marker_angle_rad(lead, trail)
    led = led_exposure_fraction(time_s, signal.t0_s, preset.exposure_s)
    modes = blade_modes_of(preset)
    shapes = [shape_along_chord(scene, bend) if bend else None for *_, bend in modes] or [None]
    renderer = FrameRenderer(scene, preset.camera(), noise_sigma_dn=preset.noise_sigma_dn, noise_seed=noise_seed,
                             mode_shape=shapes if len(shapes) > 1 else shapes[0], view=preset.view())
    extra_xy = scene.to_image(scene.extra_centres_uv(), pitch) if scene.extra_stickers else None
    rolling: dict = {}
    if preset.readout_s > 0:
        # Each row is exposed around its own time; the stickers and the LED
        # are seen at their rows' times, which truth records.
        pitch_at = _rolling_pitch(preset, signal, time_s)
        camera = preset.camera()
        lead_uv, trail_uv = scene.sticker_centres_uv()
        lead_time, lead = _rolling_truth(preset, scene, camera, pitch_at, time_s, lead_uv)
        trail_time, trail = _rolling_truth(preset, scene, camera, pitch_at, time_s, trail_uv)
        led_time, _ = _rolling_truth(preset, scene, camera, pitch_at, time_s, scene.led_centre_uv())
        angle = marker_angle_rad(lead, trail)
        led = led_exposure_fraction(led_time, signal.t0_s, preset.exposure_s)
        rolling = {"lead_time_s": lead_time.tolist(), "trail_time_s": trail_time.tolist(),
                   "led_time_s": led_time.tolist()}
        rows = np.arange(preset.height, dtype=np.float64)
    flicker = preset.flicker_depth > 0 and preset.flicker_hz > 0
    phase = preset.flicker_phase_rad or 0.0
    shake = _shake_px(preset, n, noise_seed)
    roll = preset.roll_rad * np.sin(2.0 * np.pi * preset.roll_hz * time_s)
    rock = preset.rock_rad * np.sin(2.0 * np.pi * preset.rock_hz * time_s)
    per_mode = mode_heaves_px(preset, signal, time_s)
    heave = per_mode.sum(axis=0)  # zeros for a rigid blade (no modes)
    # What the renderer moves each frame by: the heave (one mode), or each mode's (two).
    frame_heave = (lambda i: float(heave[i])) if len(per_mode) <= 1 else (lambda i: tuple(per_mode[:, i]))
    blur = _blur_samples(preset, signal, time_s, scene) if preset.motion_blur else None
    if preset.frames_format == "mraw":
        # 12-bit samples packed two in three bytes, as Photron's cameras save them; 8 in bytes, 16 in words.
        writer_cm = MrawWriter(path, preset.width, preset.height, fps, preset.bit_depth)
    elif preset.frames_format is not None:
        writer_cm = TiffSequenceWriter(path, preset.width, preset.height, fps)
    else:
        writer_cm = VideoWriter(path, preset.width, preset.height, fps, codec=preset.codec, bit_rate=preset.bit_rate,
                                preset=preset.x264_preset, gop=preset.gop)
    with writer_cm as writer:
        for i in range(n):
            if preset.readout_s > 0:
                row_t = _row_time_s(time_s[i], rows, preset)
                row_led = led_exposure_fraction(row_t, signal.t0_s, preset.exposure_s)
                row_gain = (lamp_gain(row_t, preset.exposure_s, preset.flicker_hz, preset.flicker_depth,
                                      phase) if flicker else None)
                writer.write(renderer.render_rolling(pitch_at(row_t), row_led, i, row_gain))
            elif blur is not None:
                sub_t, sub_pitch, sub_dt = blur[0][i], blur[1][i], blur[2]
                sub_led = led_exposure_fraction(sub_t, signal.t0_s, sub_dt)
                sub_gain = (lamp_gain(sub_t, sub_dt, preset.flicker_hz, preset.flicker_depth, phase)
                            if flicker else None)
                writer.write(renderer.render_blurred(sub_pitch, sub_led, i, sub_gain, tuple(shake[i]), float(roll[i]),
                                                     float(rock[i])))
            else:
                gain = float(lamp_gain(time_s[i], preset.exposure_s, preset.flicker_hz, preset.flicker_depth,
                                       phase)) if flicker else 1.0
                if preset.monochrome:
                    clean = renderer.composite(float(pitch[i]), float(led[i]), gain, tuple(shake[i]), float(roll[i]),
                                               float(rock[i]), frame_heave(i))
                    writer.write_gray(_gray_frame(clean, preset, noise_seed, i), preset.bit_depth)
                else:
                    writer.write(renderer.render(float(pitch[i]), float(led[i]), i, gain, tuple(shake[i]),
                                                 float(roll[i]), float(rock[i]), frame_heave(i)))
    rec: dict = {"kind": signal.kind}
    if signal.kind == "sine":
        rec["frequency_hz"] = signal.frequency_hz
    elif signal.kind == "sweep":
        rec.update(from_hz=signal.from_hz, to_hz=signal.to_hz, duration_s=signal.duration_s, shape=signal.shape)
    rec.update({
        "amplitude": signal.amplitude,
        "t0_s": signal.t0_s,
        "time_s": written_s.tolist(),
        # Only said when it differs from the timestamp (timestamp_at != "middle").
        **({"exposure_mid_s": time_s.tolist()} if centre_offset != 0.0 else {}),
        "angle_rad": angle.tolist(),
        "pitch_rad": pitch.tolist(),
        "pitch_at_frame_time_rad": pitch_instant.tolist(),
        "lead_xy_px": lead.tolist(),
        "trail_xy_px": trail.tolist(),
        # The extra stickers' centres at the pitch alone (shape (frames, k, 2)), as lead's and trail's.
        **({"extra_xy_px": extra_xy.tolist()} if extra_xy is not None else {}),
        "led_level": led.tolist(),
        **rolling,
        **({"shake_xy_px": shake.tolist()} if preset.shake_px > 0 else {}),
        **({"roll_rad": roll.tolist()} if preset.roll_rad != 0 else {}),
        **({"rock_rad": rock.tolist()} if preset.rock_rad != 0 else {}),
        **({"heave_px": heave.tolist()} if preset.blade_mode_hz > 0 else {}),
        **({"mode_heave_px": per_mode.tolist()} if len(per_mode) > 1 else {}),
        **({"blur_samples": int(blur[1].shape[1])} if blur is not None else {}),
    })
    return rec


def _gray_frame(clean_rgb: np.ndarray, preset: CampaignPreset, noise_seed: int, index: int) -> np.ndarray:
    """A monochrome camera's frame (:func:`~servoscope.simulate.render_parts.gray_frame`): the noise-free
    scene's luma at ``bit_depth`` bits scaled by ``light_level``, with ``noise_sigma_dn`` of 8-bit DN scaled to
    the depth, seeded per frame."""
    return gray_frame(clean_rgb, preset.bit_depth, preset.light_level, preset.noise_sigma_dn,
                      (noise_seed, 0x6A7, index))


def reference_stickers(scene: Scene) -> tuple[Clutter, Clutter]:
    """The airframe's two reference stickers: discs in the image's lower corners, far apart.

    Colours :data:`servoscope.defaults.REFERENCE_COLOURS`, diameter 1.3× the blade's stickers,
    centres 8 % of the width in from the sides and 10 % of the height up from the bottom:
    clear of the blade's swing, with a line as long as the blade stickers' so that it turns
    no less precisely.
    """
    d = 1.3 * scene.sticker_diameter_px
    y = 0.9 * scene.height
    return (Clutter(REFERENCE_COLOURS[0], (0.92 * scene.width, y), (d, d), shape="disc", airframe=True),
            Clutter(REFERENCE_COLOURS[1], (0.08 * scene.width, y), (d, d), shape="disc", airframe=True))


def _shake_px(preset: CampaignPreset, n: int, noise_seed: int) -> np.ndarray:
    """Per-frame translation of the whole picture (camera shake), recorded pixels, shape (n, 2).

    Seeded white noise smoothed by a Gaussian of ``shake_smooth_frames``,
    scaled to an RMS of ``shake_px`` per axis; zeros when ``shake_px`` is 0.
    """
    if preset.shake_px <= 0 or n == 0:
        return np.zeros((n, 2))
    # Its own stream (the test's noise seed, tagged): the other draws keep their values.
    rng = np.random.default_rng([noise_seed, 0x5EA4E])
    sigma = float(preset.shake_smooth_frames)
    pad = int(math.ceil(4 * sigma))
    white = rng.standard_normal((n + 2 * pad, 2))
    k = np.arange(-pad, pad + 1)
    kernel = np.exp(-0.5 * (k / sigma) ** 2)
    smooth = np.stack([np.convolve(white[:, a], kernel, mode="valid") for a in range(2)], axis=1)
    smooth -= smooth.mean(axis=0)
    rms = np.sqrt(np.mean(smooth**2, axis=0))
    return smooth * (preset.shake_px / np.where(rms > 0, rms, 1.0))


def _blur_samples(preset: CampaignPreset, signal: InputSignal, time_s: np.ndarray, scene: Scene
                  ) -> tuple[np.ndarray, np.ndarray, float]:
    """Sub-exposure instants and pitches for real motion blur: (times (n, m), pitches (n, m), sub-interval).

    ``m`` is chosen so that no blade point (the farthest, a chord from the
    pivot) moves more than ``blur_step_px`` between two samples in any frame,
    capped at ``blur_max_samples``; each sample is the pose at the middle of
    its sub-interval (exposure-averaged over the sub-interval's short span).
    """
    e = preset.exposure_s
    if e <= 0:
        return time_s[:, None], preset.servo.response(signal, time_s)[:, None], 0.0
    probe = 64
    edges = time_s[:, None] + e * (np.arange(probe + 1) / probe - 0.5)[None, :]
    p = preset.servo.response(signal, edges.ravel()).reshape(edges.shape)
    travel = float(np.max(np.sum(np.abs(np.diff(p, axis=1)), axis=1))) * scene.chord_px
    m = int(min(preset.blur_max_samples, max(1, math.ceil(travel / preset.blur_step_px))))
    sub_t = time_s[:, None] + e * ((np.arange(m) + 0.5) / m - 0.5)[None, :]
    sub_p = preset.servo.response(signal, sub_t.ravel()).reshape(sub_t.shape)
    return sub_t, sub_p, e / m


def _test_plan(p: CampaignPreset, suffix: str) -> list[tuple[str, str, float | None, float]]:
    """(video name, kind, frequency, amplitude) per test, in recording order: the dwells, a sweep, the step."""
    if p.sine_amplitudes:
        pairs = [(f, a) for f in p.frequencies_hz for a in p.sine_amplitudes]
        plan: list[tuple[str, str, float | None, float]] = [
            (f"dwell_{k + 1:02d}_{f:.2f}Hz_a{a:g}{suffix}", "sine", f, a) for k, (f, a) in enumerate(pairs)]
    else:
        plan = [(f"dwell_{k + 1:02d}_{f:.2f}Hz{suffix}", "sine", f, p.sine_amplitude)
                for k, f in enumerate(p.frequencies_hz)]
    if p.sweep is not None:
        plan.append((f"sweep_{p.sweep[0]:.2f}-{p.sweep[1]:.2f}Hz{suffix}", "sweep", None, p.sine_amplitude))
    if p.piloted_sweep is not None:
        lo, hi, _ = p.piloted_sweep
        plan.append((f"piloted_{lo:.2f}-{hi:.2f}Hz{suffix}", "piloted", None, p.sine_amplitude))
    if p.include_step:
        plan.append((f"step{suffix}", "step", None, p.step_amplitude))
    return plan


def _test_signal(p: CampaignPreset, kind: str, freq: float | None, amplitude: float, t0: float, seed: int = 0
                 ) -> tuple[InputSignal, float]:
    """A test's input starting at ``t0`` and the length of its video (``seed``: a piloted sweep's wander)."""
    if kind == "sine":
        signal = InputSignal("sine", amplitude, freq, t0_s=t0)
        duration = p.dwell_duration_s(freq, t0)
    elif kind == "sweep":
        signal = InputSignal("sweep", amplitude, t0_s=t0, from_hz=p.sweep[0], to_hz=p.sweep[1],
                             duration_s=p.sweep[2], shape=p.sweep_shape)
        duration = p.sweep_video_duration_s(t0)
    elif kind == "piloted":
        signal = InputSignal("recorded", amplitude, t0_s=t0, samples=pilot_input(*p.piloted_sweep, amplitude, seed))
        duration = p.sweep_video_duration_s(t0, p.piloted_sweep)
    else:
        signal = InputSignal("step", p.step_amplitude, t0_s=t0)
        duration = t0 + p.step_after_t0_s
    return signal, duration


def simulate_campaign(outdir: str | Path, preset: str = "paper", seed: int = 0, *,
                      progress: Callable[[int, int, str], None] | None = None, **overrides) -> Path:
    """Simulate a whole measurement campaign with a known answer.

    Parameters
    ----------
    outdir : str or Path
        Directory to write into (created if needed; our files are overwritten).
    preset : str
        Name of a preset in :data:`servoscope.simulate.PRESETS` ("paper", "quick").
    seed : int
        Seed of everything random: t0 phases, sensor noise, background.
    progress : callable, optional
        Called as ``progress(i, n, video_name)`` before test ``i`` of ``n``.
    **overrides
        Any :class:`~servoscope.simulate.presets.CampaignPreset` field, e.g.
        ``width=360, height=288, fps=50, codec="raw", bit_rate=8_000_000,
        noise_sigma_dn=0, frequencies_hz=(1.0, 2.0), servo=ServoModel(...)``;
        ``readout_s=0.015`` (with ``fps=50, exposure_s=0.02``) films with a
        rolling shutter (see docs/twin.md); ``sweep=(from_hz, to_hz, duration_s)``
        (and ``sweep_shape="linear"``) adds a frequency-sweep test;
        ``piloted_sweep=(from_hz, to_hz, duration_s)`` a pilot's sweep, recorded as ``u.csv``.

    Returns
    -------
    Path
        The written ``campaign.toml``.

    Raises
    ------
    ServoscopeError
        Unknown preset or override, or invalid settings.
    """
    if preset in ROTOR_PRESETS:  # a turning rotor (issue 33): its own renderer and truth
        return simulate_rotor_campaign(outdir, preset, seed, progress=progress, **overrides)
    base = get_preset(preset)
    allowed = {f.name for f in fields(CampaignPreset)} - {"name"}
    # Scene settings (clutter, sticker_shape, ...) go to the scene.
    scene_fields = {f.name for f in fields(Scene)} - {"width", "height"}
    scene_kw = {k: overrides.pop(k) for k in list(overrides) if k in scene_fields and k not in allowed}
    unknown = set(overrides) - allowed
    if unknown:
        raise ServoscopeError(f"unknown simulation setting(s) {sorted(unknown)} (known: {', '.join(sorted(allowed))})")
    if int(seed) != seed or seed < 0:
        raise ServoscopeError(f"seed must be a non-negative integer, not {seed!r}")
    seed = int(seed)
    p = replace(base, **overrides)
    if p.flicker_depth > 0 and p.flicker_phase_rad is None:
        # Its own stream: the tests' t0 phases and noise seeds keep their values.
        p = replace(p, flicker_phase_rad=float(np.random.default_rng([seed, 0xF11C]).uniform(0.0, 2.0 * np.pi)))
    suffix = "" if p.frames_format is not None else container_suffixes(p.codec)[0]  # a folder of frames
    fps = Fraction(p.fps).limit_denominator(1_000_000)
    if p.scene is not None:
        scene = replace(p.scene, **scene_kw) if scene_kw else p.scene
    else:
        scene = Scene.for_size(p.width, p.height, **{"background_seed": seed, **scene_kw})
    if p.reference_stickers:
        scene = replace(scene, clutter=tuple(scene.clutter) + reference_stickers(scene))
    scene = led_placed(p, replace(scene, extra_stickers=p.extra_stickers) if p.extra_stickers else scene)
    if p.monochrome and scene.extra_stickers:
        raise ServoscopeError("extra_stickers are told by colour: the twin's monochrome camera films two white dots "
                              "(leave out extra_stickers or monochrome)")
    if p.monochrome and "lead_colour" not in scene_kw and "trail_colour" not in scene_kw:
        # White dots on the dark blade: what a monochrome camera's users stick on.
        scene = replace(scene, lead_colour="#f4f4f4", trail_colour="#f4f4f4")
    camera = p.camera()

    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)

    plan = _test_plan(p, suffix)
    streams = np.random.SeedSequence(seed).spawn(len(plan))

    tests = []
    for k, ((name, kind, freq, amplitude), ss) in enumerate(zip(plan, streams)):
        if progress is not None:
            progress(k, len(plan), name)
        rng = np.random.default_rng(ss)
        # t0 falls a random fraction into a frame interval, as for a camera
        # that is not synchronised with the input (kept off the exact frame
        # times). When the switch falls inside an exposure the partly lit LED
        # frame dates it; when it falls between exposures it is only known
        # to within the gap, 1/fps - exposure_s.
        frac = rng.uniform(0.02, 0.98)
        if p.t0_frame_phase is not None:
            frac = p.t0_frame_phase  # drawn all the same: the noise seeds keep their values
        t0 = float((round(p.pre_roll_s * fps) + frac) / fps)
        noise_seed = int(rng.integers(0, 2**63 - 1))
        # Drawn only for a piloted sweep, after the noise seed: the other tests' draws keep their values.
        pilot_seed = int(rng.integers(0, 2**63 - 1)) if kind == "piloted" else 0
        signal, duration = _test_signal(p, kind, freq, amplitude, t0, pilot_seed)
        rec = render_test(out / name, p, scene, signal, duration, noise_seed)
        if kind == "piloted":
            rec.update(record_pilot(out, p.piloted_sweep, signal.samples))
        tests.append({"video": name, **rec})

    truth = _truth(p, seed, camera, fps, scene, tests)
    if p.view() is not None:
        truth["board"] = _write_board(out / "board.png", p, scene, camera, seed)
    camera.save(out / "camera.json")
    write_text_atomic(out / "truth.json", json.dumps(truth, allow_nan=False) + "\n")
    toml_path = out / "campaign.toml"
    twin_campaign(p, scene, tests, toml_path, fps if p.frames_format is not None else None).save(
        toml_path, header=TWIN_HEADER)
    return toml_path


def _write_board(path: Path, p: CampaignPreset, scene: Scene, camera, seed: int) -> dict:
    """Photograph a chessboard lying in the blade's plane through the campaign's view and lens; its truth.

    Its noise comes from its own stream of the campaign seed (the tests' draws keep their values);
    a monochrome camera's photo is the luma, in three equal channels.
    """
    board_seed = int(np.random.default_rng([seed, 0xB0A2D]).integers(0, 2**63 - 1))
    image, board = render_board_photo(scene, p.view(), camera, noise_sigma_dn=p.noise_sigma_dn, seed=board_seed)
    if p.monochrome:
        image = np.repeat(np.rint(luma_bt601(image)).astype(np.uint8)[..., None], 3, axis=2)
    with atomic_path(path) as tmp:
        if not cv2.imwrite(str(tmp), np.ascontiguousarray(image[..., ::-1])):  # OpenCV writes BGR
            raise ServoscopeError(f"could not write {path}")
    return {"file": path.name, **board}


def _truth(p: CampaignPreset, seed: int, camera, fps: Fraction, scene: Scene, tests: list[dict]) -> dict:
    s = p.servo
    steps = step_metrics(s)
    steps["dead_time_s"] = s.dead_time_s
    return {
        "preset": p.name,
        "seed": seed,
        "model": s.truth(),
        "bandwidth_rad_s": s.bandwidth_rad_s,
        "step": steps,
        "camera": camera.to_dict(),
        "video": {
            "codec": p.codec, "bit_rate": p.bit_rate if p.codec in LOSSY else None, "gop": p.gop, "fps": float(fps),
            "fps_rational": [fps.numerator, fps.denominator], "exposure_s": p.exposure_s,
            "noise_sigma_dn": p.noise_sigma_dn, "width": p.width, "height": p.height,
            # Only a rolling shutter is said: a global shutter's truth stays as it was.
            **({"readout_s": p.readout_s} if p.readout_s > 0 else {}),
            # Real-camera options, only when set (default truth unchanged).
            **{k: getattr(p, k) for k in ("flicker_hz", "flicker_depth", "flicker_phase_rad", "shake_px", "shake_smooth_frames",
                                          "t0_frame_phase", "motion_blur", "timestamp_at", "manifest_exposure",
                                          "frames_format", "roll_rad", "roll_hz", "rock_rad", "rock_hz",
                                          "reference_stickers", "monochrome", "sine_amplitudes",
                                          "blade_mode_hz", "blade_mode_damping", "blade_mode_px_per_rad",
                                          "blade_mode_bend", "blade_mode2", "bit_depth", "view_yaw_deg",
                                          "view_tilt_deg", "light_level")
               if getattr(p, k) != getattr(_DEFAULT, k)},
        },
        # An oblique camera: the homography from the plane, where truth's positions and angles are.
        **({"view": {**p.view().to_dict(), "plane_mm_per_px": PLANE_MM_PER_PX,
                     "coordinates": "lead_xy_px, trail_xy_px, extra_xy_px and angle_rad are in the blade's plane "
                                    "(plane px); the recorded picture is homography_plane_to_image, then the lens"}}
           if p.view() is not None else {}),
        "sticker_offset_rad": scene.sticker_offset_rad,
        # Only an LED off the blade (or its look-alikes) is said: the default truth stays as it was.
        **({"led": {"place": p.led_place, "xy_px": None if scene.led_fixed_px is None else list(scene.led_fixed_px),
                    "diameter_px": scene.led_diameter_px,
                    "distractors": [{"kind": k, "xy_px": list(c.centre_px)}
                                    for k, c in zip(("glint", "screw"), led_distractors(scene))]
                    if p.led_distractors else []}}
           if p.led_place != "blade" or p.led_distractors else {}),
        **({"extra_stickers": [{"colour": c, "position": f} for c, f in scene.extra_stickers]}
           if scene.extra_stickers else {}),
        **({"modes": [{"frequency_hz": hz, "damping_ratio": z, "heave_px_per_rad": k,
                       **({"shape": _shape_truth(scene, bend)} if scene.extra_stickers or bend else {})}
                      for hz, z, k, bend in blade_modes_of(p)]} if p.blade_mode_hz > 0 else {}),
        "input_units": p.input_units,
        "tests": [_with_steady_heave(p, t) for t in tests] if p.blade_mode_hz > 0 else tests,
    }


def _with_steady_heave(p: CampaignPreset, test: dict) -> dict:
    """A sine test's truth with the blade's steady heave at its frequency (``heave_steady``: px per input unit and
    degrees against the input), beside its whole trace (``heave_px``): what a dwell long enough would show."""
    if test.get("kind") != "sine":
        return test
    z = steady_heave(p, test["frequency_hz"])
    return {**test, "heave_steady": {"gain_px_per_unit": abs(z), "phase_deg": math.degrees(cmath.phase(z))}}


def led_placed(p: CampaignPreset, scene: Scene) -> Scene:
    """The scene with the LED where ``p`` puts it (on the blade or fixed to the stand) and its look-alikes."""
    if p.led_place == "stand":
        trail = scene.sticker_centres_px(0.0)[1]
        xy = p.led_xy_px if p.led_xy_px is not None else (float(trail[0]), 0.2 * scene.height)
        scene = replace(scene, led_fixed_px=xy)
    if p.led_distractors:
        scene = replace(scene, clutter=tuple(scene.clutter) + led_distractors(scene))
    return scene


def led_distractors(scene: Scene) -> tuple[Clutter, Clutter]:
    """What an LED is taken for: a glint by the hub (the LED's hue, brighter and larger than it) just above
    the blade at its pivot, and a screw head on the stand (brighter than the LED's off level) beside the LED."""
    d = scene.led_diameter_px
    px, py = scene.pivot_xy_px
    glint = Clutter("#ffe040", (px, py - 0.5 * scene.thickness_ratio * scene.chord_px - 1.5 * d - 3.0),
                    (1.7 * d, 1.5 * d), shape="disc")
    led = scene.led_centre_px(0.0)
    screw = Clutter("#c4c4c4", (float(led[0]) + 4.0 * d, float(led[1])), (0.9 * d, 0.9 * d), shape="disc")
    return glint, screw


def _shape_truth(scene: Scene, bend: float) -> dict:
    shape = mode_shape(scene, bend)
    return {"lead": shape[0], "trail": shape[1], "extra": list(shape[2:])}
