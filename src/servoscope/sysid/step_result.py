"""The result of a step test's analysis: :class:`StepAnalysis` (made by :func:`~servoscope.sysid.analyse_step`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from servoscope.defaults import STEP_DISCERNIBLE_SIGMA
from servoscope.errors import ServoscopeError
from servoscope.parameters import FitResult, Parameter, Parameters, interval95
from servoscope.results import fields_from_summary, import_pandas, jsonable, readonly
from servoscope.sysid.plotting import new_axes, plot_step

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes

__all__ = ["StepAnalysis"]


def step_discernible(change: float, noise_sigma: float) -> bool:
    """Whether a step's output change stands out of its noise.

    Parameters
    ----------
    change : float
        Output change across the step (output units).
    noise_sigma : float
        Robust noise estimate (output units).

    Returns
    -------
    bool
        True when ``|change|`` exceeds ``STEP_DISCERNIBLE_SIGMA`` noise sigmas (and is not 0).
    """
    # Written as the negation of "within the noise" so that NaN reads as it always did (moved).
    return not (abs(change) <= max(STEP_DISCERNIBLE_SIGMA * noise_sigma, 0.0) or change == 0)


@dataclass(frozen=True)
class StepAnalysis(FitResult):
    """Result of :func:`~servoscope.sysid.analyse_step`.

    A :class:`~servoscope.parameters.FitResult`: :attr:`parameters` holds the model fit's dead
    time, gain and baseline (empty without a model), :meth:`fit_statistics` the measured
    metrics, and ``fit_report()`` and the notebook's table show both; :meth:`to_pandas` is the
    samples (``self.parameters.to_pandas()`` the parameters' table).

    Attributes
    ----------
    t0_s : float
        Step time in s.
    step_size : float
        Input step (input units).
    initial_value, final_value : float
        Output before the step and at the end (output units, e.g. rad).
    change : float
        ``final_value - initial_value``.
    gain : float
        Measured static gain ``change / step_size``.
    rise_time_s : float
        10-90 % rise time in s (NaN when not measurable).
    overshoot_pct : float
        Peak overshoot in percent of the change (>= 0).
    peak_time_s : float
        Time of the peak after ``t0_s``, in s.
    settling_time_s : float
        2 % settling time measured from ``t0_s``, in s (NaN if not settled).
    dead_time_s : float or None
        Dead time from the model fit, in s (None without a model).
    dead_time_stderr_s : float or None
        Its standard error in s.
    dead_time_threshold_s : float
        Frame-counting dead-time estimate in s (NaN if never exceeded).
    fitted_gain, fitted_gain_stderr, fitted_baseline : float or None
        Model-fit ``g`` (output per input unit), its standard error, and
        ``b`` (output units).
    noise_sigma : float
        Robust noise estimate, output units.
    warnings : tuple of str
        Non-fatal problems.
    time_s, y : numpy.ndarray
        Valid samples used (s, output units).
    predicted_metrics : dict or None
        The model's own step metrics (:func:`model_step_metrics` with the
        fitted dead time, scaled to this step), for comparison with the
        measured ones; None without a model.
    model_source : str
        Which model's shape the dead time was fitted against: the frequency-domain model, or
        a time-domain model's linear part where that one could not stand (``identify
        --nonlinear``).
    """

    t0_s: float
    step_size: float
    initial_value: float
    final_value: float
    change: float
    gain: float
    rise_time_s: float
    overshoot_pct: float
    peak_time_s: float
    settling_time_s: float
    dead_time_s: float | None
    dead_time_stderr_s: float | None
    dead_time_threshold_s: float
    fitted_gain: float | None
    fitted_gain_stderr: float | None
    fitted_baseline: float | None
    noise_sigma: float
    warnings: tuple[str, ...]
    time_s: NDArray[np.float64] = field(repr=False, compare=False)
    y: NDArray[np.float64] = field(repr=False, compare=False)
    _unit_step: Callable[[NDArray[np.float64]], NDArray[np.float64]] | None = field(
        default=None, repr=False, compare=False
    )
    predicted_metrics: dict[str, float] | None = field(default=None, compare=False)
    model_source: str = "frequency-domain model"

    @property
    def model_name(self) -> str:  # type: ignore[override]
        if self.dead_time_s is None:
            return "step response (measured metrics, no model)"
        return f"step response b + g·step·s(t − t0 − τ), s the {self.model_source}'s unit step"

    @property
    def parameters(self) -> Parameters:
        """The model fit's ``dead_time_s`` (s), ``fitted_gain`` and ``fitted_baseline``; empty without a model.

        Every interval is normal (a least-squares fit's covariance; the baseline's error is not
        kept: NaN). The dead time was fitted within ``[0, …]`` and is never negative: its
        interval stops at 0 (the fit's bound) where a step's dead time is within errors of none.
        """
        if self.dead_time_s is None:
            return Parameters()
        dead, dead_se = float(self.dead_time_s), _num(self.dead_time_stderr_s)
        lo, hi = interval95(dead, dead_se, "normal")
        gain, gain_se = _num(self.fitted_gain), _num(self.fitted_gain_stderr)
        return Parameters([
            Parameter("dead_time_s", dead, dead_se, (max(lo, 0.0), hi), min=0.0, unit="s"),
            Parameter.estimated("fitted_gain", gain, gain_se),
            Parameter("fitted_baseline", _num(self.fitted_baseline))])

    def fit_statistics(self) -> dict[str, Any]:
        """The measured metrics (the model's own, where there is one, prefixed ``model``), samples and noise."""
        out: dict[str, Any] = {
            "samples": int(np.size(self.time_s)), "t0_s": float(self.t0_s), "step_size": float(self.step_size),
            "initial_value": float(self.initial_value), "final_value": float(self.final_value),
            "gain": float(self.gain), "rise_time_s": float(self.rise_time_s),
            "overshoot_pct": float(self.overshoot_pct), "peak_time_s": float(self.peak_time_s),
            "settling_time_s": float(self.settling_time_s), "dead_time_threshold_s": float(self.dead_time_threshold_s),
            "noise_sigma": float(self.noise_sigma)}
        for k, v in (self.predicted_metrics or {}).items():
            out[f"model {k}"] = float(v)
        return out

    def predicted(self, time_s: ArrayLike) -> NDArray[np.float64]:
        """Model prediction ``b + g*step_size*s(t - t0 - tau)`` at `time_s`.

        Parameters
        ----------
        time_s : array_like
            Times in s.

        Returns
        -------
        numpy.ndarray
            Predicted output, output units.

        Raises
        ------
        ServoscopeError
            When the analysis was run without a model.
        """
        if self._unit_step is None or self.dead_time_s is None:
            raise ServoscopeError("StepAnalysis.predicted: analyse_step was called without a model")
        t = np.asarray(time_s, dtype=float)
        assert self.fitted_baseline is not None and self.fitted_gain is not None
        return self.fitted_baseline + self.fitted_gain * self.step_size * self._unit_step(
            t - self.t0_s - self.dead_time_s
        )

    @property
    def residual(self) -> NDArray[np.float64] | None:
        """``y - predicted`` for samples at or after ``t0_s`` (None without a model)."""
        if self._unit_step is None:
            return None
        sel = self.time_s >= self.t0_s
        return self.y[sel] - self.predicted(self.time_s[sel])

    @property
    def output_moved(self) -> bool:
        """Whether the output moved: its change stands out of the noise (:func:`step_discernible`).

        False comes with the warning "no discernible step response": the metrics are then NaN or noise.
        """
        return step_discernible(self.change, self.noise_sigma)

    @classmethod
    def from_summary(cls, data: dict[str, Any], *, time_s: ArrayLike = (), y: ArrayLike = (),
                     unit_step: Callable[[NDArray[np.float64]], NDArray[np.float64]] | None = None) -> "StepAnalysis":
        """Rebuild a step analysis from its :meth:`summary` (a saved result.json's ``step``).

        Parameters
        ----------
        data : dict
            What :meth:`summary` returned.
        time_s, y : array_like, optional
            The step video's samples (its track), for :meth:`plot` and :meth:`to_pandas`.
        unit_step : callable, optional
            The model's unit step response (without dead time), for :meth:`predicted`;
            without it the analysis has no prediction curve.

        Returns
        -------
        StepAnalysis
            Its :meth:`summary` equals `data`.
        """
        change = (data.get("final_value") or 0.0) - (data.get("initial_value") or 0.0)
        kw = fields_from_summary(cls, data, time_s=readonly(time_s), y=readonly(y), change=change,
                                 fitted_baseline=data.get("fitted_baseline"),
                                 predicted_metrics=None if data.get("predicted") is None else dict(data["predicted"]),
                                 _unit_step=unit_step)
        return cls(**kw)

    def summary(self) -> dict[str, Any]:
        """Scalar results as a JSON-serializable dict (NaN -> None).

        Includes ``predicted``: the model's metrics (rise_time_s,
        overshoot_pct, settling_time_s, peak_time_s from t0 with the fitted
        dead time, final_change = model DC gain * step) or None.
        """
        return jsonable(
            {
                "rise_time_s": self.rise_time_s,
                "overshoot_pct": self.overshoot_pct,
                "settling_time_s": self.settling_time_s,
                "peak_time_s": self.peak_time_s,
                "dead_time_s": self.dead_time_s,
                "dead_time_stderr_s": self.dead_time_stderr_s,
                "dead_time_threshold_s": self.dead_time_threshold_s,
                "final_value": self.final_value,
                "initial_value": self.initial_value,
                "gain": self.gain,
                "fitted_gain": self.fitted_gain,
                "fitted_gain_stderr": self.fitted_gain_stderr,
                "fitted_baseline": self.fitted_baseline,
                "noise_sigma": self.noise_sigma,
                "t0_s": self.t0_s,
                "step_size": self.step_size,
                "predicted": None if self.predicted_metrics is None else dict(self.predicted_metrics),
                "model_source": self.model_source,
                "warnings": list(self.warnings),
            }
        )

    def to_pandas(self) -> Any:
        """Samples (and model prediction if any) as a DataFrame. Needs pandas.

        The parameters' table (one row each) is ``self.parameters.to_pandas()``.
        """
        pd = import_pandas()
        data: dict[str, Any] = {"time_s": np.asarray(self.time_s), "y": np.asarray(self.y)}
        if self._unit_step is not None:
            data["predicted"] = self.predicted(self.time_s)
        return pd.DataFrame(data)

    def plot(self, ax: Axes | None = None) -> list[Any]:
        """Draw the measured samples, the model's prediction (when a model was given), the step
        time and the dead time on `ax` (a new figure's when None).

        Returns
        -------
        list
            The artists: the measured line (x = `time_s`, y = `y`), then the prediction and the
            vertical lines that were drawn (:func:`~servoscope.sysid.plotting.plot_step`).
        """
        predicted = self.predicted(self.time_s) if self._unit_step is not None else None
        return plot_step(new_axes(ax), self.time_s, self.y, predicted, t0_s=self.t0_s, dead_time_s=self.dead_time_s)


def _num(value: float | None) -> float:
    """NaN for None (a number not estimated)."""
    return float("nan") if value is None else float(value)
