"""The identified model as every view states it first: the headline.

An identification can hold two descriptions of the servo: the transfer function fitted to
the dwells' fundamentals (the frequency domain) and, with ``identify(nonlinear=...)``, the
block-structured models fitted to the whole traces (the time domain). When a nonlinear
structure is selected (play, a rate limit), the frequency-domain fit is no longer the
servo's linear part: it is a describing function at the dwells' amplitudes, and its gain
and natural frequency can be 10–20 % off the truth with intervals that exclude it. The
headline is then the selected model; otherwise it is the transfer function, with the dead
time from the more precise of its two estimates (:mod:`servoscope.sysid.dead_time`).

The report's first table, ``identify``'s first table, the notebook view and result.json's
``model`` all read :func:`headline`, so they cannot disagree.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ..parameters import FitResult, Parameter, Parameters
from ..results import html_rows
from ..sysid.model_text import PARAM_LABELS, model_equation

__all__ = ["SOURCE_KEYS", "Headline", "chosen_dead_time", "headline"]

#: result.json's name (in ``dead_time``) for each source of the headline's dead time.
SOURCE_KEYS = {"step test": "step", "frequency response (phase)": "phase"}
TIME_DOMAIN_KEY = "time_domain"


@dataclass(frozen=True)
class Headline(FitResult):
    """The model an identification states first, with its parameters.

    Attributes
    ----------
    domain : str
        "frequency domain" (the transfer function fitted to the dwells) or "time domain"
        (the servo model selected from the whole traces).
    structure : str
        "linear", or the selected nonlinear structure ("backlash", "rate_limit", …).
    table : Parameters
        The parameters as stated: value, error, 95 % interval, held or tied.
    dead_time_source : str or None
        Where the dead time comes from ("step test", "frequency response (phase)", or the
        selected model's fit to the whole traces); None without one.
    equation : str
        The model as text.
    """

    domain: str
    structure: str
    table: Parameters
    dead_time_source: str | None
    equation: str

    @property
    def model_name(self) -> str:  # type: ignore[override]
        return f"{self.structure} servo model, {self.domain}"

    @property
    def parameters(self) -> Parameters:
        return self.table

    def label(self, name: str) -> str:
        """A parameter's name as a reader sees it, with its unit (the dead time with its source)."""
        if name == "dead_time_s":
            return f"dead time τ (s), from the {self.dead_time_source}" if self.dead_time_source else "dead time τ (s)"
        return PARAM_LABELS.get(name, name)

    def rows(self) -> list[list[str]]:
        """One row per parameter: label (and how it was held), value, standard error, 95 % interval.

        The cells every view writes: the report's first table, ``identify``'s, the notebook's.
        """
        return [[self.label(p.name) + p.held_text(), *p.cells()] for p in self.table.values()]

    def _repr_html_(self) -> str:
        return html_rows(["parameter", "value", "std. error", "95 % interval"], self.rows(),
                         caption=f"{self.model_name}: {self.equation}")


def _servo_equation(fit: Any) -> str:
    p = fit.params
    text = (f"G(s) = {p['gain']:.4g} · {p['natural_frequency_rad_s']:.4g}² / (s² + 2·{p['damping_ratio']:.3g}·"
            f"{p['natural_frequency_rad_s']:.4g}·s + {p['natural_frequency_rad_s']:.4g}²) · e^(−sτ), "
            f"τ = {1e3 * p['dead_time_s']:.1f} ms")
    name = fit.nonlinear_parameter
    return text if name is None else f"{text}, {PARAM_LABELS.get(name, name)} = {p[name]:.4g}"


def chosen_dead_time(estimates: dict[str, Any]) -> tuple[str | None, Any]:
    """The more precise of the step's and the phases' dead time: (its source's words, the estimate).

    The step's wins a tie: it is the direct measurement (LED off → blade moving).
    """
    step, phase = estimates.get("step"), estimates.get("phase")
    if step is not None and (phase is None or step.stderr_s <= phase.stderr_s):
        return "step test", step
    if phase is not None:
        return "frequency response (phase)", phase
    return None, None


def headline(result: Any) -> Headline:
    """The model `result` (an :class:`~servoscope.campaign.result.IdentificationResult`, which imports this
    module) states first (see the module's description)."""
    selection = result.servo_model
    if selection is not None and selection.selected.structure != "linear":
        fit = selection.selected
        return Headline("time domain", fit.structure, fit.parameters,
                        f"{fit.structure} model (fitted to the whole traces)", _servo_equation(fit))
    model = result.model
    rows = [p for p in model.parameters.values() if p.name != "dead_time_s"]
    source, chosen = chosen_dead_time(result.dead_time_estimates)
    if chosen is not None:
        rows.append(Parameter("dead_time_s", chosen.value_s, chosen.stderr_s, chosen.ci95_s, unit="s"))
    base = model.parameters
    correlated = [n for n in base.correlated if n != "dead_time_s"]
    correlation = None
    if base.correlation is not None and len(correlated) > 1:
        idx = [base.correlated.index(n) for n in correlated]
        correlation = base.correlation[idx][:, idx]
    return Headline("frequency domain", "linear", Parameters(rows, correlation=correlation, correlated=correlated
                                                             if correlation is not None else ()),
                    source, model_equation(model, None if chosen is None else chosen.value_s))
