"""The blade's other motions beside its pitch (issue 18): its structural mode, and its heave per dwell.

Both read the heave, the markers' line's distance from the pitch axis
(:func:`servoscope.angle.heave_px`): a rigid blade turning about its axis keeps it; a
blade that flaps moves the line across itself.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..angle.pivot import heave_px, pivot_motion
from ..markers.track import marker_names
from ..markers.track import Track
from ..sysid import SineFit
from ..sysid.heave import (HEAVE_FLOOR_MIN_INTRA_PX, HEAVE_FLOOR_MIN_PX, HEAVE_SYSTEMATIC_IFRAME_PX, HEAVE_SYSTEMATIC_REL,
                           HEAVE_SYSTEMATIC_REL_PREDICTED, HeaveModel, HeaveRow, coded_alone, dwell_heave,
                           fit_heave_model, heave_systematic_px)
from ..sysid.heave_traces import HeaveTrace, fit_heave_traces, mode_response_px
from ..sysid.modes import ModeFit, fit_damped_modes, fit_mode_shapes, pool_modes
from .manifest import Campaign
from .result import input_start

__all__ = ["HEAVE_MIN_Z", "MIN_IFRAMES", "MIN_RINGDOWN_PERIODS", "MIN_SETTLED_PERIODS", "axis_of", "bending_response",
           "blade_modes", "dwell_modes", "flapping", "heave_model", "heave_response", "heave_traces", "step_ringdown_warning"]

#: A dwell's heave at its frequency counts as measured when its amplitude is this many standard errors.
HEAVE_MIN_Z = 5.0
#: Near the blade's mode, a dwell's heave is measured from the mode's settling (4/(ζω) after the input's start)
#: on when the dwell records at least this many of its periods after it; else it is the model's.
MIN_SETTLED_PERIODS = 4.0
#: A dwell's heave is fitted to its I-frames alone when its window holds at least this many (and the codec
#: predicts the others): :func:`~servoscope.sysid.heave.dwell_heave` fits nothing to fewer than 10 samples
#: (with 8, as the pitch's codec check asks, a dwell once got no row at all).
MIN_IFRAMES = 10


def blade_modes(step, track: Track | None, model, pivot, colours: tuple[str, str] = ("", "")) -> list[ModeFit]:
    """The blade's structural modes (one or two, strongest first) from its heave after the step has settled
    (:func:`~servoscope.sysid.modes.fit_damped_modes`).

    With extra markers each mode gets its shape (:func:`~servoscope.sysid.modes.fit_mode_shapes`):
    each marker's ring-down across the chord line; ``colours`` are the lead's and trail's.

    The heave is the markers' line's distance from the pitch axis
    (:func:`servoscope.angle.heave_px`); the free motion starts when the servo has
    settled (the step's measured settling time after t0, else its dead time and
    0.3 s) and four of the model's time constants 1/(ζ·ωn) more: the servo's own
    forced motion, 2 % at settling, biased the twin's 9 Hz mode by 0.03 %, 4 σ of its
    fit. Its noise is the heave's frame-to-frame scatter before the input. ``pivot`` is the
    pitch axis (:func:`axis_of`, found on this step's track).
    """
    if step is None or track is None or pivot is None:
        return []
    t0_s = step.t0_s
    heave = heave_px(track.lead_xy_px, track.trail_xy_px, track.valid, pivot.centre_xy_px)
    settled = _ringdown_start_s(step, model)
    modes = fit_damped_modes(track.angle_time_s, heave, t0_s + settled, noise=_noise_before(track, heave, t0_s),
                             source="step")
    if modes and track.bending_px is not None:
        # Which markers move in each: each one's distance across the chord line (the line's heave
        # plus its own bending), its ring-downs at the modes' frequencies and dampings.
        shapes = fit_mode_shapes(track.angle_time_s, heave[:, None] + track.bending_px, t0_s + settled, modes,
                                 tuple(marker_names(len(track.extra_colours))), (*colours, *track.extra_colours),
                                 systematic_px=heave_systematic_px(track.intra))
        modes = [replace(m, shape=sh) for m, sh in zip(modes, shapes)] if shapes else modes
    return modes


def _noise_before(track: Track, heave: np.ndarray, t0_s: float) -> float | None:
    """The heave's noise: its frame-to-frame scatter before the input starts; None with 5 frames or fewer."""
    before = heave[(track.angle_time_s < t0_s) & np.isfinite(heave)]
    return float(np.std(np.diff(before)) / math.sqrt(2.0)) if before.size > 5 else None


def _four_time_constants_s(model, otherwise_s: float) -> float:
    """Four of the servo model's time constants 1/(ζ·ωn): its own motion has died to 2 % of its start
    (``otherwise_s`` when the model has none)."""
    decay = model.params.get("natural_frequency_rad_s", 0.0) * model.params.get("damping_ratio", 0.0)
    return 4.0 / decay if decay > 0 and math.isfinite(decay) else otherwise_s


def _ringdown_start_s(step, model) -> float:
    """When the step's free motion starts, after t0: the servo settled, and four time constants more."""
    settled = step.settling_time_s if math.isfinite(step.settling_time_s) else (step.dead_time_s or 0.0) + 0.3
    return settled + _four_time_constants_s(model, 0.2)


#: The least free motion after the step that a mode is fitted to: this many of its periods.
MIN_RINGDOWN_PERIODS = 4.0


def step_ringdown_warning(step, track: Track | None, model, label: str, modes: list[ModeFit]) -> str | None:
    """A warning when the blade rings (a mode seen in the dwells or the heave) but the step was too short to fit it.

    None when the step gave a mode, or nothing rings, or the step's record after the servo
    settles spans :data:`MIN_RINGDOWN_PERIODS` of the mode (then the ring-down was too small to see).
    """
    if step is None or track is None or not modes or any(m.source == "step" for m in modes):
        return None
    period = 1.0 / modes[0].frequency_hz
    t = track.angle_time_s[track.valid]
    span = float(t[-1] - step.t0_s - _ringdown_start_s(step, model)) if t.size else 0.0
    if span >= MIN_RINGDOWN_PERIODS * period:
        return None
    need = _ringdown_start_s(step, model) + MIN_RINGDOWN_PERIODS * period
    return (f"{label}: the blade rings at {modes[0].frequency_hz:.3g} Hz ({modes[0].source}), but the step records "
            f"only {max(span, 0.0):.2g} s after the servo settles: too short to fit its ring-down; record at least "
            f"{need:.2g} s after the input's start")


def axis_of(tracks: dict[str, Track], fits: dict[str, SineFit], axis_track: Track | None):
    """The pitch axis (:class:`~servoscope.angle.pivot.PivotMotion`), found on the step's track, else on the dwell
    that swings most (an axis found on a small swing is uncertain); None when none turned enough."""
    candidates = [axis_track] if axis_track is not None else sorted(
        (tracks[label] for label in fits), key=lambda tr: -float(np.nanmax(tr.angle_rad) - np.nanmin(tr.angle_rad)))
    for track in candidates:
        pivot = pivot_motion(track.lead_xy_px, track.trail_xy_px, track.valid)
        if pivot is not None:
            return pivot
    return None


def _fitted_dwells(campaign: Campaign, tracks: dict[str, Track], fits: dict[str, SineFit]):
    """Each fitted dwell with a known input start: (test, track, its sine fit, t0)."""
    for test in campaign.sine_tests:
        fit, track = fits.get(test.label), tracks.get(test.label)
        t0 = None if track is None else input_start(test, track)
        if fit is not None and t0 is not None:
            yield test, track, fit, t0


def _dwell_heaves(campaign: Campaign, tracks: dict[str, Track], fits: dict[str, SineFit], pivot):
    """Each fitted dwell with a known input start: (test, track, its sine fit, t0, heave per frame)."""
    for test, track, fit, t0 in _fitted_dwells(campaign, tracks, fits):
        yield test, track, fit, t0, heave_px(track.lead_xy_px, track.trail_xy_px, track.valid, pivot.centre_xy_px)


def dwell_modes(campaign: Campaign, tracks: dict[str, Track], fits: dict[str, SineFit], pivot,
                model, known: list[ModeFit] | None = None) -> list[ModeFit]:
    """The blade's mode from the dwells: each one's heave rings down after its sine starts, beside the forced motion.

    Each dwell's heave is fitted, from the servo's settling on (its dead time and four time
    constants 1/(ζ·ωn) after the input's start), as a ring-down plus a sine at the dwell's
    frequency (:func:`~servoscope.sysid.modes.fit_damped_mode` with ``forced_hz``); a dwell
    within the mode's resonance (3ζ + 2 % of its frequency) is left out, its free and forced
    motions one; the rest are pooled (:func:`~servoscope.sysid.modes.pool_modes`), each with the
    ``known`` mode (the step's) it is nearest to within 10 %, or, without known modes, with the
    ones within 10 % of it. As many modes are looked for in a dwell as are known (at least one).
    ``pivot`` is the pitch axis (:func:`axis_of`).
    """
    if pivot is None:
        return []
    settle = (model.dead_time_s or 0.0) + _four_time_constants_s(model, 0.3)
    found = []
    for test, track, _, t0, heave in _dwell_heaves(campaign, tracks, fits, pivot):
        for mode in fit_damped_modes(track.angle_time_s, heave, t0 + settle, noise=_noise_before(track, heave, t0),
                                     source="dwells", forced_hz=test.frequency_hz,
                                     max_modes=max(1, len(known or []))):
            if not mode.resonates_at(test.frequency_hz):
                found.append(mode)
    groups: list[list[ModeFit]] = []
    if known:
        groups = [[] for _ in known]
        for mode in found:
            gap = [abs(mode.frequency_hz / k.frequency_hz - 1.0) for k in known]
            if min(gap) < 0.1:
                groups[int(np.argmin(gap))].append(mode)
    else:
        for mode in sorted(found, key=lambda m: m.frequency_hz):
            if groups and mode.frequency_hz / groups[-1][0].frequency_hz - 1.0 < 0.1:
                groups[-1].append(mode)
            else:
                groups.append([mode])
    return [p for p in (pool_modes(g, "dwells") for g in groups) if p is not None]


def _mode_of(modes: list[ModeFit] | None) -> list[tuple[float, float]] | None:
    """The blade's modes to fit beside a dwell's sine: those of the first source that found any (the step's)."""
    if not modes:
        return None
    return [(m.frequency_hz, m.damping_ratio) for m in modes if m.source == modes[0].source]


def heave_traces(campaign: Campaign, tracks: dict[str, Track], pivot) -> list[HeaveTrace]:
    """Every test's heave and pitch per frame with its input start (dwells, steps and sweeps), for
    :func:`~servoscope.sysid.heave_traces.fit_heave_traces`; empty without an axis."""
    out = []
    if pivot is None:
        return out
    for test in campaign.tests:
        track = tracks.get(test.label)
        t0 = None if track is None else input_start(test, track)
        if t0 is None:
            continue
        h = heave_px(track.lead_xy_px, track.trail_xy_px, track.valid, pivot.centre_xy_px)
        pitch = np.where(track.valid, track.angle_rad, np.nan)
        out.append(HeaveTrace(test.label, np.asarray(track.angle_time_s, float), pitch, h, float(t0)))
    return out


def _settles_s(mode: ModeFit) -> float:
    """How long a mode takes to settle after its drive starts: four time constants, 4/(ζω)."""
    return 4.0 / (mode.damping_ratio * 2.0 * math.pi * mode.frequency_hz)


def _floor_px(campaign: Campaign, tracks: dict[str, Track], fits: dict[str, SineFit], pivot,
              modes: list[ModeFit], model: HeaveModel, intra: bool) -> float | None:
    """The heave's systematic floor, as this footage shows it; None when it cannot.

    A codec that predicts frames holds each sticker's motion across the line back by an amount that
    depends on the bit rate and the picture (rigid blades on the twin: 0.03–0.07 px at 20 Mbit/s, up
    to 0.1 px at 4 Mbit/s, issue 32); frames coded alone leave 0.001–0.003 px with disc stickers and
    more with strips seen through a lens. One constant is either too wide for a good camera or too
    narrow for a poor one. The whole traces' model predicts each dwell's heave; the dwells away from
    the modes' resonances, measured with no floor, scatter about it by their fit's errors and the
    footage's: the floor is the RMS of that scatter (their amplitudes', px) less the fit's, over the
    degrees of freedom the model leaves (dwells less its parameters), and at least
    :data:`~servoscope.sysid.heave.HEAVE_FLOOR_MIN_INTRA_PX` (frames coded alone, ``intra``) or
    :data:`~servoscope.sysid.heave.HEAVE_FLOOR_MIN_PX`: an estimate from a few dwells can fall well
    short. None with fewer than 3 degrees of freedom: then the constants
    (:func:`~servoscope.sysid.heave.heave_systematic_px`) stand.
    """
    bare = heave_response(campaign, tracks, fits, pivot, modes, axis=model, predicted_floor_px=0.0)
    excess = []
    for row in bare:
        test = next(t for t in campaign.sine_tests if t.label == row.label)
        pitch = _pitch_of(fits[row.label], test.amplitude)
        if pitch is None or any(m.resonates_at(row.frequency_hz) for m in model.modes):
            continue
        a = abs(test.amplitude)
        # Amplitudes, not complex values: the floor is an amplitude's (its phase's is the floor over the
        # amplitude), and the codec's small relative phase lag of a large heave is not a floor in px.
        predicted = abs(complex(model.ratio(np.array([row.frequency_hz]))[0])) * pitch[0] * a
        # Less the row's own error (its floor 0 here, but its 0.3 % of the amplitude).
        excess.append((row.gain * a - predicted) ** 2 - (row.gain_stderr * a) ** 2)
    dof = len(excess) - 3 * len(model.modes) - 1
    if dof < 3:
        return None
    return max(math.sqrt(max(sum(excess) / dof, 0.0)), HEAVE_FLOOR_MIN_INTRA_PX if intra else HEAVE_FLOOR_MIN_PX)


def _pitch_of(fit: SineFit, amplitude: float) -> tuple[float, float, float, float] | None:
    """A dwell's pitch per input unit: (gain, its error, phase rad, its error); None without a phase."""
    if fit.phase_rad is None or not amplitude:
        return None
    a = abs(amplitude)
    return fit.amplitude / a, fit.amplitude_stderr / a, fit.phase_rad, fit.phase_stderr_rad or 0.0


def _model_row(test, fit: SineFit, model: HeaveModel, systematic_px: float) -> HeaveRow | None:
    """A dwell's steady-state heave from the flapping model (its ratio times the dwell's measured pitch), marked ``"model"``."""
    pitch = _pitch_of(fit, test.amplitude)
    if pitch is None:
        return None
    gain_p, se_p, phase_p, se_phase_p = pitch
    ratio = complex(model.ratio(np.array([test.frequency_hz]))[0])
    r = abs(ratio)
    if not r > 0:
        return None
    se_r = model.ratio_stderr(test.frequency_hz)
    gain = r * gain_p
    floor = systematic_px / abs(test.amplitude)
    se_gain = math.sqrt((se_r * gain_p) ** 2 + (r * se_p) ** 2 + floor**2)
    se_phase = math.hypot(se_r / r, se_phase_p)
    phase = math.degrees(math.remainder(math.atan2(ratio.imag, ratio.real) + phase_p, 2.0 * math.pi))
    return HeaveRow(test.label, float(test.frequency_hz), gain, se_gain, phase, math.degrees(se_phase),
                    gain * abs(test.amplitude), source="model")


def _unsettled(test, track: Track, t0: float, fit: SineFit, row: HeaveRow, model: HeaveModel, pitch_rad: np.ndarray,
               mode_columns, window_s: tuple[float, float]) -> ModeFit | None:
    """The mode whose transient the dwell's window still holds, or None: the window starts before the mode
    settles (4/(ζω) after the input's start) and the model's own heave over this dwell, fitted as the
    measurement is, misses its steady state by more than the row's standard error."""
    start = window_s[0] - t0
    waiting = [m for m in model.modes if start < _settles_s(m)]
    pitch = _pitch_of(fit, test.amplitude)
    if not waiting or pitch is None:
        return None
    near = [m for m in waiting if m.resonates_at(test.frequency_hz)]
    if near:
        # Within the mode's resonance its free and forced motions are one in a window this short,
        # whatever the row's error says (the ring-down's columns are the sine's).
        return max(near, key=_settles_s)
    # The model's heave over this dwell, noise-free, driven by the pitch measured each frame.
    sim = sum(kappa * mode_response_px(track.angle_time_s, pitch_rad, m.frequency_hz, m.damping_ratio)
              for kappa, m in zip(model.gains_px_per_rad, model.modes))
    seen = dwell_heave(track.angle_time_s, sim, test.frequency_hz, t0, test.amplitude, window_s, test.label,
                       systematic_px=0.0, mode=mode_columns)
    steady = abs(complex(model.ratio(np.array([test.frequency_hz]))[0])) * pitch[0]
    if seen is None or abs(seen.gain - steady) <= row.gain_stderr:
        return None
    return max(waiting, key=_settles_s)


def flapping(campaign: Campaign, tracks: dict[str, Track], fits: dict[str, SineFit], pivot,
             modes: list[ModeFit], warnings: list[str], *,
             exposure_s: float = 0.0) -> tuple[list[HeaveRow], HeaveModel | None]:
    """The blade's heave per dwell and its flapping model, the model fitted to the heave's whole traces (issue 32).

    1. The model (:func:`~servoscope.sysid.heave_traces.fit_heave_traces`) is fitted to every
       test's heave, started at the modes found (the step's ring-down, else the dwells' heave ratios,
       :func:`heave_model`); with no mode, only its axis term (the heave in phase with the pitch
       that an axis found off along the chord leaves).
    2. Each dwell's heave (:func:`heave_response`) is measured on the heave less the axis term,
       its error widened by the term's.
    3. A dwell whose window starts before a mode has settled (4/(ζω)) and whose window, on the
       model's own heave, misses the steady state by more than its standard error is measured from
       the mode's settling on where the dwell records :data:`MIN_SETTLED_PERIODS` after it; where it
       does not, it gets a warning naming it and the record it needs, and its row is the model's
       steady state (``source = "model"``), not a sine fitted to a transient.

    4. Each row is corrected for the camera's averaging over ``exposure_s`` (the gain divided by
       sinc(f·e), as the pitch's frequency response is): the blade's heave, not the frames'. The
       model needs no correction: the pitch that drives it is averaged alike.

    Returns the rows (empty for a blade whose dwells show no heave) and the model (None when it
    cannot be fitted and the dwells' ratios cannot tell one either).
    """
    rows, model = _flapping(campaign, tracks, fits, pivot, modes, warnings)
    return [_unaveraged(r, exposure_s) for r in rows], model


def _unaveraged(row: HeaveRow, exposure_s: float) -> HeaveRow:
    """``row`` divided by the exposure's box filter at its frequency, sinc(f·e) (unchanged without an exposure)."""
    factor = float(np.sinc(row.frequency_hz * exposure_s)) if exposure_s and exposure_s > 0 else 1.0
    if not 0.0 < factor < 1.0:
        return row
    return replace(row, gain=row.gain / factor, gain_stderr=row.gain_stderr / factor,
                   amplitude_px=row.amplitude_px / factor)


def _flapping(campaign: Campaign, tracks: dict[str, Track], fits: dict[str, SineFit], pivot,
              modes: list[ModeFit], warnings: list[str]) -> tuple[list[HeaveRow], HeaveModel | None]:
    """:func:`flapping` before the exposure's correction."""
    if pivot is None:
        return [], None
    traces = heave_traces(campaign, tracks, pivot)
    n_dwells = sum(1 for tr in traces if any(t.label == tr.label for t in campaign.sine_tests))
    start = _mode_of(modes) or []
    if not start:
        ratios = heave_model(campaign, heave_response(campaign, tracks, fits, pivot, modes), fits, modes)
        start = [] if ratios is None else [(m.frequency_hz, m.damping_ratio) for m in ratios.modes]
    intra = all(coded_alone(tr.intra) for tr in tracks.values())
    whole = fit_heave_traces(traces, start, n_dwells=n_dwells,
                             gain_systematic_rel=HEAVE_SYSTEMATIC_REL if intra else HEAVE_SYSTEMATIC_REL_PREDICTED)
    rows = heave_response(campaign, tracks, fits, pivot, modes, axis=whole)
    model = whole if whole is not None and whole.modes else heave_model(campaign, rows, fits, modes)
    if not rows or model is None or model.method != "whole traces":
        return rows, model
    floor = _floor_px(campaign, tracks, fits, pivot, modes, model, intra)
    if floor is not None:
        rows = heave_response(campaign, tracks, fits, pivot, modes, axis=whole, predicted_floor_px=floor)
        model = replace(model, floor_px=floor)
    out = []
    by_label = {tr.label: tr for tr in traces}
    for row in rows:
        test = next(t for t in campaign.sine_tests if t.label == row.label)
        track, fit, trace = tracks[row.label], fits[row.label], by_label.get(row.label)
        if trace is None:
            out.append(row)
            continue
        pitch = trace.pitch_from_rest()
        mode = _unsettled(test, track, trace.start_s, fit, row, model, pitch, _mode_of(modes), fit.window_s)
        if mode is None:
            out.append(row)
            continue
        # The window starts while the mode still rings from the dwell's start: measured from its settling on
        # when the dwell records enough of that (MIN_SETTLED_PERIODS of its sine), else the model's.
        settled = (trace.start_s + _settles_s(mode), fit.window_s[1])
        if (settled[1] - settled[0]) * test.frequency_hz >= MIN_SETTLED_PERIODS:
            late = _measured_row(test, track, fit, trace.start_s, trace.heave_px, modes, model, settled, floor)
            if late is not None and _unsettled(test, track, trace.start_s, fit, late, model, pitch, _mode_of(modes),
                                               settled) is None:
                out.append(late)
                continue
        need = _settles_s(mode) + MIN_SETTLED_PERIODS / test.frequency_hz
        warnings.append(
            f"{row.label}: its heave window starts {fit.window_s[0] - trace.start_s:.2g} s after the input, before the "
            f"blade's {mode.frequency_hz:.3g} Hz mode (ζ {mode.damping_ratio:.2g}) settles ({_settles_s(mode):.2g} s), "
            f"and the dwell ends {fit.window_s[1] - trace.start_s:.2g} s after it: the heave stated there is the flapping "
            f"model's steady state, fitted to the whole traces, not a measurement; record at least {need:.2g} s of this "
            f"dwell after the input's start to measure it")
        systematic = heave_systematic_px(track.intra)
        model_row = _model_row(test, fit, model, floor if floor is not None else systematic)
        out.append(model_row if model_row is not None else row)
    return out, model


def _measured_row(test, track: Track, fit: SineFit, t0: float, heave: np.ndarray, modes: list[ModeFit] | None,
                  axis: HeaveModel | None, window_s: tuple[float, float],
                  predicted_floor_px: float | None = None) -> HeaveRow | None:
    """A dwell's heave sine over ``window_s`` (:func:`~servoscope.sysid.heave.dwell_heave`), the axis term taken off first.

    ``predicted_floor_px``: the systematic floor where the codec predicts frames, when the footage
    told it (:func:`_floor_px`); else :func:`~servoscope.sysid.heave.heave_systematic_px`'s."""
    e = 0.0 if axis is None else axis.axis_px_per_rad
    se_e = 0.0 if axis is None or not math.isfinite(axis.axis_stderr_px_per_rad) else axis.axis_stderr_px_per_rad
    if e:
        trace = HeaveTrace(test.label, track.angle_time_s, np.where(track.valid, track.angle_rad, np.nan), heave, t0)
        heave = heave - e * trace.pitch_from_rest()
    systematic = heave_systematic_px(track.intra)
    if predicted_floor_px is not None:
        systematic = predicted_floor_px  # the footage's own (the I-frames' below keep theirs)
    intra = None if track.intra is None else np.asarray(track.intra, dtype=bool)
    if intra is not None and intra.shape == heave.shape and not np.all(intra):
        t = np.asarray(track.angle_time_s, float)
        inside = (t >= window_s[0]) & (t <= window_s[1]) & np.isfinite(heave)
        if np.count_nonzero(inside & intra) >= MIN_IFRAMES:
            # A camcorder's GOP: the I-frames show the stickers where they are (the codec check, as the
            # pitch's sine fit has it); the predicted frames between hold their motion back.
            heave = np.where(intra, heave, np.nan)
            systematic = HEAVE_SYSTEMATIC_IFRAME_PX
    row = dwell_heave(track.angle_time_s, heave, test.frequency_hz, t0, test.amplitude, window_s, test.label,
                      systematic_px=systematic, mode=_mode_of(modes))
    if row is not None and se_e:
        extra = se_e * fit.amplitude / abs(test.amplitude)
        row = replace(row, gain_stderr=math.hypot(row.gain_stderr, extra),
                      phase_stderr_deg=math.degrees(math.hypot(math.radians(row.phase_stderr_deg),
                                                               extra / row.gain if row.gain > 0 else 0.0)))
    return row


def heave_response(campaign: Campaign, tracks: dict[str, Track], fits: dict[str, SineFit], pivot,
                   modes: list[ModeFit] | None = None, axis: HeaveModel | None = None,
                   predicted_floor_px: float | None = None) -> list[HeaveRow]:
    """Each fitted dwell's heave at its input frequency; empty unless one of them is measured.

    ``modes``: the blade's modes found (the step's first): their ring-downs are fitted
    beside each dwell's sine (:func:`~servoscope.sysid.heave.dwell_heave`). The systematic floor
    is the footage's (:func:`~servoscope.sysid.heave.heave_systematic_px`).

    ``pivot`` is the pitch axis (:func:`axis_of`: an axis found on a small swing is uncertain,
    and its error would read as heave at the input frequency). A campaign whose dwells show
    no heave beyond :data:`HEAVE_MIN_Z` standard errors (a rigid blade) gets none, so its
    result is as before.

    ``axis``: the whole traces' model (:func:`~servoscope.sysid.heave_traces.fit_heave_traces`),
    whose axis term (heave in phase with the pitch, px/rad) is taken off each dwell's heave
    before its sine is fitted; the term's error times the dwell's pitch amplitude is added to the row's.
    ``predicted_floor_px``: the floor where the codec predicts frames, as the footage told it.
    """
    if pivot is None:
        return []
    rows = []
    for test, track, fit, t0, h in _dwell_heaves(campaign, tracks, fits, pivot):
        row = _measured_row(test, track, fit, t0, h, modes, axis, fit.window_s, predicted_floor_px)
        if row is not None:
            rows.append(row)
    if not any(r.gain >= HEAVE_MIN_Z * r.gain_stderr for r in rows):
        return []
    return rows


def bending_response(campaign: Campaign, tracks: dict[str, Track], fits: dict[str, SineFit],
                     modes: list[ModeFit] | None = None) -> list[HeaveRow]:
    """Each extra marker's bending at each fitted dwell's input frequency (px per input unit, phase).

    A marker's bending is its distance across the lead–trail chord line from where it rests
    (:attr:`~servoscope.markers.Track.bending_px`); fitted as the heave is
    (:func:`~servoscope.sysid.heave.dwell_heave`, with the first of ``modes``), one row per
    marker and dwell. Empty without extra markers; with them, every row, measured or not
    (its error says which).
    """
    rows = []
    for test, track, fit, t0 in _fitted_dwells(campaign, tracks, fits):
        if track.bending_px is None:
            continue
        names = marker_names(len(track.extra_colours))
        for k, colour in enumerate(track.extra_colours):
            row = dwell_heave(track.angle_time_s, track.bending_px[:, 2 + k], test.frequency_hz, t0, test.amplitude,
                              fit.window_s, test.label, names[2 + k], colour or campaign.extra[k],
                              systematic_px=heave_systematic_px(track.intra, bending=True), mode=_mode_of(modes))
            if row is not None:
                rows.append(row)
    return rows


def heave_model(campaign: Campaign, rows: list[HeaveRow], fits: dict[str, SineFit],
                modes: list[ModeFit]) -> HeaveModel | None:
    """The flapping frequency response fitted (:func:`~servoscope.sysid.heave.fit_heave_model`): each dwell's
    heave over its pitch, one term per mode found (the step's) started there; None when the dwells cannot
    tell it."""
    if not rows:
        return None
    pitch = {}
    for test in campaign.sine_tests:
        fit = fits.get(test.label)
        if fit is not None and fit.phase_rad is not None and test.amplitude:
            a = abs(test.amplitude)
            pitch[test.label] = (fit.amplitude / a, fit.amplitude_stderr / a, fit.phase_rad, fit.phase_stderr_rad or 0.0)
    return fit_heave_model(rows, pitch, _mode_of(modes))
