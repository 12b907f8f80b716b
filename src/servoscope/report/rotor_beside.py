"""The rotor's response beside a static campaign's (issue 33, the report's "Under rotation").

``servoscope identify ROTOR_CAMPAIGN --beside STATIC_OUT/result.json`` records the comparison in result.json's
``rotor["beside_static"]`` (:mod:`servoscope.campaign.compare`); this part of the section draws both
frequency responses on one Bode plot (each with its points and its fitted model) from the static result
read again where it was, and tables K, ωn, ζ, τ static against rotating from the recorded numbers, so
that a report rebuilt from a saved result shows the table even when the static result has moved.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.figure import Figure

from ..campaign.compare import DIFFERS_Z, ResultComparison, load_static_result
from ..errors import ServoscopeError
from ..numbers import format_interval, format_with_uncertainty
from ..sysid.plotting import on_branch_deg, plot_gain
from .html import ReportSection

if TYPE_CHECKING:  # pragma: no cover
    from ..campaign.result import IdentificationResult

__all__ = ["beside_bode_figure", "beside_static_part", "comparison_rows"]

#: The compared parameters as the table names them, and the factor to its unit.
_LABELS = {"gain": ("gain K", 1.0), "natural_frequency_rad_s": ("natural frequency ωn (rad/s)", 1.0),
           "damping_ratio": ("damping ratio ζ", 1.0), "dead_time_s": ("dead time τ (ms)", 1e3)}


def beside_bode_figure(static: "IdentificationResult", rotating: "IdentificationResult") -> Figure:
    """Both frequency responses on one Bode plot: each one's points (±1 standard error) and its fitted model."""
    fig = Figure(figsize=(7.5, 6.0), layout="constrained")
    ax, axp = fig.subplots(2, 1, sharex=True)
    f_all = np.r_[static.frequency_response.frequency_hz, rotating.frequency_response.frequency_hz]
    omega = np.logspace(np.log10(2 * np.pi * f_all.min() / 2), np.log10(2 * np.pi * f_all.max() * 2), 300)
    for result, name, colour, marker in ((static, "static", "C0", "o"), (rotating, "rotating", "C3", "s")):
        fr, model = result.frequency_response, result.model
        w = 2 * np.pi * np.asarray(fr.frequency_hz)
        plot_gain(ax, w, fr.gain, fr.gain_stderr, label=f"{name}: measured ({len(w)} dwells)", color=colour,
                  marker=marker, ms=4.5, capsize=2)
        ax.semilogx(omega, 20 * np.log10(model.magnitude(omega)), "-", color=colour, lw=1.1,
                    label=f"{name}: fitted model")
        # A measured phase is known modulo 360°: drawn on the model's branch, which runs on past −180°.
        phase = on_branch_deg(fr.phase_deg, model.phase_deg(w))
        axp.errorbar(w, phase, yerr=fr.phase_stderr_deg, fmt=marker, ms=4.5, color=colour, capsize=2,
                     label=f"{name}: measured")
        axp.plot(omega, np.degrees(model.phase_rad(omega)), "-", color=colour, lw=1.1, label=f"{name}: fitted model")
    ax.set_xscale("log")
    ax.set_ylabel("gain (dB)")
    ax.set_title("The servo static and under rotation", fontsize=10)
    axp.set_ylabel("phase (°)")
    axp.set_xlabel("angular frequency ω (rad/s)")
    for a in (ax, axp):
        a.grid(True, which="both", alpha=0.3)
        a.legend(fontsize=7, loc="lower left")
    return fig


def comparison_rows(comparison: ResultComparison) -> list[list[str]]:
    """The table's rows: each parameter static and rotating (value ± s.e., 95 %), the difference ± s.e., z."""
    rows = []
    for p in comparison.parameters:
        label, scale = _LABELS.get(p.name, (p.name, 1.0))
        cells = [label]
        for value, err, ci in ((p.static, p.static_stderr, p.static_ci95),
                               (p.rotating, p.rotating_stderr, p.rotating_ci95)):
            v, e = format_with_uncertainty(scale * value, scale * err)
            cells.append(f"{v} ± {e}, 95 % {format_interval(scale * ci[0], scale * ci[1], scale * err)}")
        d, de = format_with_uncertainty(scale * p.difference, scale * p.difference_stderr)
        cells += [f"{d} ± {de}", "—" if not math.isfinite(p.z) else f"{p.z:+.2f}",
                  "yes" if p.differs else "no"]
        rows.append(cells)
    return rows


def beside_static_part(s: ReportSection, result: "IdentificationResult") -> None:
    """Add the comparison with the static campaign to the section (nothing when the result has none)."""
    recorded = (result.rotor or {}).get("beside_static")
    if not recorded:
        return
    comparison = ResultComparison.from_summary(recorded)
    where = comparison.static_path or comparison.static_campaign
    try:
        static = load_static_result(Path(comparison.static_path)) if comparison.static_path else None
    except ServoscopeError as exc:
        static, why = None, str(exc)
    else:
        why = "" if static is not None else "its path was not recorded"
    if static is not None:
        s.figure(beside_bode_figure(static, result),
                 f"Circles: the static campaign ({static.campaign.path}); squares: the turning rotor's dwells, "
                 "each with its fitted model (±1 standard error bars).",
                 "Frequency response static and under rotation", name="rotor_beside_bode")
    else:
        s.text(f"The Bode plot beside the static campaign is left out: the static result ({where}) could not be "
               f"read again ({why}). Its numbers, recorded when this result was made, follow.")
    s.text(f"Beside the static campaign's identification ({where}): rotating − static, its error the two in "
           f"quadrature (the campaigns are independent), z their ratio; a difference beyond |z| > "
           f"{recorded.get('differs_beyond_z', DIFFERS_Z):.2f} (95 %) is called real.")
    s.table(["parameter", "static", "rotating", "rotating − static", "z", "beyond the errors"],
            comparison_rows(comparison))
    names = [_LABELS.get(n, (n, 1))[0] for n in comparison.differing]
    s.text("Differ beyond their errors: " + ", ".join(names) + "." if names else
           "No parameter differs beyond its errors: the rotor's loads do not change the servo measurably here.")
