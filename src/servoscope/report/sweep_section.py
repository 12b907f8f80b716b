"""The report's section on frequency sweeps (issue 31): each sweep's input and angle, and CIFER's three panels.

Each sweep shows its command and the measured angle against time, then its frequency response
as CIFER plots one: magnitude, phase and coherence against frequency, the points with coherence
below the standard's 0.6 drawn hollow (left out of the fit), the dwells' points on the same axes
when the campaign has both, and the fitted model.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from ..campaign.dwells import exposure_undone  # noqa: E402
from ..campaign.result import input_start  # noqa: E402
from .html import ReportSection  # noqa: E402

if TYPE_CHECKING:  # pragma: no cover
    from ..campaign.result import IdentificationResult

__all__ = ["sweep_section"]


def _time_figure(result: "IdentificationResult", label: str) -> Figure:
    test = next(t for t in result.campaign.tests if t.label == label)
    track = result.tracks[label]
    t0 = input_start(test, track) or 0.0
    t = np.asarray(track.angle_time_s) - t0
    fig, (ax_u, ax_y) = plt.subplots(2, 1, figsize=(7.5, 4.6), sharex=True)
    ax_u.plot(t, test.command(t), lw=0.8, color="0.3")
    ax_u.set_ylabel(f"command ({result.campaign.input_units or 'input units'})")
    if test.recorded:  # a pilot's (or any) recorded input: its file and its band
        lo, hi = test.sweep_band_hz
        ax_u.set_title(f"{label}: recorded input {test.input_file.name}, band {lo:.3g}–{hi:.3g} Hz, "
                       f"{test.input_duration_s:g} s")
    else:
        ax_u.set_title(f"{label}: {test.shape} sweep {test.from_hz:g}–{test.to_hz:g} Hz over {test.duration_s:g} s")
    y = np.where(track.valid, track.angle_rad, np.nan)
    ax_y.plot(t, np.degrees(y - np.nanmedian(y[t < 0])) if np.any(t < 0) else np.degrees(y), lw=0.8, color="C0")
    ax_y.set_ylabel("blade angle (deg, from rest)")
    ax_y.set_xlabel("time after the input's start (LED), s")
    fig.tight_layout()
    return fig


def _cifer_figure(result: "IdentificationResult", label: str) -> Figure:
    sweep = result.sweeps[label]
    e, _ = exposure_undone(result.campaign, result.exposure)
    if e > 0:
        # As the fit takes it (and the dwells' squares are drawn): the camera's averaging over each
        # exposure undone. A full frame at 100 frames/s otherwise drew the sweep 3–4 % under the
        # model and the dwells at 12–14 Hz.
        sweep = replace(sweep, gain=sweep.gain / np.sinc(sweep.frequency_hz * e))
    fig, axes = plt.subplots(3, 1, figsize=(7.5, 7.0), sharex=True, gridspec_kw={"height_ratios": [3, 3, 1.6]})
    sweep.plot(axes)
    ax_g, ax_p, _ = axes
    fr = result.frequency_response
    dwell = np.array([not lab.startswith(tuple(result.sweeps)) for lab in fr.labels], dtype=bool)
    if dwell.any():
        ax_g.errorbar(fr.frequency_hz[dwell], 20 * np.log10(fr.gain[dwell]), fmt="s", ms=5, color="C1",
                      label="dwells")
        ax_p.plot(fr.frequency_hz[dwell], fr.phase_deg[dwell], "s", ms=5, color="C1")
    f = np.geomspace(sweep.frequency_hz.min() / 1.2, sweep.frequency_hz.max() * 1.2, 300)
    w = 2 * np.pi * f
    model = result.model
    ax_g.plot(f, 20 * np.log10(model.magnitude(w)), "-", color="C2", lw=1.2, label="fitted model")
    phase = model.phase_deg(w)
    # The sweep's phase is continuous from 0 at low frequency; draw the model on the same branch.
    shift = 360.0 * np.round((np.interp(sweep.frequency_hz[0], f, phase) - sweep.phase_deg[0]) / 360.0)
    ax_p.plot(f, phase - shift, "-", color="C2", lw=1.2)
    ax_g.legend(loc="lower left", fontsize=8)
    ax_g.set_title(f"{label}: composite of {len(sweep.windows_s)} windows", fontsize=10)
    fig.tight_layout()
    return fig


def sweep_section(result: "IdentificationResult", figures_dir: Path | None) -> ReportSection | None:
    """The campaign's frequency sweeps; None without one."""
    if not result.sweeps:
        return None
    s = ReportSection("Frequency sweeps", figures_dir=figures_dir)
    s.text("Each sweep's response from its command (known from the LED's switch) and the measured angle: "
           "overlapped, Hann-windowed cross- and auto-spectra at several window lengths, combined at each "
           "frequency by their random error (CIFER's composite); coherence γ² is the share of the angle's power "
           "the command explains. Frequencies with γ² below 0.6 are drawn hollow and left out of the fit; the "
           "others enter it beside the dwells, each with its random error √(1 − γ²)/(|γ|·√(2 n)).")
    rows = []
    for label, sw in result.sweeps.items():
        kept = int(np.count_nonzero(sw.kept))
        rows.append([label, f"{sw.frequency_hz.min():.3g}–{sw.frequency_hz.max():.3g} Hz", f"{kept} of {len(sw)}",
                     f"{np.min(sw.coherence[sw.kept]) if kept else float('nan'):.3f}",
                     ", ".join(f"{w:.2g}" for w in sw.windows_s), str(sw.filled_samples)])
    s.table(["sweep", "frequencies", "fitted (γ² ≥ 0.6)", "lowest γ² fitted", "windows (s)", "frames filled"],
            rows)
    for label in result.sweeps:
        s.figure(_time_figure(result, label), f"{label}: the command and the blade's measured angle against time.",
                 f"{label} against time", name=f"{label}_time")
        s.figure(_cifer_figure(result, label),
                 f"{label}: magnitude, phase and coherence (hollow: γ² < 0.6, not fitted); squares: the dwells; "
                 "line: the fitted model; the sweep's gains corrected for the exposure as the fit takes them, where it is known.", f"{label} frequency response", name=f"{label}_response")
    return s
