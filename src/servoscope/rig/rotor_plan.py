"""Planning dwells for a turning rotor: ``servoscope plan --rotor-hz 20 --blades 2``.

A camera in the rotor's plane reads each blade's pitch once a revolution, as the blade
points at it: N blades at Ω rev/s give N·Ω pitch samples a second, and the dwells must stay
below their Nyquist frequency N·Ω/2 (:func:`servoscope.sysid.pass_sine.pass_nyquist_hz`):
above it the passes cannot tell a dwell at f from one at N·Ω − f. The plan's highest dwell
is :data:`ROTOR_TOP_FRACTION` of it (14 Hz at 20 rev/s and 2 blades, where the paper's sweep
stopped at 15 Hz), few enough passes a period for the fit
(:func:`~servoscope.sysid.pass_sine.fit_pass_sine`) to stay clear of the Nyquist frequency's
warning (:data:`~servoscope.defaults.NEAR_NYQUIST`). A dwell that lands near a multiple of
the rotor speed (k·Ω, below the Nyquist frequency with 3 blades or more) looks still to every
blade and cannot be told from the blades' offsets: it is warned about.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

from ..errors import ServoscopeError
from ..defaults import ROTOR_BLADE_COLOURS
from ..sysid.pass_sine import pass_nyquist_hz, rotor_harmonic_warning
from .plan import SweepPlan, plan_sweep, positive_option

__all__ = ["ROTOR_TOP_FRACTION", "parse_blade_colours", "plan_rotor_sweep", "rotor_lines", "rotor_top_hz"]

#: The highest dwell a rotor's plan reaches, as a share of the pass-rate Nyquist frequency.
ROTOR_TOP_FRACTION = 0.7


def rotor_top_hz(rev_per_s: float, n_blades: int) -> float:
    """The highest dwell of a rotor's plan: :data:`ROTOR_TOP_FRACTION` of N·Ω/2, to 3 digits, not above it (Hz)."""
    top = ROTOR_TOP_FRACTION * pass_nyquist_hz(rev_per_s, n_blades)
    digits = 2 - math.floor(math.log10(top))
    return math.floor(top * 10**digits + 1e-9) / 10**digits


def parse_blade_colours(text: str) -> list[tuple[str, str]]:
    """``--blade-colours "LEAD/TRAIL,LEAD/TRAIL"``: each blade's (lead, trail) colours, blade 0 first, checked."""
    from ..markers.colour import parse_colour

    pairs = [tuple(c.strip() for c in pair.split("/")) for pair in text.split(",")]
    if any(len(p) != 2 for p in pairs):
        raise ServoscopeError(f"--blade-colours {text!r}: give LEAD/TRAIL for each blade, e.g. "
                              "'#d62728/#2ca02c,#1d4fd8/#c81dd8'")
    for k, (lead, trail) in enumerate(pairs):
        parse_colour(lead, what=f"--blade-colours (blade {k} lead)")
        parse_colour(trail, what=f"--blade-colours (blade {k} trail)")
    return pairs


def _blade_colours(n_blades: int, blades: list[tuple[str, str]] | None) -> list[list[str]] | None:
    """Each blade's colours: those given (one pair a blade), else the defaults' (None past their 3 blades: the
    plan can be made, not written, until they are named)."""
    if blades is not None and len(blades) != n_blades:
        raise ServoscopeError(f"a rotor of {n_blades} blades needs {n_blades} colour pairs in --blade-colours, "
                              f"not {len(blades)}")
    if blades is None and n_blades > len(ROTOR_BLADE_COLOURS):
        return None
    return [list(b) for b in (blades if blades is not None else ROTOR_BLADE_COLOURS[:n_blades])]


def plan_rotor_sweep(fps: float, rev_per_s: float, n_blades: int | None = None, *, from_hz: float | None = None,
                     to_hz: float | None = None, blades: str | list[tuple[str, str]] | None = None,
                     **options: Any) -> SweepPlan:
    """Plan sine dwells (and the step) below a turning rotor's pass-rate Nyquist frequency.

    Parameters
    ----------
    fps : float
        Camera frame rate, frames/s (a high-speed camera's; the frame-rate checks still run).
    rev_per_s : float
        Rotor speed Ω, rev/s.
    n_blades : int, optional
        Blades N (each read once a revolution); default as many as ``blades`` names, else 2.
    from_hz : float, optional
        Lowest dwell, Hz; default 0.5 Hz (the paper's), or the top when that is lower.
    to_hz : float, optional
        Highest dwell, Hz; default, and at most, :func:`rotor_top_hz` (a higher one is lowered
        to it, and the plan's ``rotor["notes"]`` say so).
    blades : str or list of (str, str), optional
        Each blade's (lead, trail) sticker colours, blade 0 first (or ``--blade-colours``' text,
        :func:`parse_blade_colours`); default :data:`~servoscope.defaults.ROTOR_BLADE_COLOURS`
        (3 blades; more must be named before the plan is written).
    **options
        The other keywords of :func:`~servoscope.rig.plan.plan_sweep` (points, amplitude, …).

    Returns
    -------
    SweepPlan
        Its ``rotor`` holds ``rev_per_s``, ``n_blades``, ``pass_rate_hz``, ``pass_nyquist_hz``,
        ``top_hz``, ``notes`` and ``blades`` (written as campaign.toml's ``[rotor]``); each dwell
        near a rotor harmonic carries a warning.

    Raises
    ------
    ServoscopeError
        A speed or a blade count out of range, or a lowest dwell above the top.
    """
    rev = positive_option(rev_per_s, "--rotor-hz")
    if isinstance(blades, str):
        blades = parse_blade_colours(blades)
    if n_blades is None:
        n_blades = 2 if blades is None else len(blades)
    if int(n_blades) != n_blades or n_blades < 1:
        raise ServoscopeError(f"--blades {n_blades}: must be a whole number ≥ 1")
    n_blades = int(n_blades)
    colours = _blade_colours(n_blades, blades)
    nyq = pass_nyquist_hz(rev, n_blades)
    top = rotor_top_hz(rev, n_blades)
    notes = []
    if to_hz is not None and positive_option(to_hz, "--to") > top:
        notes.append(f"--to {to_hz:g} Hz lowered to {top:g} Hz: the passes' Nyquist frequency is {nyq:g} Hz "
                     f"({n_blades} blades × {rev:g} rev/s / 2), and a rotor's plan stops at "
                     f"{100 * ROTOR_TOP_FRACTION:g} % of it")
    high = top if to_hz is None else min(float(to_hz), top)
    low = min(0.5, high) if from_hz is None else positive_option(from_hz, "--from")
    if low > high:
        raise ServoscopeError(f"--from {low:g} Hz is above {high:g} Hz, the highest dwell {rev:g} rev/s with "
                              f"{n_blades} blades allows ({100 * ROTOR_TOP_FRACTION:g} % of the passes' Nyquist "
                              f"frequency {nyq:g} Hz)")
    plan = plan_sweep(fps, low, high, **options)
    settle = plan.settle_s
    dwells = []
    for d in plan.dwells:
        if d.kind == "sine":
            extra = rotor_harmonic_warning(float(d.frequency_hz), rev, d.duration_s - settle)
            if extra is not None:
                d = replace(d, warnings=(*d.warnings, extra))
        dwells.append(d)
    rotor = {"rev_per_s": rev, "n_blades": n_blades, "pass_rate_hz": 2.0 * nyq, "pass_nyquist_hz": nyq,
             "top_hz": top, "notes": tuple(notes), "blades": colours}
    return replace(plan, dwells=tuple(dwells), rotor=rotor)


def rotor_lines(plan: SweepPlan) -> list[str]:
    """What ``servoscope plan`` says about a rotor's plan (nothing for a static one)."""
    r = plan.rotor
    if not r:
        return []
    sines = [d.frequency_hz for d in plan.dwells if d.kind == "sine"]
    highest = max(sines) if sines else float("nan")
    lines = [
        f"rotor {r['rev_per_s']:g} rev/s × {r['n_blades']} blades: a pass every {1000.0 / r['pass_rate_hz']:.1f} ms "
        f"({r['pass_rate_hz']:g} passes/s); the passes' Nyquist frequency is {r['pass_nyquist_hz']:g} Hz, "
        f"every dwell is below it (highest {highest:g} Hz, {100 * highest / r['pass_nyquist_hz']:.0f} % of it; a "
        f"rotor's plan stops at {100 * ROTOR_TOP_FRACTION:g} %)",
        "the step's passes are 1/(N·Ω) apart: its rise and dead time are read to that spacing; the dead time "
        "comes from the dwells' phases and the LED",
    ]
    return lines + list(r.get("notes", ()))
