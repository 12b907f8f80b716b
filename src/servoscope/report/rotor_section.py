"""The report's section "Under rotation": a turning rotor's passes, speed and blade-to-blade pitch (issue 33)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.figure import Figure

from .html import ReportSection

if TYPE_CHECKING:  # pragma: no cover
    from ..campaign.result import IdentificationResult

__all__ = ["passes_figure", "rotor_section"]

_MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*")


def passes_figure(time_s: np.ndarray, blade: np.ndarray, pitch_rad: np.ndarray, fit, title: str) -> Figure:
    """Each blade's pitch per pass against time (its own marker), and the fitted sine with each blade's offset.

    ``time_s``, ``blade``, ``pitch_rad``: the dwell's passes; ``fit``: its
    :class:`~servoscope.sysid.pass_result.PassSineFit` (the common sine, one offset a blade).
    """
    fig = Figure(figsize=(7.0, 3.2), layout="constrained")
    ax = fig.add_subplot()
    fine = np.linspace(float(np.min(time_s)), float(np.max(time_s)), 2000)
    common = fit.model(fine) - fit.offset
    for o in fit.blade_offsets:
        mine = blade == o.blade
        marker = _MARKERS[o.blade % len(_MARKERS)]
        points = ax.plot(time_s[mine], np.degrees(pitch_rad[mine]), marker, ms=3.5, ls="none",
                         label=f"blade {o.blade} ({int(np.count_nonzero(mine))} passes)")
        ax.plot(fine, np.degrees(common + o.offset_rad), "-", lw=0.9, color=points[0].get_color())
    lo, hi = fit.window_s
    ax.axvspan(lo, hi, color="0.9", zorder=0)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("pitch (°)")
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=8, loc="best")
    return fig


def _deg(value_rad: float | None) -> str:
    return "—" if value_rad is None or not math.isfinite(value_rad) else f"{math.degrees(value_rad):.4f}"


def rotor_section(result: "IdentificationResult", figures_dir: Path | None) -> ReportSection | None:
    """The passes of the highest dwell by blade with its fitted sine, rev/s and passes per test, each blade's pitch
    against blade 0's; None for a static blade."""
    rotor = result.rotor
    if rotor is None:
        return None
    s = ReportSection("Under rotation", figures_dir=figures_dir)
    blades = rotor["blades"]
    s.text(f"{len(blades)} blades, read once a revolution each as its tip passes the camera (ψ = 0): each pass "
           f"gives that blade's pitch then, with its error. Each dwell's sine is common to the blades, with one "
           f"constant a blade (its rigging); the pass rate bounds the dwells (its Nyquist frequency, "
           f"blades × rev/s / 2). What the method cannot see (flapping, lead-lag, cyclic away from the camera) is "
           f"in docs/rotor.md.")
    fits = {k: f for k, f in result.sine_fits.items() if getattr(f, "blade_offsets", None)}
    if fits:
        label = max(fits, key=lambda k: fits[k].frequency_hz)
        fit = fits[label]
        track = result.tracks[label]
        s.figure(passes_figure(np.asarray(fit.time_s) if len(fit.blade) else track.time_s,
                               np.asarray(fit.blade) if len(fit.blade) else np.zeros(track.n_frames, int),
                               np.asarray(fit.pitch_rad) if len(fit.blade) else track.angle_rad, fit,
                               f"{label}: each blade's pitch per pass and the fitted sine"),
                 f"{label} at {fit.frequency_hz:.4g} Hz, {100 * fit.frequency_hz / fit.pass_nyquist_hz:.0f} % of the "
                 f"passes' Nyquist frequency ({fit.pass_nyquist_hz:.4g} Hz); shaded: the steady-state window.",
                 "Passes by blade", name="rotor_passes")
    s.table(["test", "rotor speed (rev/s)", "passes"],
            [[t["label"], f"{t['rev_per_s']:.5f} ± {t['rev_per_s_stderr']:.1g}", t["passes"]] for t in rotor["tests"]])
    if rotor["blade_differences"]:
        s.text("Each blade's pitch against blade 0's (its rigging), pooled over the dwells:")
        s.table(["blade", "pitch − blade 0's (°)", "95 % interval (°)", "dwells"],
                [[d["blade"], _deg(d["difference_rad"]), f"[{_deg(d['ci95_rad'][0])}, {_deg(d['ci95_rad'][1])}]",
                  d["dwells"]] for d in rotor["blade_differences"]])
    rows = [[t["label"], d["blade"], _deg(d["difference_rad"]), f"[{_deg(d['ci95_rad'][0])}, {_deg(d['ci95_rad'][1])}]"]
            for t in rotor["tests"] for d in t.get("blade_differences", [])]
    if rows and rotor.get("identified_by") == "order":
        s.text("The blades look alike here (a monochrome camera's bright stickers): each video numbers them in the "
               "order they pass first, so blade 0 may be a different blade in each video, and the differences are "
               "not pooled. Give each blade its own colours to follow one blade through the campaign.")
    if rows:
        s.table(["dwell", "blade", "pitch − blade 0's (°)", "95 % interval (°)"], rows)
    return s
