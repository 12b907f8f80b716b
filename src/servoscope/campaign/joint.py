"""The campaign's tests as whole traces, for one model of the sines, the sweeps and the step (issues 17, 31).

:func:`servo_model` turns each tracked test into a :class:`~servoscope.sysid.servo_sim.ServoTrace`
(its valid angles, input start, measured noise and the camera's exposure) and runs
:func:`~servoscope.sysid.servo_fit.select_servo_model`: the linear model and the nonlinear
structures asked for, fitted to the dwells, the sweeps and the step together, selected by BIC
and cross-validated. :func:`check_nonlinear` refuses, before any tracking, what cannot work.

What a campaign can tell apart
------------------------------
Every test's input start is known (the LED's switch or the manifest's t0), so the dead time
is measured by the dwells' and the sweeps' phases as well as by a step: no step is needed.
A nonlinearity shows in how the response changes with the input: a rate limit where the
commanded slew ``K·A·2πf`` exceeds it (a large amplitude at a high frequency, a sweep's top, a
step's edge), backlash where the swing is small beside the play, so dwells at two amplitudes,
a sweep or a step each show them. :func:`identifiability_warnings` says what a campaign
without a step cannot rule out: with one input amplitude only, a structure shows only in
its waveform's harmonics and in how it changes with frequency, and a rate limit above the
fastest slew any test commands never bites.
"""

from __future__ import annotations

import math

from dataclasses import replace

import numpy as np

from ..errors import ServoscopeError
from ..markers.track import Track
from ..parameters import check_held, tie_names
from ..sysid.servo_fit import ServoModelFit, check_servo_held, fit_percent
from ..sysid.servo_select import ServoModelSelection, select_servo_model
from ..sysid.servo_sim import LINEAR_PARAMETERS, NONLINEAR_PARAMETER, STRUCTURES, ServoTrace, simulate_trace
from .manifest import Campaign
from .result import input_start

__all__ = ["NONLINEAR_CHOICES", "check_nonlinear", "identifiability_warnings", "predicted_step_fit_percent",
           "servo_model", "servo_traces", "split_held"]

#: What ``identify --nonlinear`` takes: none (the frequency-domain fit alone), auto (every
#: structure, selected by BIC), or one structure (fitted beside the linear model).
NONLINEAR_CHOICES = ("none", "auto", *STRUCTURES)


def split_held(fix: dict[str, float], bounds: dict[str, tuple[float, float]]) -> tuple[dict, dict, dict, dict]:
    """The held parameters the frequency-domain fit knows, and the nonlinear structures' own."""
    own = set(NONLINEAR_PARAMETER.values())
    return ({k: v for k, v in fix.items() if k not in own}, {k: v for k, v in bounds.items() if k not in own},
            {k: v for k, v in fix.items() if k in own}, {k: v for k, v in bounds.items() if k in own})


def structures_of(nonlinear: str) -> tuple[str, ...]:
    """The structures ``--nonlinear`` asks for (the linear model is always fitted beside them)."""
    if nonlinear == "auto":
        return tuple(s for s in STRUCTURES if s != "linear")
    return (nonlinear,)


def check_nonlinear(campaign: Campaign, nonlinear: str, order, fix: dict[str, float],
                    bounds: dict[str, tuple[float, float]], ties: dict[str, str] | None = None) -> None:
    """Refuse, before any tracking, a time-domain fit the campaign cannot support.

    Raises
    ------
    ServoscopeError
        An unknown structure; a nonlinear parameter held without its structure; a nonlinear
        structure with fewer dwells than parameters and no sweep (a step is not needed: see the
        module's description); a model order
        other than the 2nd-order one the time-domain models are built on; a tie without a
        time-domain fit, or one naming an unknown parameter.
    """
    ties = dict(ties or {})
    if nonlinear not in NONLINEAR_CHOICES:
        raise ServoscopeError(f"--nonlinear {nonlinear!r}: choose from {', '.join(NONLINEAR_CHOICES)}")
    own = [k for k in [*fix, *bounds, *ties] if k in NONLINEAR_PARAMETER.values()]
    if nonlinear == "none" and ties:
        raise ServoscopeError(f"tie {next(iter(ties))} = {next(iter(ties.values()))!r}: parameters are tied in the "
                              "time-domain fits only; add --nonlinear linear (or a structure, or auto)")
    if nonlinear == "none":
        if own:
            raise ServoscopeError(f"{own[0]} belongs to a nonlinear model: add --nonlinear "
                                  f"{next(s for s, p in NONLINEAR_PARAMETER.items() if p == own[0])} (or auto)")
        return
    tried = structures_of(nonlinear)
    check_held({*LINEAR_PARAMETERS, *(NONLINEAR_PARAMETER[s] for s in tried if s in NONLINEAR_PARAMETER)},
               fix, bounds, ties, who=f"--nonlinear {nonlinear}")
    for s in tried:
        mine = set(LINEAR_PARAMETERS) | {NONLINEAR_PARAMETER.get(s)}
        check_servo_held(s, {k: v for k, v in fix.items() if k in mine}, {k: v for k, v in bounds.items() if k in mine},
                         {k: v for k, v in ties.items() if k in mine and tie_names(v) <= mine})
    if isinstance(order, str) or tuple(order) != (0, 2):
        raise ServoscopeError(f"--nonlinear {nonlinear}: the time-domain models are 2nd-order with a dead time; "
                              f"use --order 2 (not {order})")
    if nonlinear == "linear":
        return
    n_params = len(LINEAR_PARAMETERS) + 1
    # A sweep's response spans its band at many frequencies: enough for the parameters by itself.
    if len(campaign.sine_tests) < n_params and not campaign.sweep_tests:
        raise ServoscopeError(f"{campaign.path}: --nonlinear {nonlinear} fits {n_params} parameters but the campaign "
                              f"has {len(campaign.sine_tests)} sine dwell(s) and no sweep; plan at least {n_params} "
                              "dwells, or a sweep")


def servo_traces(campaign: Campaign, tracks: dict[str, Track], windows: dict[str, tuple[float, float]],
                 exposure_s: float) -> list[ServoTrace]:
    """Each test with a known input start and enough valid frames, as a trace.

    ``windows`` holds each fitted dwell's steady-state window (its fundamental's, for CIFER's J);
    a sine whose dwell fit was left out is left out here too.
    """
    traces = []
    for test in campaign.tests:
        track = tracks.get(test.label)
        if track is None or (test.kind == "sine" and test.label not in windows):
            continue  # a sweep and a step are fitted whole, from before their start to the record's end
        t0 = input_start(test, track)
        if t0 is None or track.n_valid < 10:
            continue
        summary = track.summary()
        noise = summary.get("angle_noise_measured_rad") or summary.get("angle_noise_rad")
        separation = summary.get("mean_separation_px")
        v = track.valid
        traces.append(ServoTrace(test.label, test.kind, test.amplitude, test.frequency_hz, float(t0),
                                 np.asarray(track.angle_time_s[v], float), np.asarray(track.angle_rad[v], float),
                                 float(noise) if noise and noise > 0 else 1e-4, exposure_s,
                                 windows.get(test.label), 0.5 * float(separation) if separation else math.nan,
                                 *(_sweep_fields(test) if test.kind == "sweep" else ())))
    return traces


def _sweep_fields(test) -> tuple:
    """A sweep's ServoTrace fields: its chirp's, or a recorded input's band, length and samples (its own command)."""
    if test.recorded:
        return (*test.sweep_band_hz, test.input_duration_s, None, (test.input_time_s, test.input_command))
    return test.from_hz, test.to_hz, test.duration_s, test.shape or "log"


def servo_model(campaign: Campaign, tracks: dict[str, Track], windows: dict[str, tuple[float, float]],
                response: dict[str, tuple[float, float, float]], start: dict[str, float] | None, *,
                nonlinear: str, exposure_s: float, t0_stderr_s: float, fix: dict[str, float],
                bounds: dict[str, tuple[float, float]], ties: dict[str, str] | None = None) -> ServoModelSelection:
    """Fit and select the time-domain models ``nonlinear`` asks for (see :func:`check_nonlinear`).

    Parameters
    ----------
    campaign, tracks
    windows : dict of label → (start, end)
        The fitted dwells' steady-state windows.
    response : dict of label → (gain, phase_deg, coherence)
        The measured frequency response, for CIFER's J of each candidate.
    start : dict or None
        The frequency-domain fit's parameters, a starting point (None when it has none).
    nonlinear : str
        One of :data:`NONLINEAR_CHOICES` but "none".
    exposure_s : float
        The exposure averaging each sample (0 when unknown).
    t0_stderr_s : float
        The input starts' error, added to the dead time's.
    fix, bounds : dict
        Held parameters, linear and nonlinear.
    ties : dict of name → expression, optional
        Parameters computed from the others (:func:`~servoscope.sysid.servo_fit.fit_servo_model`).
    """
    traces = servo_traces(campaign, tracks, windows, exposure_s)
    if not traces:
        raise ServoscopeError(f"{campaign.path}: no test has a known input start and enough valid frames for a "
                              "time-domain fit")
    selection = select_servo_model(traces, structures_of(nonlinear), start=start, fix=fix, bounds=bounds, ties=ties,
                                   response=response, t0_stderr_s=t0_stderr_s)
    notes = identifiability_warnings(traces, structures_of(nonlinear), selection.selected)
    return replace(selection, warnings=(*selection.warnings, *notes)) if notes else selection


def identifiability_warnings(traces: list[ServoTrace], structures: tuple[str, ...], selected: ServoModelFit
                             ) -> list[str]:
    """What the traces fitted cannot tell apart (the module's description); none with a step.

    Without a step: with one input amplitude only, the nonlinear structures are told from the
    linear model only by their waveforms; a rate limit not selected is ruled out only up to
    the fastest slew any test commanded (the selected model's gain times ``A·2πf``).
    """
    tried = [s for s in structures if s in NONLINEAR_PARAMETER]
    if not tried or any(tr.kind == "step" for tr in traces):
        return []
    out = []
    amplitudes = sorted({round(abs(tr.amplitude), 12) for tr in traces})
    if len(amplitudes) == 1:
        out.append(f"every test has one input amplitude ({amplitudes[0]:g}) and there is no step: "
                   f"{', '.join(tried)} show only in the waveforms' harmonics and in how they change with "
                   "frequency, not in a gain that changes with amplitude, so they are told apart from the linear "
                   "model (and from each other) less surely; add dwells at a second amplitude, or a step")
    if "rate_limit" in tried and selected.structure != "rate_limit":
        fastest = max(traces, key=lambda tr: abs(tr.amplitude) * tr.top_frequency_hz)
        slew = abs(selected.params["gain"] * fastest.amplitude) * 2.0 * math.pi * fastest.top_frequency_hz
        out.append(f"without a step, a rate limit is seen only where a test's slew exceeds it: one above "
                   f"{slew:.3g} rad/s (the fastest commanded, {fastest.label}) never bites and is not ruled out")
    return out


def predicted_step_fit_percent(campaign: Campaign, tracks: dict[str, Track], label: str,
                               params: dict[str, float], exposure_s: float) -> float | None:
    """The step's fit (percent) predicted by a 2nd-order model fitted to the dwells alone.

    The step's rest angle is its own (the mean before the delayed input arrives); nothing
    else is fitted to the step.
    """
    if any(not (k in params and params[k] is not None and math.isfinite(params[k])) for k in LINEAR_PARAMETERS):
        return None
    traces = servo_traces(campaign, {label: tracks[label]}, {}, exposure_s)
    if not traces:
        return None
    trace = traces[0]
    predicted = simulate_trace(trace, "linear", params)
    before = trace.time_s < trace.t0_s + params["dead_time_s"]
    rest = float(np.mean((trace.angle_rad - predicted)[before])) if before.sum() >= 3 else float(
        np.mean(trace.angle_rad - predicted))
    return fit_percent(trace.angle_rad, predicted + rest)
