"""Sweep planning: which frequencies to dwell at, for how long, and what to warn about.

A plan is a ``campaign.toml`` without ``video`` keys plus a ``[plan]`` table
with what the rig needs (frame rate, servo update rate, dwell lengths,
warnings). ``servoscope drive`` reads it, runs it, and writes the completed
campaign with one video name per test.

Warning rules (see ``docs/rig.md``):

* camera: a frequency above half the frame rate aliases; below 5 frames per
  period the sine fit has too few samples per cycle;
* servo update (the command is a staircase held for ``1/update_hz``): at or
  above ``update_hz/2`` the servo sees the folded alias, not the frequency;
  above ``0.4·update_hz`` (fewer than 2.5 updates per period) the staircase's
  first image at ``update_hz − f`` carries ≥ 2/3 of the sine's amplitude;
* PWM ripple: the servo's own response to each PWM frame shakes the blade at
  ``k·update_hz``; the camera sees that at the fold of ``k·update_hz`` by the
  frame rate; a frequency within a dwell's resolution of that alias is
  contaminated by it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..defaults import LEAD_COLOUR, LED_COLOUR, MIN_DWELL_S, SETTLE_AUTO, SETTLE_S, TRAIL_COLOUR
from ..errors import ServoscopeError

__all__ = [
    "Dwell",
    "SweepPlan",
    "plan_sweep",
    "dwell_duration_s",
    "frequency_warnings",
    "fold_hz",
    "pause_options",
    "positive_option",
    "step_dwells",
    "read_plan",
    "write_plan",
    "plan_to_toml",
    "plan_campaign",
    "default_video_name",
    "with_videos",
    "MIN_FRAMES_PER_PERIOD",
    "MIN_UPDATES_PER_PERIOD",
    "PWM_HARMONICS",
]

#: Fewer camera frames per period than this draws a warning.
MIN_FRAMES_PER_PERIOD = 5.0
#: Fewer servo updates per period than this draws a warning (the staircase's
#: first image at update_hz − f then has ≥ 2/3 of the fundamental's amplitude).
MIN_UPDATES_PER_PERIOD = 2.5
#: PWM-frame harmonics k·update_hz (k = 1…PWM_HARMONICS) checked for camera aliases.
PWM_HARMONICS = 4

_DEFAULT_MARKERS = {"lead": LEAD_COLOUR, "trail": TRAIL_COLOUR, "led": LED_COLOUR}


@dataclass(frozen=True)
class Dwell:
    """One recording: a sine dwell or the step test.

    Attributes
    ----------
    kind : str
        ``"sine"``, ``"step"`` or ``"sweep"`` (a chirp from ``from_hz`` to ``to_hz``).
    amplitude : float
        Sine amplitude or step size, input units.
    frequency_hz : float or None
        Sine frequency, Hz; None for a step.
    duration_s : float
        Time the input is applied, from t0 until the command returns to
        centre, s. For a sine a whole number of periods, so the command ends at 0.
    warnings : tuple of str
        Why this dwell may measure badly.
    video : str or None
        Video file name, once known.
    label : str or None
        Optional label (the manifest's ``label``).
    max_late_ms : float or None
        After driving: the latest any command was sent behind schedule, ms.
    from_hz, to_hz : float or None
        A sweep's start and end frequencies, Hz; None otherwise.
    shape : str or None
        A sweep's shape, ``"log"`` or ``"linear"``; None otherwise.
    """

    kind: str
    amplitude: float
    frequency_hz: float | None
    duration_s: float
    warnings: tuple[str, ...] = ()
    video: str | None = None
    label: str | None = None
    max_late_ms: float | None = None
    from_hz: float | None = None
    to_hz: float | None = None
    shape: str | None = None

    def input_at(self, t_s: float | np.ndarray) -> float | np.ndarray:
        """The planned input u at time ``t_s`` after t0 (0 before t0 and after the dwell).

        Parameters
        ----------
        t_s : float or array
            Time since the input start t0, s.

        Returns
        -------
        float or array
            Input, input units: ``amplitude·sin(2πf·t)`` (sine),
            ``amplitude`` (step) or the chirp of
            :func:`servoscope.sysid.inputs.sweep_command` (sweep) for ``0 ≤ t < duration_s``.
        """
        t = np.asarray(t_s, dtype=float)
        on = (t >= 0.0) & (t < self.duration_s)
        if self.kind == "sine":
            u = self.amplitude * np.sin(2.0 * np.pi * float(self.frequency_hz) * t)
        elif self.kind == "sweep":
            from ..sysid.inputs import sweep_command

            u = sweep_command(t, self.amplitude, float(self.from_hz), float(self.to_hz), self.duration_s,
                              self.shape or "log")
        else:
            u = np.full_like(t, self.amplitude)
        out = np.where(on, u, 0.0)
        return float(out) if out.ndim == 0 else out


@dataclass(frozen=True)
class SweepPlan:
    """A planned campaign.

    Attributes
    ----------
    fps : float
        Camera frame rate, frames/s.
    update_hz : float
        Rate at which commands are streamed to the servo (its PWM rate), Hz.
    settle_s : float
        Time after t0 before the response is steady; also written as the
        manifest's ``[analysis] settle_s``, s.
    periods : float
        Periods wanted after settling in each sine dwell.
    min_seconds : float
        Shortest input duration of a dwell, s.
    lead_in_s : float
        Servo at centre with the LED lit, camera rolling, before t0, s.
    tail_s : float
        Servo back at centre after the input, before the camera stops, s.
    rest_s : float
        Wait between dwells, s.
    dwells : tuple of Dwell
        The tests in order.
    markers : dict
        The manifest's ``[markers]`` table.
    units : str
        The manifest's ``[input] units``.
    camera : dict
        The manifest's ``[camera]`` table, passed through (may be empty).
    drive : dict
        After driving: the rig settings used (``[plan.drive]``).
    settle_auto : bool
        The manifest's ``[analysis] settle_s`` is ``"auto"`` (each dwell's steady state found
        by the fit, :func:`servoscope.sysid.fit_sine`): kept when the plan is written again;
        ``settle_s`` still times the dwells.
    rotor : dict
        A turning rotor's plan (``servoscope plan --rotor-hz``, :mod:`servoscope.rig.rotor_plan`):
        ``rev_per_s``, ``n_blades``, ``pass_rate_hz``, ``pass_nyquist_hz``, ``top_hz``, ``notes``;
        empty for a static blade. Not written to campaign.toml yet (:func:`plan_campaign`).
    """

    fps: float
    update_hz: float
    settle_s: float
    periods: float
    min_seconds: float
    lead_in_s: float
    tail_s: float
    rest_s: float
    dwells: tuple[Dwell, ...]
    markers: dict[str, str] = field(default_factory=lambda: dict(_DEFAULT_MARKERS))
    units: str = "normalized"
    camera: dict[str, Any] = field(default_factory=dict)
    drive: dict[str, Any] = field(default_factory=dict)
    settle_auto: bool = False
    rotor: dict[str, Any] = field(default_factory=dict)

    @property
    def warnings(self) -> list[str]:
        """All dwells' warnings, each prefixed with its frequency."""
        return [w for d in self.dwells for w in d.warnings]

    @property
    def total_s(self) -> float:
        """Time the rig runs the plan, not counting the camera prompts, s."""
        return sum(self.lead_in_s + d.duration_s + self.tail_s for d in self.dwells) + self.rest_s * max(len(self.dwells) - 1, 0)


def fold_hz(frequency_hz: float, sample_hz: float) -> float:
    """Where a tone appears after sampling: ``|f − sample_hz·round(f/sample_hz)|``, Hz (in 0…sample_hz/2)."""
    return abs(frequency_hz - sample_hz * round(frequency_hz / sample_hz))


def dwell_duration_s(frequency_hz: float, periods: float, settle_s: float, min_seconds: float) -> float:
    """Input duration of a sine dwell, s.

    ``settle_s`` plus ``periods`` periods, at least ``min_seconds``, rounded up
    to a whole number of periods so that the command ends at zero (no jump
    when it returns to centre).
    """
    wanted_s = max(min_seconds, settle_s + periods / frequency_hz)
    n_periods = math.ceil(wanted_s * frequency_hz - 1e-9)
    return n_periods / frequency_hz


def frequency_warnings(frequency_hz: float, fps: float, update_hz: float, analysed_s: float | None = None,
                       *, ripple: bool = True) -> list[str]:
    """Why a sine dwell at ``frequency_hz`` may measure badly.

    Parameters
    ----------
    frequency_hz : float
        Dwell frequency, Hz.
    fps : float
        Camera frame rate, frames/s.
    update_hz : float
        Servo command update (PWM) rate, Hz.
    analysed_s : float, optional
        Steady-state time the fit sees (duration − settle), s; sets the
        frequency resolution ``1/analysed_s`` of the PWM-ripple check. Without
        it a 2 % band is used.
    ripple : bool
        Check for the PWM ripple (a sweep checks its whole band instead: :func:`ripple_warnings`).

    Returns
    -------
    list of str
        One line per problem, each starting with the frequency.
    """
    f = float(frequency_hz)
    tag = f"{f:g} Hz"
    out: list[str] = []
    # Camera sampling.
    if f > fps / 2:
        out.append(f"{tag}: above half the frame rate ({fps / 2:g} Hz); the camera sees it at {fold_hz(f, fps):.3g} Hz")
    elif fps / f < MIN_FRAMES_PER_PERIOD:
        out.append(f"{tag}: only {fps / f:.1f} frames per period at {fps:g} fps (fewer than {MIN_FRAMES_PER_PERIOD:g})")
    # Servo command stream: a staircase sampled at update_hz.
    if math.isclose(f, update_hz / 2):
        out.append(f"{tag}: exactly half the servo update rate; every command sample of the sine falls on a zero crossing")
    elif f > update_hz / 2:
        out.append(
            f"{tag}: at or above half the servo update rate ({update_hz / 2:g} Hz); "
            f"the servo receives its alias at {fold_hz(f, update_hz):.3g} Hz"
        )
    elif update_hz / f < MIN_UPDATES_PER_PERIOD:
        out.append(
            f"{tag}: only {update_hz / f:.1f} servo updates per period at {update_hz:g} Hz "
            f"(the staircase's image at {update_hz - f:.3g} Hz is nearly as strong)"
        )
    # PWM-frame ripple at k·update_hz as the camera sees it.
    tol_hz = max(1.0 / analysed_s, 0.02 * f) if analysed_s and analysed_s > 0 else 0.02 * f
    for k in range(1, PWM_HARMONICS + 1 if ripple else 1):
        ripple_hz = fold_hz(k * update_hz, fps)
        if abs(f - ripple_hz) < tol_hz:
            harmonic = f"{k}×" if k > 1 else ""
            out.append(
                f"{tag}: within {tol_hz:.2g} Hz of the servo's PWM ripple ({harmonic}{update_hz:g} Hz), "
                f"which the camera at {fps:g} fps sees at {ripple_hz:.3g} Hz"
            )
            break
    return out


def positive_option(value: float, option: str, *, allow_zero: bool = False) -> float:
    """``value`` as a float, checked > 0 (≥ 0 with ``allow_zero``); a ServoscopeError naming ``option`` if not."""
    value = float(value)
    if not math.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
        raise ServoscopeError(f"{option} {value:g}: must be {'≥ 0' if allow_zero else '> 0'}")
    return value


def pause_options(settle_s: float, min_seconds: float, lead_in_s: float, tail_s: float,
                  rest_s: float) -> tuple[float, float, float, float, float]:
    """A plan's times (settle, shortest input, lead-in, tail, rest between tests), each checked ≥ 0, in that order.

    Raises
    ------
    ServoscopeError
        The first one out of range, named by its option.
    """
    min_seconds = positive_option(min_seconds, "--min-seconds", allow_zero=True)
    settle_s = positive_option(settle_s, "--settle", allow_zero=True)
    return (settle_s, min_seconds, positive_option(lead_in_s, "--lead-in", allow_zero=True),
            positive_option(tail_s, "--tail", allow_zero=True), positive_option(rest_s, "--rest", allow_zero=True))


def step_dwells(step: bool, step_amplitude: float, step_seconds: float, min_seconds: float) -> list[Dwell]:
    """The plan's final step test (none without ``step``), its options checked.

    Raises
    ------
    ServoscopeError
        A step of size 0 (or not finite), or a step duration ≤ 0.
    """
    if not step:
        return []
    if not math.isfinite(step_amplitude) or step_amplitude == 0:
        raise ServoscopeError("--step-amplitude must be ≠ 0 (or use --no-step)")
    step_seconds = positive_option(step_seconds, "--step-seconds")
    return [Dwell("step", float(step_amplitude), None, max(step_seconds, min_seconds))]


def plan_sweep(
    fps: float,
    from_hz: float,
    to_hz: float,
    *,
    points: int = 14,
    amplitude: float = 0.1,
    periods: float = 8,
    min_seconds: float = MIN_DWELL_S,
    settle_s: float = SETTLE_S,
    update_hz: float = 50.0,
    step: bool = True,
    step_amplitude: float = 0.5,
    step_seconds: float = 3.0,
    lead_in_s: float = 1.0,
    tail_s: float = 0.5,
    rest_s: float = 2.0,
    markers: dict[str, str] | None = None,
    units: str = "normalized",
    amplitudes: Sequence[float] | None = None,
) -> SweepPlan:
    """Plan a log-spaced sine sweep and a final step test.

    Parameters
    ----------
    fps : float
        Camera frame rate, frames/s.
    from_hz, to_hz : float
        Lowest and highest dwell frequency, Hz.
    points : int
        Number of dwell frequencies (log-spaced, rounded to 3 significant digits).
    amplitude : float
        Sine amplitude, input units.
    periods : float
        Periods wanted after ``settle_s`` in each dwell.
    min_seconds : float
        Shortest input duration, s (:data:`~servoscope.defaults.MIN_DWELL_S`).
    settle_s : float
        Settling time after t0, s (:data:`~servoscope.defaults.SETTLE_S`); also the
        manifest's ``[analysis] settle_s``.
    update_hz : float
        Command update rate (the servo's PWM rate), Hz.
    step : bool
        Append a step test.
    step_amplitude : float
        Step size, input units (≠ 0).
    step_seconds : float
        Step duration, s (at least ``min_seconds``).
    lead_in_s, tail_s, rest_s : float
        Time before t0, after the input, and between dwells, s.
    markers : dict, optional
        ``[markers]`` colours (default: red lead, green trail, yellow LED).
    units : str
        ``[input] units``.
    amplitudes : sequence of float, optional
        Amplitude as a test axis: a dwell at every frequency for each of
        these amplitudes (frequency by frequency, smallest first), instead of
        ``amplitude`` alone; ``servoscope identify`` then compares each
        frequency's gains (the linearity check).

    Returns
    -------
    SweepPlan

    Raises
    ------
    ServoscopeError
        For an option out of range (the message names the option).
    """
    fps = positive_option(fps, "--fps")
    from_hz = positive_option(from_hz, "--from")
    to_hz = positive_option(to_hz, "--to")
    update_hz = positive_option(update_hz, "--update-hz")
    amplitude = positive_option(amplitude, "--amplitude")
    levels = [amplitude]
    if amplitudes is not None:
        levels = sorted(positive_option(a, "--amplitudes") for a in amplitudes)
        if not levels or len(set(levels)) != len(levels):
            raise ServoscopeError(f"--amplitudes {','.join(f'{a:g}' for a in amplitudes)}: give distinct amplitudes")
    periods = positive_option(periods, "--periods")
    settle_s, min_seconds, lead_in_s, tail_s, rest_s = pause_options(settle_s, min_seconds, lead_in_s, tail_s, rest_s)
    if to_hz < from_hz:
        raise ServoscopeError(f"--to {to_hz:g} is below --from {from_hz:g}")
    if int(points) != points or points < 1:
        raise ServoscopeError(f"--points {points}: must be a whole number ≥ 1")
    points = int(points)
    if points == 1 and to_hz != from_hz:
        raise ServoscopeError("--points 1 needs --from equal to --to (or use --points ≥ 2)")
    steps = step_dwells(step, step_amplitude, step_seconds, min_seconds)

    raw_hz = np.geomspace(from_hz, to_hz, points) if points > 1 else np.array([from_hz])
    # 3 significant digits: readable file names and tables, spacing still log to ±0.5 %.
    freqs_hz = [float(f"{f:.3g}") for f in raw_hz]
    if len(set(freqs_hz)) != len(freqs_hz):
        raise ServoscopeError(f"--points {points}: too many for {from_hz:g}…{to_hz:g} Hz (frequencies coincide)")

    dwells = []
    for f in freqs_hz:
        duration = dwell_duration_s(f, periods, settle_s, min_seconds)
        for level in levels:
            dwells.append(Dwell("sine", level, f, duration,
                                tuple(frequency_warnings(f, fps, update_hz, duration - settle_s))))
    dwells += steps
    return SweepPlan(
        fps=fps, update_hz=update_hz, settle_s=settle_s, periods=periods, min_seconds=min_seconds,
        lead_in_s=lead_in_s, tail_s=tail_s, rest_s=rest_s, dwells=tuple(dwells),
        markers=dict(markers or _DEFAULT_MARKERS), units=units,
    )


def default_video_name(index: int, dwell: Dwell, n_steps: int = 1) -> str:
    """The video name ``drive`` gives a test: ``dwell_01_0.50Hz.mp4``, ``sweep_01_0.5-20Hz.mp4`` or ``step.mp4``.

    Parameters
    ----------
    index : int
        1-based position of the test in the plan.
    dwell : Dwell
    n_steps : int
        Number of step tests in the plan (numbered ``step_NN.mp4`` when > 1).
    """
    if dwell.kind == "sine":
        return f"dwell_{index:02d}_{dwell.frequency_hz:.2f}Hz.mp4"
    if dwell.kind == "sweep":
        return f"sweep_{index:02d}_{dwell.from_hz:g}-{dwell.to_hz:g}Hz.mp4"
    return "step.mp4" if n_steps <= 1 else f"step_{index:02d}.mp4"


# ---------------------------------------------------------------------------
# The plan as a campaign: written and read as campaign.toml (servoscope.campaign.toml_io).


def _header(plan: SweepPlan) -> str:
    if all(d.video for d in plan.dwells):
        return "# servoscope campaign, recorded by `servoscope drive`\n\n"
    return "# servoscope campaign plan: `servoscope drive` fills in the videos\n\n"


def _plan_table(plan: SweepPlan) -> dict[str, Any]:
    """``[plan]``: the rig's settings, ``[plan.drive]`` once driven, one ``[[plan.dwells]]`` per test."""
    table: dict[str, Any] = {
        "fps": float(plan.fps), "update_hz": float(plan.update_hz), "settle_s": float(plan.settle_s),
        "periods": float(plan.periods), "min_seconds": float(plan.min_seconds),
        "lead_in_s": float(plan.lead_in_s), "tail_s": float(plan.tail_s), "rest_s": float(plan.rest_s),
    }
    if plan.drive:
        table["drive"] = dict(plan.drive)
    table["dwells"] = [{k: v for k, v in {"duration_s": float(d.duration_s), "warnings": list(d.warnings),
                                           "max_late_ms": d.max_late_ms}.items() if v is not None}
                       for d in plan.dwells]
    return table


def plan_campaign(plan: SweepPlan, path: str | Path = "campaign.toml", *, include_plan: bool = True):
    """The plan as a :class:`~servoscope.campaign.manifest.Campaign` whose manifest would be ``path``.

    Its tests have no video until driven; with ``include_plan`` it keeps the ``[plan]`` table.
    The camera's files are named, not read.
    """
    from ..campaign.manifest import campaign_from_data

    data: dict[str, Any] = {"camera": dict(plan.camera)} if plan.camera else {}
    data.update({
        "markers": dict(plan.markers), "input": {"units": plan.units},
        "analysis": {"settle_s": SETTLE_AUTO if plan.settle_auto else float(plan.settle_s)},
        "tests": [{k: v for k, v in {
            "video": d.video, "label": d.label, "kind": d.kind,
            "frequency_hz": None if d.frequency_hz is None else float(d.frequency_hz),
            "amplitude": float(d.amplitude), **_sweep_keys(d)}.items() if v is not None} for d in plan.dwells],
        "plan": _plan_table(plan),
    })
    if plan.rotor:  # a turning rotor's plan: campaign.toml's [rotor], each blade's colours and the speed
        if not plan.rotor.get("blades"):
            raise ServoscopeError(f"a rotor of {plan.rotor['n_blades']} blades: name each blade's colours "
                                  "(--blade-colours LEAD/TRAIL,LEAD/TRAIL,...), the defaults have 3")
        data["rotor"] = {"blades": [{"lead": a, "trail": b} for a, b in plan.rotor["blades"]],
                         "rev_per_s": float(plan.rotor["rev_per_s"])}
    campaign = campaign_from_data(data, Path(path), check_videos=False, planned=True, read_files=False)
    return campaign if include_plan else replace(campaign, plan={})


def _sweep_keys(d: Dwell) -> dict[str, Any]:
    """A sweep test's own keys in ``[[tests]]`` (none for a sine or a step)."""
    if d.kind != "sweep":
        return {}
    return {"from_hz": float(d.from_hz), "to_hz": float(d.to_hz), "duration_s": float(d.duration_s),
            "shape": d.shape or "log"}


def plan_to_toml(plan: SweepPlan, *, include_plan: bool = True) -> str:
    """The plan (or, with videos filled in, the campaign) as TOML text.

    Parameters
    ----------
    plan : SweepPlan
    include_plan : bool
        Write the ``[plan]`` table (rig information the analysis ignores).

    Returns
    -------
    str
        TOML that :func:`read_plan` reads back to the same plan (:meth:`Campaign.to_toml
        <servoscope.campaign.manifest.Campaign.to_toml>`).
    """
    return plan_campaign(plan, include_plan=include_plan).to_toml(_header(plan))


def write_plan(plan: SweepPlan, path: str | Path) -> Path:
    """Write :func:`plan_to_toml` to ``path`` (atomically); returns the path."""
    return plan_campaign(plan, path).save(path, header=_header(plan))


def read_plan(path: str | Path) -> SweepPlan:
    """Read a plan written by ``servoscope plan`` (or a campaign written by ``drive``).

    Read as a campaign (:meth:`Campaign.load <servoscope.campaign.manifest.Campaign.load>`
    with ``planned=True``): every problem of the file is reported at once.

    Parameters
    ----------
    path : path-like

    Returns
    -------
    SweepPlan

    Raises
    ------
    ServoscopeError
        If the file is missing, not TOML, has no ``[plan]`` table, or its
        tests and ``[[plan.dwells]]`` disagree (with every other problem).
    """
    from ..campaign.manifest import Campaign
    from ..campaign.toml_io import camera_table, markers_table, test_entries

    path = Path(path)
    if not path.exists():
        raise ServoscopeError(f"{path}: no such plan (make one with `servoscope plan`)")
    campaign = Campaign.load(path, check_videos=False, planned=True)
    plan_t = campaign.plan
    dwells = tuple(
        Dwell(t.kind, t.amplitude, t.frequency_hz, float(extra["duration_s"]), tuple(extra.get("warnings", [])),
              entry.get("video"), entry.get("label"), extra.get("max_late_ms"),
              *((t.from_hz, t.to_hz, t.shape) if t.kind == "sweep" else ()))
        for t, entry, extra in zip(campaign.tests, test_entries(campaign), plan_t["dwells"], strict=True))
    for i, (t, d) in enumerate(zip(campaign.tests, dwells), start=1):
        if t.kind == "sweep" and not math.isclose(t.duration_s, d.duration_s, rel_tol=1e-9):
            raise ServoscopeError(f"{path}: tests[{i}].duration_s {t.duration_s:g} and plan.dwells[{i}].duration_s "
                                  f"{d.duration_s:g} disagree (the sweep's length is both)")
    auto = campaign.settle_s == SETTLE_AUTO

    def get(key: str, default: float) -> float:
        return float(plan_t.get(key, default))

    return SweepPlan(
        fps=float(plan_t["fps"]), update_hz=get("update_hz", 50.0),
        # A plan needs seconds to time its dwells: settle_s = "auto" leaves it the default.
        settle_s=get("settle_s", SETTLE_S if auto else campaign.settle_s),
        periods=get("periods", 8.0), min_seconds=get("min_seconds", MIN_DWELL_S),
        lead_in_s=get("lead_in_s", 1.0), tail_s=get("tail_s", 0.5), rest_s=get("rest_s", 2.0),
        dwells=dwells, units=campaign.input_units,
        markers={k: v for k, v in markers_table(campaign).items() if v is not None},
        camera={k: v for k, v in camera_table(campaign).items() if v is not None},
        drive=dict(plan_t.get("drive", {})), settle_auto=auto,
        rotor={} if campaign.rotor is None else campaign.rotor.plan_rotor(),
    )


def with_videos(plan: SweepPlan, videos: list[str]) -> SweepPlan:
    """The plan with the given video names (one per test, in order)."""
    return replace(plan, dwells=tuple(replace(d, video=v) for d, v in zip(plan.dwells, videos, strict=True)))
