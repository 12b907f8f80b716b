"""A campaign's sine dwells: each one's fit, their frequency response, the fit's mode, the amplitude checks.

Steps of :func:`servoscope.campaign.runner.identify`, each on the dwells alone.
"""

from __future__ import annotations

import numpy as np

from ..camera.exposure import ExposureEstimate
from ..errors import ServoscopeError
from ..markers.track import Track
from ..sysid import FrequencyResponse, SineFit, fit_sine, gain_against_amplitude, rigid_motion_null
from .manifest import Campaign, TestSpec
from .result import input_start, input_start_stderr

__all__ = ["amplitude_checks", "dwell_response", "exposure_corrected", "exposure_undone", "fit_dwell", "fit_dwells", "fit_mode"]


def fit_dwell(campaign: Campaign, test: TestSpec, track: Track, own_t0_stderr: dict[str, float],
               warnings: list[str]) -> SineFit | None:
    """One dwell's sine fit; None (with a warning) when it is left out."""
    t0 = input_start(test, track)
    if t0 is None:
        warnings.append(f"{test.label}: no input start (LED or t0_s): phase unknown, steady state taken from the first frame")
    if track.n_valid < 5:
        warnings.append(f"{test.label}: only {track.n_valid} valid frames; dwell left out")
        return None
    try:
        return fit_sine(
            # When each angle was sampled (a rolling shutter's rows lag the frame time).
            track.angle_time_s,
            track.angle_rad,
            test.frequency_hz,
            t0_s=t0,
            # Each dwell's whole t0 error; the part they may share is added to the dead time (identify).
            t0_stderr_s=own_t0_stderr.get(test.label, input_start_stderr(test, track)),
            settle_s=campaign.settle_s,
            valid=track.valid,
            # Harmonics the two markers do not share are tracking
            # artefacts, not distortion (sysid.sine.rigid_motion_null).
            null_channel=rigid_motion_null(track.lead_xy_px, track.trail_xy_px, track.valid),
            # The codec check: I-frames show the motion without the codec's prediction.
            intra=track.intra,
        )
    except ServoscopeError as exc:
        warnings.append(f"{test.label}: dwell left out: {exc}")
        return None


def fit_dwells(campaign: Campaign, tracks: dict[str, Track], own_t0_stderr: dict[str, float], order,
                warnings: list[str], sweep_points: int = 0) -> tuple[dict[str, SineFit], list[float]]:
    """Every sine dwell's fit, in manifest order, and its input amplitude; refused with fewer than 3 points
    (the dwells' and `sweep_points`, the sweeps' frequencies with coherence ≥ 0.6)."""
    fits: dict[str, SineFit] = {}
    amplitudes = []
    for test in campaign.sine_tests:
        sine_fit = fit_dwell(campaign, test, tracks[test.label], own_t0_stderr, warnings)
        if sine_fit is not None:
            fits[test.label] = sine_fit
            amplitudes.append(test.amplitude)
    if len(fits) + sweep_points < 3:
        asked = "its order chosen from the data" if order == "auto" else f"order (nb, na) = {order}"
        sweeps = f" and {sweep_points} coherent sweep frequenc{'y' if sweep_points == 1 else 'ies'}" \
            if campaign.sweep_tests else ""
        raise ServoscopeError(
            f"{campaign.path}: only {len(fits)} sine dwell(s){sweeps} could be fitted; identify fits a model "
            f"({asked}) to 3 or more frequencies, whatever its order (the warnings say why each test was left out)"
        )
    return fits, amplitudes


def dwell_response(campaign: Campaign, fits: dict[str, SineFit], amplitudes: list[float],
                        exposure: ExposureEstimate) -> FrequencyResponse:
    """The dwells' frequency response, corrected for the exposure given or seen in the blur."""
    return exposure_corrected(campaign, FrequencyResponse.from_sine_fits(list(fits.values()), np.asarray(amplitudes),
                                                                         list(fits)), exposure)


def exposure_undone(campaign: Campaign, exposure: ExposureEstimate | None) -> tuple[float, float]:
    """The exposure whose averaging the frequency response undoes, and its standard error (s): the one given,
    else the one seen in the blur, else none (0, 0)."""
    if campaign.exposure_s is not None:
        return float(campaign.exposure_s), 0.0
    if exposure is not None and exposure.known and "blur" in exposure.source:
        # Seen in the blur: a long shutter (a full frame at 100 frames/s takes 3.7 % off a 12 Hz
        # dwell), corrected with its uncertainty. Not the LED's estimate alone: the LED
        # says most when the shutter is short, where the correction is a few per mille.
        return float(exposure.value_s), float(exposure.stderr_s)
    return 0.0, 0.0


def exposure_corrected(campaign: Campaign, fr: FrequencyResponse, exposure: ExposureEstimate) -> FrequencyResponse:
    """`fr` corrected for the exposure given or seen in the blur (the dwells' and the sweeps' alike,
    :func:`exposure_undone`)."""
    e, se = exposure_undone(campaign, exposure)
    return fr.corrected_for_exposure(e, se) if e > 0 else fr


def fit_mode(fit: str, fr: FrequencyResponse, campaign: Campaign) -> str:
    """"complex" or "magnitude": the fit asked, "auto" complex when every dwell's phase is known."""
    if fit not in ("auto", "magnitude", "complex"):
        raise ServoscopeError(f"fit: unknown mode {fit!r} (use auto, magnitude or complex)")
    phases_known = bool(np.all(np.isfinite(fr.phase_deg)))
    if fit == "complex" and not phases_known:
        raise ServoscopeError(
            f"{campaign.path}: a complex fit needs every dwell's input start (an LED or t0_s); use --fit magnitude"
        )
    return "complex" if fit == "complex" or (fit == "auto" and phases_known) else "magnitude"


def amplitude_checks(fr: FrequencyResponse, fits: dict[str, SineFit], amplitudes: list[float],
                      tracks: dict[str, Track]) -> list:
    """Amplitude as a test axis: one frequency's dwells at several amplitudes must agree if the servo is linear."""
    # The response is sorted by frequency: each dwell's amplitude and systematic error go by its label.
    input_amplitude = dict(zip(fits, amplitudes))
    systematic = {}
    for label, sine_fit in fits.items():
        noise = tracks[label].summary().get("angle_noise_measured_rad")
        systematic[label] = noise / sine_fit.amplitude if noise and sine_fit.amplitude > 0 else 0.0
    return gain_against_amplitude(fr, [input_amplitude[label] for label in fr.labels],
                                  [systematic[label] for label in fr.labels])
