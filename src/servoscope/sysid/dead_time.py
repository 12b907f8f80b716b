"""The dead time, measured two ways: from the dwells' phases and from the step.

The transfer-function fit's dead time (from the phases) shares one error with every
dwell: the input starts' timing, which the LED dates and which no number of dwells
averages away (see :func:`servoscope.campaign.runner.shared_t0_stderr`). The step's dead
time is fitted against the model from the step's own trace. Each is a
:class:`DeadTimeEstimate`, a :class:`~servoscope.parameters.FitResult` with one parameter,
``dead_time_s``, so that the report, the command line, the notebook and result.json state
the same value, error and interval.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from ..parameters import FitResult, Parameter, Parameters, interval95
from ..results import jsonable

__all__ = ["DEAD_TIME_SOURCES", "DeadTimeEstimate", "dead_time_estimates"]

#: The two ways the dead time is measured, as result.json's ``dead_time`` names them.
DEAD_TIME_SOURCES = ("phase", "step")


@dataclass(frozen=True)
class DeadTimeEstimate(FitResult):
    """One measurement of the dead time, with its error and 95 % interval.

    Attributes
    ----------
    source : str
        "phase" (the dwells' phases, the transfer-function fit's) or "step" (the step's trace).
    value_s : float
    fit_stderr_s : float
        The fit's own standard error, s.
    shared_t0_stderr_s : float or None
        The input starts' timing error the dwells share, s, added in quadrature (the
        phase estimate's; None for the step's, whose own fit holds its t0).
    """

    source: str
    value_s: float
    fit_stderr_s: float
    shared_t0_stderr_s: float | None = None

    @property
    def stderr_s(self) -> float:
        """The whole standard error: the fit's and the shared timing error's, in quadrature."""
        return math.hypot(self.fit_stderr_s, self.shared_t0_stderr_s or 0.0)

    @property
    def ci95_s(self) -> tuple[float, float]:
        """The 95 % interval, s (normal: many samples, a propagated error)."""
        return interval95(self.value_s, self.stderr_s, "normal")

    @property
    def model_name(self) -> str:  # type: ignore[override]
        return ("dead time from the frequency response's phases" if self.source == "phase"
                else "dead time from the step, fitted against the model")

    @property
    def parameters(self) -> Parameters:
        """One parameter, ``dead_time_s``."""
        return Parameters([Parameter("dead_time_s", self.value_s, self.stderr_s, self.ci95_s, unit="s")])

    def fit_statistics(self) -> dict[str, Any]:
        """The fit's own error and the shared timing error, s."""
        out: dict[str, Any] = {"fit stderr (s)": self.fit_stderr_s}
        if self.shared_t0_stderr_s is not None:
            out["shared t0 stderr (s)"] = self.shared_t0_stderr_s
        return out

    def summary(self) -> dict[str, Any]:
        """result.json's form: ``{"value_s", "stderr_s", "ci95_s", "shared_t0_stderr_s"}``."""
        return jsonable({"value_s": self.value_s, "stderr_s": self.stderr_s, "ci95_s": list(self.ci95_s),
                         "shared_t0_stderr_s": self.shared_t0_stderr_s})


def dead_time_estimates(model: Any, step: Any, shared_t0_s: float) -> dict[str, DeadTimeEstimate | None]:
    """The dead time from the dwells' phases and from the step, each with its own interval.

    Parameters
    ----------
    model : TransferFunctionFit
        Its ``dead_time_s`` (None for a magnitude fit).
    step : StepAnalysis or None
    shared_t0_s : float
        The dwells' shared input-start error, s (added to the phase estimate's).

    Returns
    -------
    dict
        ``{"phase": DeadTimeEstimate or None, "step": DeadTimeEstimate or None}``.
    """
    out: dict[str, DeadTimeEstimate | None] = {"phase": None, "step": None}
    if model.dead_time_s is not None and math.isfinite(model.dead_time_s):
        out["phase"] = DeadTimeEstimate("phase", float(model.dead_time_s), float(model.dead_time_stderr_s or 0.0),
                                        float(shared_t0_s))
    if step is not None and step.dead_time_s is not None and math.isfinite(step.dead_time_s):
        out["step"] = DeadTimeEstimate("step", float(step.dead_time_s), float(step.dead_time_stderr_s or 0.0))
    return out
