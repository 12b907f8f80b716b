"""A simulated campaign of the turning rotor (issue 33): videos, campaign.toml with ``[rotor]``, truth.json.

:func:`~servoscope.simulate.simulate_campaign` hands a rotor preset (:data:`ROTOR_PRESETS`) to
:func:`simulate_rotor_campaign`. Each test (the dwells, then the step) is one recording of the
rotor turning at its speed, its phase at the video's start drawn from the campaign seed, the
servo driving the collective from the input's start (which the airframe's LED marks, as in the
static twin). Its truth is the pass table (:func:`~servoscope.simulate.rotor_render.render_rotor_clip`)
and the rotor's mean speed; :func:`rotor_rig_of_test` rebuilds a test's rig from truth.json, whose
``azimuth_rad(t, blade)`` gives any blade's azimuth at any time.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, fields, replace
from fractions import Fraction
from pathlib import Path

import numpy as np

from .._io import write_text_atomic
from ..camera.model import CameraModel
from ..campaign.sections import RotorSpec
from ..errors import ServoscopeError
from ..video.writer import container_suffixes
from .manifest import TWIN_HEADER, twin_campaign
from .presets import PAPER_SERVO, CampaignPreset
from .rotor import RotorRig
from .rotor_render import RotorRenderer, render_rotor_clip
from .servo import InputSignal

__all__ = ["RotorPreset", "ROTOR_PRESETS", "simulate_rotor_campaign", "rotor_rig_of_test"]

#: The static preset's settings a rotor campaign takes; the rest (rolling shutter, shake, views, flapping …) are
#: the static twin's own.
_CAMPAIGN_KEYS = {"servo", "frequencies_hz", "sine_amplitude", "step_amplitude", "input_units", "include_step",
                  "width", "height", "fps", "codec", "bit_rate", "x264_preset", "noise_sigma_dn", "exposure_s",
                  "pre_roll_s", "settle_s", "min_dwell_s", "min_periods", "step_after_t0_s", "monochrome", "bit_depth",
                  "light_level", "frames_format", "t0_frame_phase", "manifest_exposure"}
_RIG_KEYS = {f.name for f in fields(RotorRig)} - {"azimuth0_rad", "drift_phase_rad"}


@dataclass(frozen=True)
class RotorPreset:
    """A named rotor campaign: the servo, the tests and the camera (a :class:`CampaignPreset`'s) and the rotor.

    Parameters
    ----------
    name : str
    campaign : CampaignPreset
        The servo, the dwells and the step, the video's size, rate, shutter, codec and noise.
    rig : RotorRig
        The rotor; each test draws its own phase (``azimuth0_rad``) and speed wander's phase from the seed.
    """

    name: str
    campaign: CampaignPreset
    rig: RotorRig


# The paper's servo on a two-bladed rotor at 20 rev/s, filmed at 4,000 frames/s through a 1/40,000 s shutter,
# 320×240, H.264 at 40 Mbit/s (1.2 kB a frame; at 8 Mbit/s a frame's angle is twice as noisy): each pass
# lasts ~12 frames. The pass rate is 40/s, its Nyquist 20 Hz: the dwells reach 14 Hz (70 %). Blade 1 is
# rigged 0.2° above blade 0. Dwells short (a high-speed camera's memory holds seconds).
ROTOR_PRESETS: dict[str, RotorPreset] = {
    "paper-rotor": RotorPreset(
        name="paper-rotor",
        campaign=CampaignPreset(name="paper-rotor", servo=PAPER_SERVO, frequencies_hz=(3.0, 6.0, 10.0, 14.0),
                                width=320, height=240, fps=4000, exposure_s=1.0 / 40000, bit_rate=40_000_000,
                                pre_roll_s=0.1, settle_s=0.3, min_dwell_s=0.5, min_periods=3.0,
                                step_after_t0_s=0.5),
        rig=RotorRig(rev_per_s=20.0, blade_offsets_rad=(0.0, math.radians(0.2))),
    ),
}


def _test_plan(p: CampaignPreset, suffix: str) -> list[tuple[str, str, float | None, float]]:
    """(recording name, kind, frequency, amplitude) per test in recording order: the dwells, then the step."""
    plan: list[tuple[str, str, float | None, float]] = [
        (f"rotor_dwell_{k + 1:02d}_{f:.2f}Hz{suffix}", "sine", f, p.sine_amplitude)
        for k, f in enumerate(p.frequencies_hz)]
    if p.include_step:
        plan.append((f"rotor_step{suffix}", "step", None, p.step_amplitude))
    return plan


def _split_overrides(base: RotorPreset, overrides: dict) -> RotorPreset:
    """The preset with ``overrides`` applied, each to the campaign's or the rig's settings; one error for the rest."""
    unknown = sorted(set(overrides) - _CAMPAIGN_KEYS - _RIG_KEYS)
    if unknown:
        raise ServoscopeError(f"the rotor twin ({base.name}) does not take {', '.join(unknown)} (it takes: "
                              f"{', '.join(sorted(_CAMPAIGN_KEYS | _RIG_KEYS))})")
    camp = {k: v for k, v in overrides.items() if k in _CAMPAIGN_KEYS}
    rig = {k: v for k, v in overrides.items() if k in _RIG_KEYS}
    if "monochrome" in camp and camp["monochrome"] and "frames_format" not in camp:
        camp["frames_format"] = "mraw"  # a monochrome high-speed camera's own file
    if camp.get("monochrome") and "bit_depth" not in camp:
        camp["bit_depth"] = 12
    return replace(base, campaign=replace(base.campaign, **camp), rig=replace(base.rig, **rig))


def rotor_rig_of_test(truth: dict, test: int | dict) -> RotorRig:
    """The rig a rotor campaign's test was filmed with, from its ``truth.json`` (a dict): ``.azimuth_rad(t, b)`` then
    gives blade b's azimuth at any time of that test's video."""
    rec = truth["tests"][test] if isinstance(test, int) else test
    rotor = dict(truth["rotor"])
    rotor["blades"] = tuple(tuple(b) for b in rotor["blades"])
    rotor["blade_offsets_rad"] = tuple(rotor["blade_offsets_rad"])
    rotor["sticker_chord_fractions"] = tuple(rotor["sticker_chord_fractions"])
    return RotorRig(**rotor, azimuth0_rad=rec["azimuth0_rad"], drift_phase_rad=rec["drift_phase_rad"])


def simulate_rotor_campaign(outdir: str | Path, preset: str = "paper-rotor", seed: int = 0, *,
                            progress: Callable[[int, int, str], None] | None = None, **overrides) -> Path:
    """Simulate a rotor campaign with a known answer (see the module); returns the written ``campaign.toml``.

    Parameters
    ----------
    outdir : str or Path
    preset : str
        A name in :data:`ROTOR_PRESETS`.
    seed : int
        Seed of everything random: the input's start within a frame, the rotor's phase and its speed wander's,
        the sensor noise, the background.
    progress : callable, optional
        ``progress(i, n, name)`` before test ``i`` of ``n``.
    **overrides
        The campaign's settings (``fps``, ``exposure_s``, ``width``, ``height``, ``codec``, ``frequencies_hz``,
        ``monochrome`` (a 12-bit MRAW per test) …) or the rig's (``blades``, ``rev_per_s``, ``blade_offsets_rad``,
        ``cyclic_rad`` …).
    """
    if preset not in ROTOR_PRESETS:
        raise ServoscopeError(f"unknown rotor preset {preset!r} (choose from {', '.join(sorted(ROTOR_PRESETS))})")
    if int(seed) != seed or seed < 0:
        raise ServoscopeError(f"seed must be a non-negative integer, not {seed!r}")
    seed = int(seed)
    rp = _split_overrides(ROTOR_PRESETS[preset], dict(overrides))
    p, rig = rp.campaign, rp.rig
    if p.monochrome and p.frames_format != "mraw":
        raise ServoscopeError("the rotor twin's monochrome camera writes an MRAW (frames_format='mraw')")
    fps = Fraction(p.fps).limit_denominator(1_000_000)
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    # Raw (lossless) colour in NUT: AVI's container cannot time a high-speed camera's frames (4,000 frames/s).
    suffix = "" if p.monochrome else ".nut" if p.codec == "raw" else container_suffixes(p.codec)[0]
    plan = _test_plan(p, suffix)
    streams = np.random.SeedSequence(seed).spawn(len(plan))
    tests = []
    for k, ((name, kind, freq, amplitude), ss) in enumerate(zip(plan, streams)):
        if progress is not None:
            progress(k, len(plan), name)
        rng = np.random.default_rng(ss)
        frac = rng.uniform(0.02, 0.98) if p.t0_frame_phase is None else p.t0_frame_phase
        t0 = float((round(p.pre_roll_s * fps) + frac) / fps)
        noise_seed = int(rng.integers(0, 2**63 - 1))
        test_rig = replace(rig, azimuth0_rad=float(rng.uniform(0.0, 2.0 * np.pi)),
                           drift_phase_rad=float(rng.uniform(0.0, 2.0 * np.pi)))
        if kind == "sine":
            signal = InputSignal("sine", amplitude, freq, t0_s=t0)
            duration = p.dwell_duration_s(freq, t0)
        else:
            signal = InputSignal("step", amplitude, t0_s=t0)
            duration = t0 + p.step_after_t0_s
        rec = render_rotor_clip(out / name, test_rig, lambda t, s=signal: p.servo.response(s, np.asarray(t)),
                                duration, fps=fps, exposure_s=p.exposure_s, width=p.width, height=p.height,
                                led_off_s=t0, codec=p.codec, bit_rate=p.bit_rate, x264_preset=p.x264_preset,
                                monochrome=p.monochrome, bit_depth=p.bit_depth, light_level=p.light_level,
                                noise_sigma_dn=p.noise_sigma_dn, noise_seed=noise_seed, background_seed=seed)
        tests.append({"video": name, "kind": kind, **({"frequency_hz": freq} if kind == "sine" else {}),
                      "amplitude": amplitude, "t0_s": t0, "n_frames": len(rec["time_s"]),
                      "rev_per_s": rec["rev_per_s"], "azimuth0_rad": test_rig.azimuth0_rad,
                      "drift_phase_rad": test_rig.drift_phase_rad, "blur_samples": rec["blur_samples"],
                      "passes": rec["passes"]})
    camera = CameraModel((p.width, p.height), np.array([[rig.focal_length_px, 0.0, 0.5 * (p.width - 1)],
                                                        [0.0, rig.focal_length_px, 0.5 * (p.height - 1)],
                                                        [0.0, 0.0, 1.0]]), np.zeros(5))
    camera.save(out / "camera.json")
    write_text_atomic(out / "truth.json", json.dumps(_truth(rp, seed, fps, tests), allow_nan=False) + "\n")
    toml_path = out / "campaign.toml"
    _manifest(rp, tests, toml_path, fps).save(toml_path, header=TWIN_HEADER)
    return toml_path


def _manifest(rp: RotorPreset, tests: list[dict], path: Path, fps: Fraction):
    """The campaign.toml: the static twin's (markers: blade 0's stickers and the LED), with ``[rotor]``."""
    p, rig = rp.campaign, rp.rig
    scene = replace(RotorRenderer(rig, p.width, p.height, exposure_s=0.0).scene, lead_colour=rig.blades[0][0],
                    trail_colour=rig.blades[0][1])
    campaign = twin_campaign(p, scene, tests, path, fps if p.monochrome else None)
    # A monochrome camera tells every sticker by its brightness, as the static twin's [markers] says.
    blades = tuple(("bright", "bright") if p.monochrome else b for b in rig.blades)
    # The dwells' settling time is the preset's (the static twin's manifests leave [analysis] at the default).
    rotor = RotorSpec(blades=blades, rev_per_s=float(rig.rev_per_s), camera_distance_m=float(rig.camera_distance_m),
                      tip_radius_m=float(rig.tip_radius_m))
    return replace(campaign, settle_s=float(p.settle_s), settle_stated=True, rotor=rotor)


def _truth(rp: RotorPreset, seed: int, fps: Fraction, tests: list[dict]) -> dict:
    p, rig, s = rp.campaign, rp.rig, rp.campaign.servo
    rotor = {k: v for k, v in asdict(rig).items() if k not in ("azimuth0_rad", "drift_phase_rad")}
    return {
        "preset": rp.name,
        "seed": seed,
        "model": s.truth(),
        "video": {"codec": "mraw" if p.monochrome else p.codec, "fps": float(fps),
                  "fps_rational": [fps.numerator, fps.denominator], "exposure_s": p.exposure_s,
                  "noise_sigma_dn": p.noise_sigma_dn, "width": p.width, "height": p.height,
                  **({"monochrome": True, "bit_depth": p.bit_depth} if p.monochrome else {})},
        # The rig (each test's azimuth0_rad and drift_phase_rad are its own): rotor_rig_of_test(truth, i).
        "rotor": rotor,
        "azimuth": "blade b's azimuth (rad, 0 mod 2π pointing at the camera): "
                   "servoscope.simulate.rotor_campaign.rotor_rig_of_test(truth, test).azimuth_rad(t, b)",
        "input_units": p.input_units,
        "tests": tests,
    }
