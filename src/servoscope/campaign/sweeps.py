"""A campaign's frequency sweeps: each one's spectral frequency response, and one response from every test.

Steps of :func:`servoscope.campaign.runner.identify` (issue 31). A sweep's input is known (the
chirp of its ``[[tests]]`` entry, or its recorded input ``input = "u.csv"``: a pilot's stick,
:meth:`~servoscope.campaign.manifest.TestSpec.command`)
from the instant the LED dates; its output is the tracked angle. :func:`sweep_responses`
turns each into a :class:`~servoscope.sysid.sweep_result.SweepResponse` (CIFER's composite
of windowed cross-spectra with coherence, :func:`servoscope.sysid.sweep.sweep_response`);
:func:`combined_response` puts the sweeps' points with coherence ≥ 0.6 beside the dwells', each
with its own error, for one transfer-function fit.
"""

from __future__ import annotations

import math

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from ..errors import ServoscopeError
from ..markers.track import Track
from ..sysid import FrequencyResponse
from ..sysid.sweep import sweep_response
from ..sysid.sweep_result import SweepResponse
from .manifest import Campaign
from .result import input_start, input_start_stderr

__all__ = ["LAG_NEIGHBOURS", "MIN_LAG_IFRAMES", "codec_lag_s", "combined_response", "sweep_responses",
           "sweeps_t0_stderr"]


def sweep_responses(campaign: Campaign, tracks: dict[str, Track], warnings: list[str]) -> dict[str, SweepResponse]:
    """Each sweep test's frequency response, by label; a sweep that cannot give one is left out with a warning
    that says why (no input start, too few valid frames, a gap, no coherent frequency)."""
    out: dict[str, SweepResponse] = {}
    for test in campaign.sweep_tests:
        track = tracks[test.label]
        t0 = input_start(test, track)
        if t0 is None:
            warnings.append(f"{test.label}: sweep left out: no input start (the LED's switch or t0_s): its input "
                            "cannot be dated, so neither its gain nor its phase can be measured")
            continue
        y = np.where(track.valid, track.angle_rad, np.nan)
        try:
            from_hz, to_hz = _band(test, track, warnings)
            response = sweep_response(track.angle_time_s, test.command(track.angle_time_s - t0), y,
                                      from_hz=from_hz, to_hz=to_hz)
            response.to_frequency_response()  # refuses a sweep with no coherent frequency, named below
        except ServoscopeError as exc:
            warnings.append(f"{test.label}: sweep left out: {exc}")
            continue
        out[test.label] = response
        warnings.extend(f"{test.label}: {w}" for w in response.warnings)
        low = int(np.count_nonzero(~response.kept))
        if low:
            warnings.append(f"{test.label}: {low} of {len(response)} frequencies have coherence below "
                            f"{response.coherence_min:g} (the output there is not the input's): left out of the fit")
    return out


def _band(test, track: Track, warnings: list[str]) -> tuple[float, float]:
    """The band a sweep is analysed in: its chirp's, or a recorded input's (given, or its own spectrum's).

    A recorded input's own band (:attr:`~servoscope.campaign.inputs.TestSpec.sweep_band_hz`) may
    start below what the record resolves: its bottom is raised, silently, to where half the
    record (the longest window :func:`~servoscope.sysid.sweep.sweep_response` takes) holds two
    periods. It may reach past what the camera resolves: it is cut at 0.45 of the frame rate,
    with a warning. A band the manifest gives is its author's and is not cut (a top at the Nyquist frequency is
    refused by :func:`~servoscope.sysid.sweep.sweep_response`, and the sweep left out, saying why).
    """
    from_hz, to_hz = test.sweep_band_hz
    if not test.recorded:
        return from_hz, to_hz
    time_s = np.asarray(track.angle_time_s, dtype=float)
    dt = np.diff(time_s)
    fs = 1.0 / float(np.median(dt)) if dt.size else np.inf
    if test.from_hz is None and dt.size:
        from_hz = max(from_hz, 1.01 * 4.0 / (time_s[-1] - time_s[0] + 1.0 / fs))
    if test.to_hz is None and to_hz >= 0.45 * fs:
        warnings.append(f"{test.label}: the recorded input's band reaches {to_hz:.3g} Hz, past what "
                        f"{fs:.4g} frames/s resolve: analysed up to {0.45 * fs:.3g} Hz (give to_hz to choose)")
        to_hz = 0.45 * fs
    if not to_hz > from_hz:
        raise ServoscopeError(f"the recorded input's band is empty once cut to what the record and the camera "
                              f"resolve ({from_hz:.3g}–{to_hz:.3g} Hz): give from_hz and to_hz")
    return from_hz, to_hz


#: The least I-frames in a sweep's record from which the codec's lag is estimated (:func:`codec_lag_s`).
MIN_LAG_IFRAMES = 10
#: Each I-frame's neighbours on either side fitted to say where the predicted frames put the stickers.
LAG_NEIGHBOURS = 4


def codec_lag_s(track: Track) -> tuple[float, float] | None:
    """How far the predicted frames' angle lags the I-frames', s, and its standard error; None where it cannot be told.

    A codec that predicts frames from others holds the stickers' motion back: at 1000 frames/s and
    40 kbit a frame H.264 put the angle 0.75 ms late, the dead time 0.92 ms long (issue 31). An
    I-frame shows the stickers where they are. At each I-frame the angle of its
    :data:`LAG_NEIGHBOURS` predicted neighbours on either side (a quadratic through them) is
    compared with the I-frame's: ``y_I − y_pred ≈ a + δ·ẏ``, and δ is the lag (least squares over
    the I-frames, its error from the residuals). None without I-frame marks, with every frame an
    I-frame, or with fewer than :data:`MIN_LAG_IFRAMES` usable I-frames.
    """
    if track.intra is None:
        return None
    intra = np.asarray(track.intra, dtype=bool)
    t = np.asarray(track.angle_time_s, float)
    y = np.where(np.asarray(track.valid, bool), np.asarray(track.angle_rad, float), np.nan)
    if intra.shape != t.shape or intra.all() or not intra.any():
        return None
    rows = []
    for i in np.flatnonzero(intra):
        lo, hi = i - LAG_NEIGHBOURS, i + LAG_NEIGHBOURS + 1
        if lo < 0 or hi > t.size or not np.isfinite(y[i]):
            continue
        near = np.r_[lo:i, i + 1:hi]
        near = near[~intra[near] & np.isfinite(y[near])]
        if near.size < 2 * LAG_NEIGHBOURS - 1:
            continue
        c = np.polyfit(t[near] - t[i], y[near], 2)
        rows.append((y[i] - c[2], c[1]))  # the I-frame's angle less the neighbours' there; their slope
    if len(rows) < MIN_LAG_IFRAMES:
        return None
    r, slope = np.array(rows).T
    design = np.column_stack([np.ones_like(slope), slope])
    coef, *_ = np.linalg.lstsq(design, r, rcond=None)
    resid = r - design @ coef
    dof = len(r) - 2
    try:
        cov = np.linalg.inv(design.T @ design) * float(resid @ resid) / dof
    except np.linalg.LinAlgError:
        return None
    return float(coef[1]), float(np.sqrt(max(cov[1, 1], 0.0)))


def sweeps_t0_stderr(campaign: Campaign, tracks: dict[str, Track], sweeps: dict[str, SweepResponse],
                     warnings: list[str] | None = None) -> float:
    """The timing error every point of a sweep shares, the largest over the sweeps, s.

    A sweep's phases all hang on its one t0: like the dwells' shared error it is added to the
    phase dead time's, not averaged away by the number of frequencies. Where the codec predicts
    frames and the record holds enough I-frames, the predicted frames' lag behind them
    (:func:`codec_lag_s`: sweeps have no codec check of their own) is added in quadrature, its
    size and its error, and ``warnings`` say so when it stands beyond 2 of its errors.
    """
    errors = []
    for test in campaign.sweep_tests:
        if test.label not in sweeps:
            continue
        error = input_start_stderr(test, tracks[test.label]) or 0.0
        lag = codec_lag_s(tracks[test.label])
        if lag is not None:
            error = math.hypot(error, lag[0], lag[1])
            if warnings is not None and abs(lag[0]) > 2.0 * lag[1]:
                warnings.append(
                    f"{test.label}: the codec's predicted frames show the stickers {1e3 * lag[0]:.2g} ± "
                    f"{1e3 * lag[1]:.2g} ms later than its I-frames do; sweeps have no codec check, so the dead "
                    f"time's error includes it (film sweeps raw, intra-only or at a higher bit rate to lose it)")
        errors.append(error)
    return float(max(errors, default=0.0))


def combined_response(dwells: FrequencyResponse | None, sweeps: dict[str, SweepResponse],
                      correct: Callable[[FrequencyResponse], FrequencyResponse] | None = None) -> FrequencyResponse:
    """The dwells' points and every sweep's kept points, sorted by frequency, each with its own error.

    `correct` is applied to each sweep's points first (the exposure's correction, which the
    dwells' response already has).

    Raises
    ------
    ServoscopeError
        With neither dwells nor a sweep (the caller says what the campaign lacked).
    """
    parts = [] if dwells is None else [dwells]
    for label, s in sweeps.items():
        # Its warnings were said once, under its label (sweep_responses).
        part = replace(s.to_frequency_response(label), warnings=())
        parts.append(part if correct is None else correct(part))
    if not parts:
        raise ServoscopeError("no dwell and no sweep gave a frequency response")
    if len(parts) == 1:
        return parts[0]
    f = np.concatenate([p.frequency_hz for p in parts])
    order = np.argsort(f, kind="stable")

    def col(name: str) -> np.ndarray:
        return np.concatenate([np.asarray(getattr(p, name), dtype=float) for p in parts])[order]

    labels = [label for p in parts for label in p.labels]
    flags = [fl for p in parts for fl in p.flags]
    return FrequencyResponse(
        frequency_hz=f[order], gain=col("gain"), gain_stderr=col("gain_stderr"), phase_deg=col("phase_deg"),
        phase_stderr_deg=col("phase_stderr_deg"), fidelity=col("fidelity"), labels=tuple(labels[i] for i in order),
        frequency_stderr_hz=col("frequency_stderr_hz"), thd=col("thd"), flags=tuple(flags[i] for i in order),
        warnings=tuple(w for p in parts for w in p.warnings))
