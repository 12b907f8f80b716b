"""The identified model as text: its equation and its parameters' names with units.

Shared by the report, the CLI's summary and the results' notebook HTML, so the
three say the same thing the same way.
"""

from __future__ import annotations

__all__ = ["PARAM_LABELS", "model_equation", "poly_text"]

# Each fitted parameter's name as a reader sees it, with its unit.
PARAM_LABELS: dict[str, str] = {
    "gain": "gain K (output per input unit)",
    "natural_frequency_rad_s": "natural frequency ωn (rad/s)",
    "damping_ratio": "damping ratio ζ",
    "dead_time_s": "dead time from the dwells' phases τ (s)",
    "pole_rad_s": "real pole (rad/s)",
    "zero_rad_s": "real zero (rad/s)",
    "rate_limit_rad_s": "rate limit (rad/s)",
    "backlash_rad": "backlash, the linkage's play (rad)",
    "quantization_step": "command quantization step (input units)",
    "saturation_rad": "saturation (rad)",
}


def poly_text(coeffs) -> str:
    """A polynomial in s from its coefficients (highest power first), zero terms left out."""
    n = len(coeffs) - 1
    terms = []
    for i, c in enumerate(coeffs):
        power = n - i
        if c == 0:
            continue
        s_part = "" if power == 0 else ("s" if power == 1 else f"s^{power}")
        terms.append(f"{c:.5g}{'·' if s_part else ''}{s_part}")
    return " + ".join(terms) or "0"


def model_equation(model, dead_time_s: float | None) -> str:
    """The identified model as text: the paper's eq. 6 form for 2nd order, polynomials otherwise."""
    tau = "not measured" if dead_time_s is None else f"{1e3 * dead_time_s:.1f} ms"
    if tuple(model.order) == (0, 2) and model.natural_frequency_rad_s is not None:
        wn, z = model.natural_frequency_rad_s, model.damping_ratio
        return (f"G(s) = {model.gain:.4g} · {wn:.4g}² / (s² + 2·{z:.3g}·{wn:.4g}·s + {wn:.4g}²) · e^(−sτ), τ = {tau}")
    return f"G(s) = ({poly_text(model.num)}) / ({poly_text(model.den)}) · e^(−sτ), τ = {tau}"
