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
from ..sysid.heave import HeaveModel, HeaveRow, dwell_heave, fit_heave_model, heave_systematic_px
from ..sysid.modes import ModeFit, fit_damped_modes, fit_mode_shapes, pool_modes
from .manifest import Campaign
from .result import input_start

__all__ = ["HEAVE_MIN_Z", "MIN_RINGDOWN_PERIODS", "axis_of", "bending_response", "blade_modes", "dwell_modes",
           "heave_model", "heave_response", "step_ringdown_warning"]

#: A dwell's heave at its frequency counts as measured when its amplitude is this many standard errors.
HEAVE_MIN_Z = 5.0


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
            if abs(test.frequency_hz / mode.frequency_hz - 1.0) >= 3.0 * mode.damping_ratio + 0.02:
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


def heave_response(campaign: Campaign, tracks: dict[str, Track], fits: dict[str, SineFit], pivot,
                   modes: list[ModeFit] | None = None) -> list[HeaveRow]:
    """Each fitted dwell's heave at its input frequency; empty unless one of them is measured.

    ``modes``: the blade's modes found (the step's first): their ring-downs are fitted
    beside each dwell's sine (:func:`~servoscope.sysid.heave.dwell_heave`). The systematic floor
    is the footage's (:func:`~servoscope.sysid.heave.heave_systematic_px`).

    ``pivot`` is the pitch axis (:func:`axis_of`: an axis found on a small swing is uncertain,
    and its error would read as heave at the input frequency). A campaign whose dwells show
    no heave beyond :data:`HEAVE_MIN_Z` standard errors (a rigid blade) gets none, so its
    result is as before.
    """
    if pivot is None:
        return []
    rows = []
    for test, track, fit, t0, h in _dwell_heaves(campaign, tracks, fits, pivot):
        row = dwell_heave(track.angle_time_s, h, test.frequency_hz, t0, test.amplitude, fit.window_s, test.label,
                          systematic_px=heave_systematic_px(track.intra), mode=_mode_of(modes))
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
