"""A turning rotor's campaign (issue 33): every video read pass by pass, then the static campaign's steps.

Each video goes through :func:`servoscope.pipeline.rotor.track_passes` (the blades' pitch at
ψ = 0, once a revolution each, with its error; the rotor's speed; the LED's switch). Each dwell's
sine is fitted to its passes with one offset a blade (:func:`servoscope.sysid.pass_sine.fit_pass_sine`),
the step is read from the passes (:func:`servoscope.sysid.pass_step.analyse_pass_step`), and the
frequency response and the transfer-function fit are the static campaign's own
(:mod:`servoscope.campaign.runner`). The passes also travel as a :class:`~servoscope.markers.track.Track`
whose "frames" are the passes (:func:`pass_track`), so that result.json, the tables and the report
read a rotor's tests as they read a static one's.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Callable

import numpy as np

from ..angle.pass_table import PassTable
from ..errors import ServoscopeError
from ..markers.settings import TrackerSettings
from ..markers.track import Track
from ..parameters import interval95, inverse_variance_mean
from ..pipeline.rotor import track_passes
from ..sysid.pass_sine import fit_pass_sine
from ..sysid.pass_step import analyse_pass_step
from .manifest import Campaign, TestSpec

__all__ = ["blades_by_colour", "codec_warning", "pass_track", "rotor_dwell_fits", "rotor_step", "rotor_summary", "track_rotor_campaign"]


def pass_track(table: PassTable, video: str) -> Track:
    """The passes of one video as a :class:`Track` whose samples are the passes (one a pass, in time order).

    ``time_s`` is each pass's ψ = 0 time, ``angle_rad`` the blade's pitch then (its offset left in),
    ``angle_sigma_rad`` its standard error, ``frame`` the pass's middle frame; the stickers' pixel
    positions are not a pass's quantity (NaN). The LED's switch is the table's.
    """
    n = len(table.time_s)
    nan2 = np.full((n, 2), np.nan)
    first, last = np.asarray(table.first_frame), np.asarray(table.last_frame)
    middle = (first + last) // 2 if first.size == n else np.arange(n)
    return Track(
        video=video, frame=np.asarray(middle, dtype=np.int64), time_s=np.asarray(table.time_s, dtype=np.float64),
        lead_xy_px=nan2, trail_xy_px=nan2.copy(), lead_area_px=np.full(n, np.nan), trail_area_px=np.full(n, np.nan),
        angle_rad=np.asarray(table.pitch_rad, dtype=np.float64), valid=np.isfinite(table.pitch_rad),
        reason=[""] * n, led_level=np.full(n, np.nan), warnings=tuple(table.warnings),
        angle_sigma_rad=np.asarray(table.pitch_stderr_rad, dtype=np.float64),
        t0_s=table.t0_s, t0_uncertainty_s=table.t0_uncertainty_s,
    )


def _settings(campaign: Campaign) -> TrackerSettings:
    return TrackerSettings(led=campaign.led, led_near=campaign.led_near, camera=campaign.camera,
                           exposure_s=campaign.exposure_s, readout_s=campaign.readout_s, timestamp=campaign.timestamp)


def track_rotor_campaign(campaign: Campaign, *, keep_going: bool = False, failures: dict[str, str] | None = None,
                         progress: Callable[[str, int, int], None] | None = None) -> dict[str, PassTable]:
    """Every test's video read pass by pass: label → :class:`PassTable`, in manifest order.

    ``keep_going``: a video that cannot be read is left out (its reason in ``failures``) instead of
    ending the run.
    """
    if campaign.rotor is None:
        raise ServoscopeError(f"{campaign.path}: no [rotor] section: a static campaign is tracked by track_campaign")
    settings = _settings(campaign)
    tables: dict[str, PassTable] = {}
    for index, test in enumerate(campaign.tests):
        report = (lambda frames, label=test.label, i=index: progress(label, frames, i)) if progress else None
        try:
            tables[test.label] = track_passes(test.video, settings, rotor=campaign.rotor, progress=report)
        except ServoscopeError as exc:
            if not keep_going:
                raise
            if failures is not None:
                failures[test.label] = str(exc)
    return tables


def rotor_dwell_fits(campaign: Campaign, tables: dict[str, PassTable], warnings: list[str]) -> dict:
    """Each sine dwell's fit to its passes (label → :class:`~servoscope.sysid.pass_result.PassSineFit`)."""
    n_blades = len(campaign.rotor.blades)
    fits = {}
    for test in campaign.sine_tests:
        table = tables.get(test.label)
        if table is None:
            continue
        t0 = test.t0_s if test.t0_s is not None else table.t0_s
        if t0 is None:
            warnings.append(f"{test.label}: no input start (LED or t0_s): phase unknown")
        try:
            fit = fit_pass_sine(table.time_s, table.blade, table.pitch_rad, table.pitch_stderr_rad,
                                test.frequency_hz, t0_s=t0, settle_s=campaign.settle_s,
                                # measured: [rotor] rev_per_s is the planned one (the tracker falls back on it)
                                rev_per_s=table.rev_per_s, n_blades=n_blades,
                                t0_stderr_s=table.t0_uncertainty_s if test.t0_s is None else 0.0)
        except ServoscopeError as exc:
            warnings.append(f"{test.label}: dwell left out: {exc}")
            continue
        fits[test.label] = fit
        warnings.extend(f"{test.label}: {w}" for w in fit.warnings if w)
    return fits


def rotor_step(campaign: Campaign, tables: dict[str, PassTable], model, warnings: list[str]):
    """The first step test read from its passes, with the model's prediction: (analysis, label) or (None, None)."""
    if not campaign.step_tests:
        return None, None
    test: TestSpec = campaign.step_tests[0]
    table = tables.get(test.label)
    if table is None:
        return None, None
    t0 = test.t0_s if test.t0_s is not None else table.t0_s
    if t0 is None:
        warnings.append(f"{test.label}: step test without an input start (LED or t0_s): left out")
        return None, None
    try:
        step = analyse_pass_step(table.time_s, table.blade, table.pitch_rad, t0_s=t0, step_size=test.amplitude,
                                 model=model.transfer_function, t0_stderr_s=table.t0_uncertainty_s)
    except ServoscopeError as exc:
        warnings.append(f"{test.label}: step test left out: {exc}")
        return None, None
    warnings.extend(f"{test.label}: {w}" for w in step.warnings if w)
    return step, test.label


#: Codecs whose prediction and quantization smooth a sticker's small vertical offset across a pass.
_LOSSY = ("h264", "hevc", "mpeg2video", "mpeg4", "vp9", "av1")


def codec_warning(campaign: Campaign) -> str | None:
    """A warning where the rotor's videos are lossy-compressed (the passes' pitch reads small), else None."""
    from ..video.reader import probe_video

    codecs = sorted({probe_video(t.video).codec for t in campaign.tests if not Path(t.video).is_dir()} & set(_LOSSY))
    if not codecs:
        return None
    return (f"the rotor's videos are {', '.join(codecs)}: on the twin (H.264 at 40 Mbit/s, 320×240) the codec "
            f"shrank the passes' pitch by 1.6-2.7 %, so the gain read that much low, beyond its interval "
            f"(docs/rotor.md); a high-speed camera's raw or monochrome file does not (0.1-0.9 %)")


def blades_by_colour(campaign: Campaign) -> bool:
    """Whether each blade has its own colours (else, on a monochrome camera's footage, the blades are told apart
    by their order in each video: blade 0 is that video's first seen, not the same blade in every video)."""
    return len(set(campaign.rotor.blades)) == len(campaign.rotor.blades) and not any(
        "bright" in pair for pair in campaign.rotor.blades)


def rotor_summary(campaign: Campaign, tables: dict[str, PassTable], fits: dict) -> dict:
    """result.json's ``rotor``.

    Its blades (``identified_by``: "colour" or "order"), each test's rev/s and passes and each dwell's
    blade-to-blade differences, and, where the blades are known by their colours, each blade's pitch
    against blade 0's pooled over the dwells (inverse-variance mean, its error the larger of the pooled
    one and the dwells' scatter about it, a Student-t interval). Blades known only by their order are
    not pooled: blade 0 may be a different blade in each video.
    """
    tests = []
    for label, t in tables.items():
        entry = {"label": label, "rev_per_s": float(t.rev_per_s), "rev_per_s_stderr": float(t.rev_per_s_stderr),
                 "passes": int(len(t.time_s))}
        if label in fits:
            entry["blade_differences"] = [d.summary() for d in fits[label].blade_differences]
        tests.append(entry)
    by_colour = blades_by_colour(campaign)
    differences = []
    for blade in range(1, len(campaign.rotor.blades)) if by_colour else ():
        values, errors = [], []
        for fit in fits.values():
            for d in fit.blade_differences:
                if d.blade == blade and d.reference_blade == 0 and math.isfinite(d.difference_stderr_rad) \
                        and d.difference_stderr_rad > 0:
                    values.append(d.difference_rad)
                    errors.append(d.difference_stderr_rad)
        if not values:
            continue
        mean, stderr = inverse_variance_mean(values, errors)  # the dwells' scatter widens it where larger
        n = len(values)
        ci = interval95(mean, stderr, "student", dof=n - 1) if n > 1 else interval95(mean, stderr)
        differences.append({"blade": blade, "reference_blade": 0, "difference_rad": mean,
                            "difference_stderr_rad": stderr, "ci95_rad": [float(ci[0]), float(ci[1])],
                            "dwells": n})
    return {"blades": [list(b) for b in campaign.rotor.blades], "identified_by": "colour" if by_colour else "order",
            "tests": tests, "blade_differences": differences}
