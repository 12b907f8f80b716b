"""Running a campaign: track every video, fit every dwell, identify the model.

Stages run in the pipeline's order (video → markers → camera → angles →
sysid) and the result carries every intermediate, so that a report, a
notebook or a test can look at any of them.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import Callable, NamedTuple

import numpy as np

from ..angle.pivot import axis_moved
from ..camera.exposure import ExposureEstimate, blur_evidence, estimate_exposure, pool_blur
from ..errors import ServoscopeError
from ..markers.settings import TrackerSettings
from ..markers.track import Track
from ..parameters import interval95
from ..sysid import FrequencyResponse, SineFit, check_held, fit_transfer_function, with_gain_scale_uncertainty
from ..sysid.dead_time import dead_time_estimates
from .blade import axis_of, bending_response, blade_modes, dwell_modes, flapping, step_ringdown_warning
from .dwells import amplitude_checks, dwell_response, exposure_corrected, fit_dwells, fit_mode
from .joint import check_nonlinear, predicted_step_fit_percent, servo_model, split_held
from .manifest import Campaign, TestSpec, load_campaign
from .plane_check import campaign_in_view, plane_summary
from .rotor import (codec_warning, pass_track, rotor_dwell_fits, rotor_step, rotor_summary, rotor_systematics,
                    track_rotor_campaign)
from .result import IdentificationResult
from .step_test import step_test
from .sweeps import combined_response, sweep_responses, sweeps_t0_stderr

__all__ = ["IdentificationResult", "checked_holds", "identify", "led_coverage_warning", "track_campaign"]

ProgressFn = Callable[[str, int, int], None]


def _settings(campaign: Campaign) -> TrackerSettings:
    return TrackerSettings(
        lead=campaign.lead,
        trail=campaign.trail,
        led=campaign.led,
        camera=campaign.camera,
        exposure_s=campaign.exposure_s,
        readout_s=campaign.readout_s,
        lead_near=campaign.lead_near,
        trail_near=campaign.trail_near,
        led_near=campaign.led_near,
        timestamp=campaign.timestamp,
        reference=campaign.reference,
        extra=campaign.extra,
        plane=campaign.plane,
    )


def track_campaign(
    campaign: Campaign, *, keep_going: bool = False, failures: dict[str, str] | None = None,
    progress: ProgressFn | None = None, workers: int | None = None, scheduler: str | None = None,
    cache_dir: str | Path | None = None, force: bool = False,
    on_done: Callable[[str, str], None] | None = None,
) -> dict[str, Track]:
    """Track every video of a campaign; tracks returned in manifest order.

    Parameters
    ----------
    campaign : Campaign
    keep_going : bool
        A video that fails (unreadable, markers not found) is left out and
        its reason stored in ``failures``, instead of raising.
    failures : dict, optional
        Filled with label → reason for the videos left out.
    progress : callable(label, frames_done, test_index), optional
    fix, bounds : dict, optional
        Model parameters held at a value or within limits (see
        :func:`~servoscope.sysid.fit_transfer_function`); they add to (and
        override) the manifest's ``[model]`` section.
        In-process: every 50 frames and at each video's end; on Dask: once
        per video, as its track arrives.
    workers : int or None
        None (default): one worker per core. N > 1: a local Dask cluster of
        N worker processes, each given cores / N threads (decoder, OpenCV);
        on Linux they are forked from this process and start in ~0.2 s.
        1: one video after the other in this process, no Dask. A campaign
        with a single video left to track is tracked in this process.
    scheduler : str, optional
        Address of a running Dask scheduler (``"tcp://host:8786"``); its
        workers must see the videos at the same paths.
    cache_dir : path-like, optional
        Keep each track there (e.g. ``<out>/.cache``), keyed by the video's
        content hash and the tracking settings, and reuse it on the next
        run; see :mod:`servoscope.campaign.cache`.
    force : bool
        Track again even what is cached.
    on_done : callable(label, status), optional
        Once per video as it completes: status "cached", "tracked" or "failed".

    Returns
    -------
    dict of label → Track

    Notes
    -----
    The tracks do not depend on ``workers``, ``scheduler`` or the cache:
    they are bit-identical whichever way they were made.
    """
    from .cache import TrackCache  # deferred: only this function needs them
    from .parallel import track_many

    cache = TrackCache(cache_dir) if cache_dir is not None else None
    tracks, failed = track_many(
        campaign.tests, _settings(campaign), workers=workers, scheduler=scheduler, cache=cache, force=force,
        keep_going=keep_going, progress=progress, on_done=on_done,
    )
    if failures is not None:
        failures.update(failed)
    return tracks


def led_coverage_warning(campaign: Campaign, tracks: dict[str, Track]) -> str | None:
    """A warning when the LED's switch was found in some of a campaign's videos but not in others.

    One LED on one blade switches in every video of a campaign; where it was
    not found, that video has no input start (no phase, no dead time) and the
    identification silently rests on the others. Videos given a ``t0_s`` in
    the manifest do not need the LED and are not counted.

    Returns
    -------
    str or None
        None when the campaign has no LED, or the LED was found in all or none of its videos.
    """
    if campaign.led is None:
        return None
    need = [t.label for t in campaign.tests if t.t0_s is None and t.label in tracks]
    missing = [label for label in need if tracks[label].t0_s is None]
    if not missing or len(missing) == len(need):
        return None
    found = len(need) - len(missing)
    return (f"LED found in {found} of {len(need)} videos but not in {len(missing)}: {', '.join(missing)}; these have "
            "no input start, so no phase and no dead time from them (each video's own warning says why; check the "
            "LED colour, or give their t0_s in the manifest)")


def pivot_warning(campaign: Campaign, tracks: dict[str, Track]) -> str | None:
    """A warning when the blade's axis moved in the picture and no reference stickers take a turn off the angle.

    See :mod:`servoscope.angle.pivot`: a camera that rolls, or an airframe that rocks, moves the
    axis and turns the picture; the angle then holds the turn.
    """
    if campaign.reference is not None:
        return None
    moved = []
    for test in campaign.tests:
        track = tracks.get(test.label)
        if track is None:
            continue
        pivot = axis_moved(track)
        if pivot is not None:
            moved.append(f"{test.label} {pivot.rms_px:.2f} px")
    if not moved:
        return None
    return (f"the blade's pitch axis moved in the picture ({', '.join(moved)} RMS): the camera shook or rolled, or the "
            "airframe rocked; a shake leaves the angle alone but a turn of the camera or the airframe is read as "
            "pitch: film two stickers on the airframe and name them in [markers] reference")


def campaign_exposure(campaign: Campaign, tracks: dict[str, Track]) -> ExposureEstimate:
    """The campaign's exposure: the one given, else what its LED switches and motion blur show.

    See :mod:`servoscope.camera.exposure`; the blur is pooled over every video (dwells and step).
    """
    blur = pool_blur(blur_evidence(tracks[t.label]) for t in campaign.tests if t.label in tracks)
    switches = []
    for test in campaign.tests:
        track = tracks.get(test.label)
        if track is None or test.t0_s is not None or track.t0_s is None or track.led_partial_frames is None:
            continue
        period = float(np.median(np.diff(track.time_s))) if track.time_s.size > 1 else 0.0
        switches.append((track.led_partial_frames, period))
    return estimate_exposure(switches, campaign.exposure_s, blur)


def shared_t0_stderr(tests: list[TestSpec], tracks: dict[str, Track]) -> tuple[float, dict[str, float]]:
    """Split the dwells' t0 uncertainties into a part they may share and their own parts.

    Each LED-dated t0 lies in an interval of the frame clock (the unexposed
    gap, or ±3σ of a partly lit frame's date). When those intervals, taken
    as fractions of a frame after the frame before the switch, all overlap,
    every switch may have fallen at the same point φ of the frame clock (as
    when one script starts the camera and the input), somewhere in their
    intersection [L, H]: then the dwells' errors c_i − φ (c_i each one's
    estimate) move together and do not average out, and the footage cannot
    tell otherwise. The phase dead time then errs by the dwells' weighted
    mean error c̄ − φ (weights f²/σ², as the phases weigh in the fit), whose
    root mean square over φ uniform in [L, H] is the shared part, added to
    the phase dead time's uncertainty.

    Overlapping intervals allow a common phase but do not show one: with a
    short shutter each gap covers most of the frame, and independent
    switches overlap by chance. The footage cannot tell the two apart, so
    each dwell keeps its whole σ in its phase as well (were it split off,
    independent errors would be read as precise phases and bend ωn and ζ:
    the quick preset at a quarter-frame shutter, timestamps at the exposure
    start, gave ωn 34.3 ± 1.3 rad/s for a true 37 with 12 Hz's phase
    ±0.1° where its t0 alone was off by 11°).

    Returns
    -------
    (float, dict of label → float)
        The shared standard uncertainty (s; 0 when the intervals exclude a
        common phase) and each LED-dated dwell's own (its whole σ).
    """
    own: dict[str, float] = {}
    lows, highs, centres, weights, periods = [], [], [], [], []
    for test in tests:
        track = tracks.get(test.label)
        if track is None or test.t0_s is not None or track.t0_s is None or not track.t0_uncertainty_s:
            continue
        own[test.label] = float(track.t0_uncertainty_s)
        if track.t0_earliest_s is None or track.time_s.size < 2:
            return 0.0, own  # tracks without the interval (older caches): nothing to share
        period = float(np.median(np.diff(track.time_s)))
        clock = track.angle_time_s if track.angle_time_s is not None else track.time_s
        before = int(np.searchsorted(clock, track.t0_s)) - 1
        ref = float(clock[max(before, 0)])
        lows.append((track.t0_earliest_s - ref) / period)
        highs.append((track.t0_latest_s - ref) / period)
        centres.append((track.t0_s - ref) / period)
        weights.append(((test.frequency_hz or 1.0) / track.t0_uncertainty_s) ** 2)
        periods.append(period)
    if len(centres) < 2 or max(lows) > min(highs):
        return 0.0, own
    low, high = max(lows), min(highs)
    mean_centre = float(np.average(centres, weights=weights))
    frame = float(np.median(periods))
    shared = frame * math.sqrt((mean_centre - 0.5 * (low + high)) ** 2 + (high - low) ** 2 / 12.0)
    return shared, own


def dead_time_disagreement(estimates: dict) -> str | None:
    """A warning when the phase and step dead times differ by more than their uncertainties allow (95 %)."""
    phase, step = estimates.get("phase"), estimates.get("step")
    if phase is None or step is None:
        return None
    diff = phase.value_s - step.value_s
    se = math.hypot(phase.stderr_s, step.stderr_s)
    # Their difference's own 95 % interval holds zero: they agree.
    lo, hi = interval95(diff, se)
    if se <= 0 or lo <= 0.0 <= hi:
        return None
    return (f"dead time from the dwells' phases ({1e3 * phase.value_s:.2f} ± {1e3 * phase.stderr_s:.2f} ms) and "
            f"from the step ({1e3 * step.value_s:.2f} ± {1e3 * step.stderr_s:.2f} ms) differ by "
            f"{abs(diff) / se:.1f} standard errors: the linear model or the "
            "input start of one of them is not what the footage shows (check the LED, the exposure and the "
            "step's fit)")


class _Held(NamedTuple):
    """The model parameters held at a value, within limits, or tied (the manifest's and the caller's)."""

    fix: dict
    bounds: dict
    ties: dict


def checked_holds(campaign: Campaign, order, nonlinear: str, fix=None, bounds=None, ties=None) -> _Held:
    """The parameters held (the manifest's ``[model]``, overridden by the caller's), checked once for every model
    the identification will fit, before anything is tracked: :func:`identify` and ``servoscope identify`` both
    call this.

    Raises
    ------
    ServoscopeError
        What :func:`servoscope.parameters.check_held` refuses, for the frequency-domain fit of `order` and for
        each time-domain structure `nonlinear` asks for, and what the campaign cannot support
        (:func:`~servoscope.campaign.joint.check_nonlinear`).
    """
    held_fix, held_bounds = campaign.held_parameters(fix, bounds)
    held = _Held(held_fix, held_bounds, {**campaign.model_ties, **(ties or {})})
    check_nonlinear(campaign, nonlinear, order, held.fix, held.bounds, held.ties)
    fr_fix, fr_bounds, _, _ = split_held(held.fix, held.bounds)
    check_held(order, "minimum_phase", fr_fix, fr_bounds)
    return held


def _tracked(campaign: Campaign, keep_going: bool, progress: ProgressFn | None,
             track_options: dict) -> tuple[Campaign, dict[str, Track]]:
    """Track the campaign; the videos that failed (``keep_going``) left out of it."""
    failures: dict[str, str] = {}
    tracks = track_campaign(campaign, keep_going=keep_going, failures=failures, progress=progress, **track_options)
    return (campaign.without(failures) if failures else campaign), tracks


def _add_tracking_warnings(campaign: Campaign, tracks: dict[str, Track], warnings: list[str]) -> None:
    """The LED's coverage (first: it decides what the phases and the dead time rest on) and the axis's motion."""
    led_warning = led_coverage_warning(campaign, tracks)
    if led_warning:
        warnings.insert(0, led_warning)
    moved = pivot_warning(campaign, tracks)
    if moved:
        warnings.append(moved)


def _fit_model(fr: FrequencyResponse, order, mode: str, bootstrap: int, held: _Held, scale_error):
    """The frequency-domain model, its gain's interval widened by the angle scale's uncertainty."""
    fr_fix, fr_bounds, _, _ = split_held(held.fix, held.bounds)
    model = fit_transfer_function(fr, order=order, mode=mode, bootstrap=bootstrap, seed=0, fix=fr_fix or None,
                                  bounds=fr_bounds or None)
    if scale_error is not None:
        model = with_gain_scale_uncertainty(model, *scale_error)
    return model


def _time_domain_model(campaign: Campaign, tracks: dict[str, Track], fits: dict[str, SineFit],
                       fr: FrequencyResponse, fitted: dict, order, nonlinear: str, exposure_s: float,
                       t0_stderr: tuple[float, dict[str, float]], held: _Held):
    """The servo's time-domain models fitted to the whole traces (:func:`servo_model`)."""
    shared_t0_s, own_t0_stderr = t0_stderr
    t0_se = math.hypot(shared_t0_s, float(np.median(list(own_t0_stderr.values()) or [0.0])))
    return servo_model(
        campaign, tracks, {label: f.window_s for label, f in fits.items()},
        {label: (g, p, c) for label, g, p, c in zip(fr.labels, fr.gain, fr.phase_deg, fr.fidelity)},
        fitted if order == (0, 2) and all(v is not None and math.isfinite(v) for v in fitted.values()) else None,
        nonlinear=nonlinear, exposure_s=exposure_s, t0_stderr_s=t0_se, fix=held.fix, bounds=held.bounds,
        ties=held.ties)


class _BladeMotions(NamedTuple):
    """The blade's motions beside its pitch: its modes, heave and bending per dwell, the flapping model."""

    modes: list
    heave: list
    bending: list
    flapping: object


def _blade_motions(campaign: Campaign, tracks: dict[str, Track], fits: dict[str, SineFit], step, step_label,
                   model, warnings: list[str], exposure_s: float = 0.0) -> _BladeMotions:
    """The blade's modes (step and dwells), heave and bending; the pitch axis found once for them all."""
    step_track = tracks[step_label] if step_label else None
    pivot = axis_of(tracks, fits, step_track)
    modes = blade_modes(step, step_track, model, pivot, (campaign.lead, campaign.trail))
    modes += dwell_modes(campaign, tracks, fits, pivot, model, modes)
    heave, flapped = flapping(campaign, tracks, fits, pivot, modes, warnings, exposure_s=exposure_s)
    bending = bending_response(campaign, tracks, fits, modes)
    modes += [m for m in flapped.modes if m.source in ("heave_response", "heave_traces")] if flapped is not None else []
    short = step_ringdown_warning(step, step_track, model, step_label or "", modes)
    if short:
        warnings.append(short)
    return _BladeMotions(modes, heave, bending, flapped)


def mode_warnings(campaign: Campaign, modes) -> list[str]:
    """A warning for each blade mode near a dwell's frequency (one per mode seen in both the step and the dwells)."""
    out = []
    warned: list[float] = []
    for mode in modes:
        if any(abs(mode.frequency_hz / f - 1.0) < 0.02 for f in warned):
            continue  # the same mode seen in the step and the dwells: one warning
        warned.append(mode.frequency_hz)
        near = [t.label for t in campaign.sine_tests if t.frequency_hz and mode.resonates_at(t.frequency_hz)]
        if near:
            out.append(f"the blade's mode at {mode.frequency_hz:.3g} Hz (damping {mode.damping_ratio:.3f}) is "
                       f"within its resonance of the dwell(s) {', '.join(near)}: the blade's own motion adds "
                       "to the pitch there")
    return out


def dead_time_warnings(model, step, shared_t0_s: float, exposure: ExposureEstimate) -> list[str]:
    """The dwells' possibly shared input-start error, and a disagreement of the phase and step dead times."""
    out = []
    if shared_t0_s > 0 and model.dead_time_s is not None:
        out.append(
            f"the tests' LED switches may all have fallen at the same point of the frame clock: their t0 errors "
            f"(±{1e3 * shared_t0_s:.2f} ms) may be one shared error that no averaging removes: the phase dead time's "
            f"interval includes it"
            + ("" if exposure.known else f"; exposure {exposure.detail}"))
    disagreement = dead_time_disagreement(dead_time_estimates(model, step, shared_t0_s))
    if disagreement:
        out.append(disagreement)
    return out


def _identify_rotor(campaign: Campaign, fit: str, order, bootstrap: int, held: _Held, keep_going: bool,
                    progress: ProgressFn | None, nonlinear: str, self_calibrate_plane: bool) -> IdentificationResult:
    """A turning rotor's campaign (``[rotor]``): the videos read pass by pass, then the static steps."""
    if nonlinear != "none":
        raise ServoscopeError(f"{campaign.path}: --nonlinear is not built for a turning rotor's passes yet; "
                              "identify it without (the linear model from the dwells)")
    if self_calibrate_plane:
        raise ServoscopeError(f"{campaign.path}: --self-calibrate-plane reads a static blade's stickers; a turning "
                              "rotor's pitch is read at each pass (docs/rotor.md)")
    failures: dict[str, str] = {}
    tables = track_rotor_campaign(campaign, keep_going=keep_going, failures=failures, progress=progress)
    warnings: list[str] = [f"{label}: left out: {reason}" for label, reason in failures.items()]
    systematics = rotor_systematics(campaign)  # what the passes share beyond their errors (videos probed once)
    lossy = codec_warning(campaign, shared=systematics)
    if lossy:
        warnings.append(lossy)
    video = {t.label: t.video for t in campaign.tests}
    tracks = {label: pass_track(table, str(video[label])) for label, table in tables.items()}
    shared_t0_s, own_t0_stderr = shared_t0_stderr([t for t in campaign.sine_tests if t.label in tracks], tracks)
    for label, table in tables.items():
        own = own_t0_stderr.get(label)
        if own is not None:
            tables[label] = replace(table, t0_uncertainty_s=own)
    fits = rotor_dwell_fits(campaign, tables, warnings, shared=systematics)
    if len(fits) < 3:
        raise ServoscopeError(f"{campaign.path}: only {len(fits)} dwell(s) could be fitted to the rotor's passes; "
                              f"identify fits a model to 3 or more frequencies (the warnings say why each was left out)")
    # The shutter as given (a rotor's is short: 1/40,000 s takes 0.002 % off a 14 Hz dwell); passes show no blur
    # evidence a static track would.
    exposure = estimate_exposure([], campaign.exposure_s, None)
    amplitude = {t.label: t.amplitude for t in campaign.sine_tests}
    fr = dwell_response(campaign, fits, [amplitude[label] for label in fits], exposure)
    # The passes' pitch scale (RotorSystematics): the gain's interval widened by it, as a plane's scale widens it.
    model = _fit_model(fr, order, fit_mode(fit, fr, campaign), bootstrap, held, systematics.scale_error)
    warnings.extend(fr.warnings)
    warnings.extend(w for w in model.warnings if w not in warnings)
    step, step_label = rotor_step(campaign, tables, model, warnings)
    warnings.extend(dead_time_warnings(model, step, shared_t0_s, exposure))
    return IdentificationResult(
        campaign=campaign, tracks=tracks, sine_fits=fits, frequency_response=fr, model=model, step=step,
        step_label=step_label, warnings=warnings, exposure=exposure, shared_t0_stderr_s=shared_t0_s,
        rotor=rotor_summary(campaign, tables, fits, shared=systematics))


def identify(
    campaign: Campaign | str | Path,
    *,
    tracks: dict[str, Track] | None = None,
    fit: str = "auto",
    order: tuple[int, int] | str = (0, 2),
    bootstrap: int = 0,
    keep_going: bool = False,
    progress: ProgressFn | None = None,
    fix: dict[str, float] | None = None,
    bounds: dict[str, tuple[float, float]] | None = None,
    nonlinear: str = "none",
    ties: dict[str, str] | None = None,
    self_calibrate_plane: bool = False,
    **track_options,
) -> IdentificationResult:
    """Identify a campaign: tracks → sine fits → frequency response → model → step check.

    Parameters
    ----------
    campaign : Campaign or path to campaign.toml
    tracks : dict of label → Track, optional
        Reuse tracks already computed (tracking is the expensive part).
    fit : {"auto", "magnitude", "complex"}
        "magnitude" fits |G| only, as the paper does (no dead time from the
        dwells); "complex" fits magnitude and phase with a dead time, which
        needs every dwell's input start (LED or t0_s); "auto" picks complex
        when the phases are known.
    order : (nb, na) or "auto"
        Numerator and denominator degrees (nb < na ≤ 4); (0, 2) is the
        paper's 2nd-order model; "auto" selects the order from the data
        (asymptotic slope, AIC/BIC, CIFER's J).
    bootstrap : int
        Also compute 95 % intervals by refitting on this many resamplings of
        the dwells (0: intervals from the Jacobian only).
    keep_going : bool
        Leave out a video that cannot be tracked (with a warning) and identify
        from the rest.
    fix, bounds : dict, optional
        Parameters held at a value or within limits (with the manifest's ``[model]``).
    nonlinear : {"none", "auto", "linear", "rate_limit", "backlash", "quantization", "saturation"}
        Also fit models to the whole traces of the dwells and the step
        (:mod:`servoscope.campaign.joint`): "linear" the linear model alone, a structure's name
        that structure beside it, "auto" every structure, selected by BIC. "none": the
        frequency-domain fit alone.
    ties : dict of name → expression, optional
        Parameters computed from others in the time-domain fits (with the manifest's
        ``[model] tie``), e.g. ``{"rate_limit_rad_s": "4*gain"}``.
    self_calibrate_plane : bool
        Without a plane (``[camera] plane``): correct every track for the camera's view as the
        stickers tell it (:func:`~servoscope.pipeline.plane_view.with_view_correction`:
        foreshortening and perspective, from round or square stickers of one size), the gain's
        interval widened by the estimate's uncertainty. Refused where the footage does not tell
        the view.
    **track_options
        Passed to :func:`track_campaign` when ``tracks`` is not given
        (``workers``, ``scheduler``, ``cache_dir``, ``force``, ``on_done``).
    progress : callable(label, frames_done, test_index), optional

    Returns
    -------
    IdentificationResult

    Raises
    ------
    ServoscopeError
        When the manifest or a video is bad, or too few dwells could be fitted.
    """
    if not isinstance(campaign, Campaign):
        campaign = load_campaign(campaign)
    if not isinstance(order, str):
        order = tuple(order)  # (0, 2) or [0, 2] alike
    held = checked_holds(campaign, order, nonlinear, fix, bounds, ties)
    if campaign.rotor is not None:
        return _identify_rotor(campaign, fit, order, bootstrap, held, keep_going, progress, nonlinear,
                               self_calibrate_plane)
    if tracks is None:
        campaign, tracks = _tracked(campaign, keep_going, progress, track_options)
    warnings: list[str] = [f"{label}: left out: {reason}" for label, reason in campaign.skipped]
    tracks, view, scale_error = campaign_in_view(campaign, tracks, self_calibrate_plane, warnings)
    exposure = campaign_exposure(campaign, tracks)
    shared_t0_s, own_t0_stderr = shared_t0_stderr(campaign.sine_tests, tracks)
    _add_tracking_warnings(campaign, tracks, warnings)

    sweeps = sweep_responses(campaign, tracks, warnings)
    shared_t0_s = max(shared_t0_s, sweeps_t0_stderr(campaign, tracks, sweeps, warnings))
    fits, amplitudes = fit_dwells(campaign, tracks, own_t0_stderr, order, warnings,
                                  sum(int(np.count_nonzero(s.kept)) for s in sweeps.values()))
    dwells = dwell_response(campaign, fits, amplitudes, exposure) if fits else None
    fr = combined_response(dwells, sweeps, lambda r: exposure_corrected(campaign, r, exposure)) if sweeps else dwells
    mode = fit_mode(fit, fr, campaign)
    checks = amplitude_checks(dwells, fits, amplitudes, tracks) if dwells is not None else []
    warnings.extend(w for w in (c.warning() for c in checks) if w)
    model = _fit_model(fr, order, mode, bootstrap, held, scale_error)
    warnings.extend(fr.warnings)
    warnings.extend(w for w in model.warnings if w not in warnings)

    exposure_s = campaign.exposure_s if campaign.exposure_s is not None else (
        exposure.value_s if exposure.known else 0.0)
    fitted = {"gain": model.gain, **model.params, "dead_time_s": model.dead_time_s}
    selection = None
    if nonlinear != "none":
        selection = _time_domain_model(campaign, tracks, fits, fr, fitted, order, nonlinear, exposure_s,
                                       (shared_t0_s, own_t0_stderr), held)
        warnings.extend(w for w in [*selection.warnings, *selection.selected.warnings] if w not in warnings)

    step, step_label = step_test(campaign, tracks, model, selection, warnings)
    blade = _blade_motions(campaign, tracks, fits, step, step_label, model, warnings, exposure_s)
    warnings.extend(mode_warnings(campaign, blade.modes))
    warnings.extend(dead_time_warnings(model, step, shared_t0_s, exposure))
    predicted = None
    if step_label is not None and order == (0, 2):
        predicted = predicted_step_fit_percent(campaign, tracks, step_label, fitted, exposure_s)
    return IdentificationResult(
        campaign=campaign, tracks=tracks, sine_fits=fits, frequency_response=fr, model=model, step=step,
        step_label=step_label, warnings=warnings, exposure=exposure, shared_t0_stderr_s=shared_t0_s,
        amplitude_checks=checks, modes=blade.modes, servo_model=selection,
        predicted_step_fit_percent=predicted, heave_response=blade.heave, bending_response=blade.bending,
        heave_model=blade.flapping, view=view, plane=plane_summary(campaign, tracks), sweeps=sweeps)
