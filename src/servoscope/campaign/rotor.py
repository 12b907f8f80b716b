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
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

import numpy as np

from ..angle.pass_table import PassTable
from ..errors import ServoscopeError
from ..markers.settings import TrackerSettings
from ..markers.track import Track
from ..parameters import interval95, inverse_variance_mean
from ..pipeline.rotor import monochrome_blades, track_passes
from ..sysid.pass_result import BladeDifference
from ..sysid.pass_sine import fit_pass_sine
from ..sysid.pass_step import analyse_pass_step
from .manifest import Campaign, TestSpec
from .step_test import step_with_model_error

__all__ = ["ROTOR_AMPLITUDE_STDERR_COLOUR_RAD", "ROTOR_AMPLITUDE_STDERR_MONO_RAD", "ROTOR_SCALE_STDERR_COLOUR",
           "ROTOR_SCALE_STDERR_MONO", "RotorSystematics", "blades_by_colour", "codec_warning", "pass_track",
           "rotor_dwell_fits", "rotor_scale_error", "rotor_settings", "rotor_step", "rotor_summary",
           "rotor_systematics",
           "track_rotor_campaign"]


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


def rotor_settings(campaign: Campaign) -> TrackerSettings:
    """How the campaign's rotor videos are read: its LED, lens, shutter and timestamps (``identify``'s and the
    report's frame alike)."""
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
    settings = rotor_settings(campaign)
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


def rotor_dwell_fits(campaign: Campaign, tables: dict[str, PassTable], warnings: list[str], *,
                     shared: RotorSystematics | None = None) -> dict:
    """Each sine dwell's fit to its passes (label → :class:`~servoscope.sysid.pass_result.PassSineFit`), each
    amplitude's error with the dwell's share of the passes' systematic error (``shared``, default
    :func:`rotor_systematics` of the campaign)."""
    n_blades = len(campaign.rotor.blades)
    shared = shared or rotor_systematics(campaign)
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
        if shared is not None:
            # Each dwell's own share of the stickers' sub-pixel bias (RotorSystematics): its amplitude's error;
            # and each blade's own, constant through the campaign (its stickers cross the same rows every
            # revolution): in every blade-to-blade difference, √2 of it (two blades).
            fit = replace(fit, amplitude_stderr=math.hypot(fit.amplitude_stderr, shared.amplitude_stderr_rad),
                          blade_differences=tuple(_with_blade_bias(d, shared) for d in fit.blade_differences))
        fits[test.label] = fit
        warnings.extend(f"{test.label}: {w}" for w in fit.warnings if w)
    return fits


def _with_blade_bias(d: BladeDifference, shared: RotorSystematics) -> BladeDifference:
    """``d`` with √2 × the blades' constant bias added to its error in quadrature, its interval widened alike."""
    if not (math.isfinite(d.difference_stderr_rad) and d.difference_stderr_rad > 0):
        return d
    se = math.hypot(d.difference_stderr_rad, math.sqrt(2.0) * shared.amplitude_stderr_rad)
    half = 0.5 * (d.ci95_rad[1] - d.ci95_rad[0]) * se / d.difference_stderr_rad
    return replace(d, difference_stderr_rad=se, ci95_rad=(d.difference_rad - half, d.difference_rad + half))


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

    def run_step(tf):
        return analyse_pass_step(table.time_s, table.blade, table.pitch_rad, t0_s=t0, step_size=test.amplitude,
                                 model=tf, t0_stderr_s=table.t0_uncertainty_s)

    try:
        # Fitted against the model's shape, as a static step is: the model's uncertainty in ωn and ζ is the
        # dead time's too. Passes 10-25 ms apart lean on that shape more than frames do (3 blades at 25 rev/s,
        # 2,000 frames/s: τ 84.84 ± 0.08 ms against 85.00 without it, the interval missing the truth).
        step = step_with_model_error(run_step, model)
    except ServoscopeError as exc:
        warnings.append(f"{test.label}: step test left out: {exc}")
        return None, None
    warnings.extend(f"{test.label}: {w}" for w in step.warnings if w)
    return step, test.label


#: Codecs whose prediction and quantization smooth a sticker's small vertical offset across a pass.
_LOSSY = ("h264", "hevc", "mpeg2video", "mpeg4", "vp9", "av1")

#: What the passes' pitch shares beyond its stated errors, measured on the twin (docs/rotor.md, "The pitch's
#: scale"). Each sticker's centroid carries a vertical sub-pixel bias that follows its row (up to ~0.03 px,
#: the same with or without noise, blur or a codec), frozen through a pass (the stickers move along the rows),
#: and over a dwell the sticker nearer the pitch axis moves only a few tenths of a pixel: the bias's gradient
#: there reads as a scale of the pitch, whose sign the footage does not tell. On colour footage (raw yuv420p or
#: H.264 at 0.03-0.33 bit per pixel; stickers 10-21 px; mean pitch 0-5°; 4,000-5,000 frames/s) the pitch per
#: pass against the truth has a slope of 0.983-1.017 (RMS 1.3 % about 1) at ±1.3° of pitch, and each dwell's
#: amplitude errs by 0.005-0.034° (RMS 0.02°) whatever its size, so that a small dwell's gain errs most
#: (+6 % at 0.35°). Two terms, then: a scale common to every dwell (the gain's interval, after the fit) and an
#: amplitude error of each dwell's own (its gain's error, which the fit carries into ωn and ζ).
#: Since session 10 a sticker's height is read on luma (markers/pass_centroid.py, ≤ 0.003 px; slopes 0.998-1.006
#: on 4 mm stickers), but a sticker within 20 DN of the blade's luma (the twin's blue) or nearly as tall as the tip
#: is thick keeps the kernel's: the slopes' RMS about 1 is still 0.61 % over the ten clips measured (3 mm with a
#: blue lead 1.0067 raw, 1.0116 H.264; 6 mm 0.990), and the term stays until the narrower one is checked on the
#: 3 mm / 5,000 frames/s and 3-blade campaigns.
ROTOR_SCALE_STDERR_COLOUR = 0.013
#: Each dwell's amplitude error on colour footage, rad (1σ; 0.02°).
ROTOR_AMPLITUDE_STDERR_COLOUR_RAD = math.radians(0.02)
#: The same on a monochrome camera's native samples (the luma-only kernel, no chroma): the paper-rotor
#: campaign's dwells read 0.1-0.9 % low, K 0.3 % low.
ROTOR_SCALE_STDERR_MONO = 0.005
#: Each dwell's amplitude error on monochrome footage, rad (1σ; 0.005°).
ROTOR_AMPLITUDE_STDERR_MONO_RAD = math.radians(0.005)


@dataclass(frozen=True)
class RotorSystematics:
    """What a rotor campaign's passes share beyond their stated errors (module constants; docs/rotor.md).

    Attributes
    ----------
    scale_relative_stderr : float
        The pitch's scale, common to every dwell (0.013: 1.3 %): added to the gain's error after the fit.
    amplitude_stderr_rad : float
        Each dwell's own amplitude error (rad): added to its amplitude's error before the fit.
    why : str
        The footage it was sized for, as the warnings say it.
    lossy_codecs : tuple of str
        The decoders of the campaign's lossy-compressed videos (:func:`codec_warning`).
    """

    scale_relative_stderr: float
    amplitude_stderr_rad: float
    why: str
    lossy_codecs: tuple[str, ...] = ()

    @property
    def scale_error(self) -> tuple[float, str]:
        """(relative σ, why) for the runner's gain interval (:func:`~servoscope.sysid.with_gain_scale_uncertainty`)."""
        return self.scale_relative_stderr, self.why

    def summary(self) -> dict:
        """Plain values for result.json's ``rotor``."""
        return {"pitch_scale_relative_stderr": float(self.scale_relative_stderr),
                "dwell_amplitude_stderr_rad": float(self.amplitude_stderr_rad), "why": self.why}


def _codecs(campaign: Campaign) -> list[str]:
    """The decoder names of the campaign's video files (image folders and high-speed files left out)."""
    from ..video.reader import probe_video

    names = set()
    for t in campaign.tests:
        if Path(t.video).is_dir():
            continue
        try:
            names.add(probe_video(t.video).codec)
        except ServoscopeError:
            continue
    return sorted(names)


def rotor_systematics(campaign: Campaign) -> RotorSystematics | None:
    """The passes' shared errors for this campaign's footage (:class:`RotorSystematics`), None when static.

    Colour footage (each blade its own colours: chroma at half resolution, and a codec's smoothing where
    lossy) :data:`ROTOR_SCALE_STDERR_COLOUR` and :data:`ROTOR_AMPLITUDE_STDERR_COLOUR_RAD`; a monochrome
    camera's (every sticker ``"bright"``) :data:`ROTOR_SCALE_STDERR_MONO` and
    :data:`ROTOR_AMPLITUDE_STDERR_MONO_RAD`.
    """
    if campaign.rotor is None:
        return None
    lossy = tuple(sorted(set(_codecs(campaign)) & set(_LOSSY)))  # the videos probed once, here
    if monochrome_blades(campaign.rotor):
        return RotorSystematics(ROTOR_SCALE_STDERR_MONO, ROTOR_AMPLITUDE_STDERR_MONO_RAD,
                                "a turning rotor's passes on monochrome footage: each sticker's sub-pixel "
                                "bias, frozen through a pass, reads as a scale of the pitch (docs/rotor.md)", lossy)
    what = f"{', '.join(lossy)}-compressed colour footage" if lossy else "colour footage"
    return RotorSystematics(ROTOR_SCALE_STDERR_COLOUR, ROTOR_AMPLITUDE_STDERR_COLOUR_RAD,
                            f"a turning rotor's passes on {what}: each sticker's sub-pixel bias, frozen through a "
                            "pass, reads as a scale of the pitch (slope 0.983-1.017 on the twin, 0.998-1.006 where its height "
                            "is read on luma: kept for the stickers whose is not) and errs a dwell's amplitude by "
                            "~0.02° (docs/rotor.md)", lossy)


def rotor_scale_error(campaign: Campaign) -> tuple[float, str] | None:
    """(relative σ, why) of the pitch's scale for the runner's gain interval
    (:func:`~servoscope.sysid.with_gain_scale_uncertainty`), or None for a static campaign."""
    shared = rotor_systematics(campaign)
    return None if shared is None else shared.scale_error


def codec_warning(campaign: Campaign, *, shared: RotorSystematics | None = None) -> str | None:
    """A warning where the rotor's videos are lossy-compressed (the passes' pitch scale less sure), else None.
    ``shared``: the campaign's :func:`rotor_systematics`, where already made."""
    shared = shared or rotor_systematics(campaign)
    codecs = [] if shared is None else list(shared.lossy_codecs)
    if not codecs:
        return None
    return (f"the rotor's videos are {', '.join(codecs)}: on the twin a codec moved the passes' pitch scale by "
            f"-0.6 to +0.9 % against the same footage raw (H.264 at 0.03-0.33 bit per pixel), inside the "
            f"±{100 * ROTOR_SCALE_STDERR_COLOUR:.1f} % (1σ) that colour footage's gain interval carries "
            f"(docs/rotor.md)")


def blades_by_colour(campaign: Campaign) -> bool:
    """Whether each blade has its own colours (else, on a monochrome camera's footage, the blades are told apart
    by their order in each video: blade 0 is that video's first seen, not the same blade in every video)."""
    return len(set(campaign.rotor.blades)) == len(campaign.rotor.blades) and not monochrome_blades(campaign.rotor)


def rotor_summary(campaign: Campaign, tables: dict[str, PassTable], fits: dict, *,
                  shared: RotorSystematics | None = None) -> dict:
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
    shared = shared or rotor_systematics(campaign)
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
        # The blades' constant bias is in every dwell's error (rotor_dwell_fits) but does not average over the
        # dwells: pooled without it, then added back.
        bias = 0.0 if shared is None else math.sqrt(2.0) * shared.amplitude_stderr_rad
        random = [math.sqrt(max(e * e - bias * bias, 0.0)) or e for e in errors]
        mean, spread = inverse_variance_mean(values, random)  # the dwells' scatter widens it where larger
        stderr = math.hypot(spread, bias)
        n = len(values)
        # A Student-t for what the few dwells' scatter tells, a normal for the bias's stated size.
        half = math.hypot((interval95(0.0, spread, "student", dof=n - 1) if n > 1 else interval95(0.0, spread))[1],
                          interval95(0.0, bias)[1])
        ci = (mean - half, mean + half)
        differences.append({"blade": blade, "reference_blade": 0, "difference_rad": mean,
                            "difference_stderr_rad": stderr, "ci95_rad": [float(ci[0]), float(ci[1])],
                            "dwells": n})
    return {"blades": [list(b) for b in campaign.rotor.blades], "identified_by": "colour" if by_colour else "order",
            "tests": tests, "blade_differences": differences,
            # What the passes share beyond their stated errors, in the dwells' and the gain's intervals.
            "systematic": None if shared is None else shared.summary()}
