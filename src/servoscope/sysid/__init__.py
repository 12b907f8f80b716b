"""System identification: sine-dwell fits, frequency response, transfer-function
fit, order selection and step-response analysis.

Typical use::

    fits = [fit_sine(t, angle_rad, f_hz, t0_s=t0) for ...]   # settle_s="auto"
    fr = FrequencyResponse.from_sine_fits(fits, input_amplitudes=0.1, labels=names)
    tf_fit = fit_second_order(fr)                  # paper eq. 5, magnitude only
    tf_fit = fit_transfer_function(fr, order=(0, 2), mode="complex", bootstrap=200)
    sel = select_order(fr, mode="complex")         # or order="auto" above
    step = analyse_step(t, angle_rad, t0_s=t0, step_size=0.5,
                        model=tf_fit.transfer_function)
    fr.plot(); tf_fit.plot(); step.plot()          # matplotlib artists, for keeping

Modules, each importing only those below it:

* results: ``sine_result`` (SineFit), ``frequency_response``, ``tf_result``
  (TransferFunctionFit, OrderSelection), ``step_result`` (StepAnalysis); ``plotting`` draws them;
* sine dwells: ``sine`` (fit_sine) on ``_sine_window``, ``_sine_harmonics``, ``_sine_codec``, ``hac``;
* transfer-function fit (lmfit's separation): the model ``_rational``, data and weights
  ``_tf_data``, residuals and minimizer ``_tf_minimize``, ``_tf_metrics``, ``_tf_build``,
  resampling ``_tf_resample``, one order's fit ``_fixed_order``; then ``order`` (select_order)
  and, on top, ``tf_fit`` (fit_transfer_function, whose ``order="auto"`` calls select_order);
* step tests: ``step`` (analyse_step); the dead time's two estimates ``dead_time``;
* a turning rotor's passes (one irregular sample a blade a revolution, issue 33): ``pass_result``
  (PassSineFit, BladeOffset, BladeDifference), ``pass_sine`` (fit_pass_sine, one offset a blade),
  ``pass_step`` (analyse_pass_step); ``FrequencyResponse.from_sine_fits`` takes PassSineFits.

Every fit's parameters are :class:`~servoscope.parameters.Parameter` objects gathered in a
:class:`~servoscope.parameters.Parameters` (``result.parameters``), and every result offers
``fit_report()``, ``to_pandas()`` and a notebook table from them (:class:`~servoscope.parameters.FitResult`).
"""

from servoscope.parameters import FitResult, Parameter, Parameters, interval95
from servoscope.sysid._fixed_order import check_held
from servoscope.sysid.dead_time import DeadTimeEstimate, dead_time_estimates
from servoscope.sysid._tf_resample import with_gain_scale_uncertainty
from servoscope.sysid.frequency_response import FrequencyResponse
from servoscope.sysid.linearity import AmplitudeCheck, gain_against_amplitude
from servoscope.sysid.pass_result import BladeDifference, BladeOffset, PassSineFit
from servoscope.sysid.pass_sine import fit_pass_sine, pass_nyquist_hz, rev_per_s_from_passes
from servoscope.sysid.pass_step import PassStepAnalysis, analyse_pass_step
from servoscope.sysid.order import OrderSelection, estimate_slope_db_per_decade, select_order
from servoscope.sysid.sine import SineFit, fit_sine, hac_covariance, rigid_motion_null
from servoscope.sysid.step import StepAnalysis, analyse_step, model_step_metrics
from servoscope.sysid.sweep import SweepResponse, sweep_response
from servoscope.sysid.tf_fit import (
    TransferFunctionFit,
    bandwidth_rad_s,
    cifer_cost,
    fit_second_order,
    fit_transfer_function,
)

__all__ = [
    "AmplitudeCheck",
    "BladeDifference",
    "BladeOffset",
    "DeadTimeEstimate",
    "FitResult",
    "FrequencyResponse",
    "OrderSelection",
    "PassSineFit",
    "PassStepAnalysis",
    "Parameter",
    "Parameters",
    "SineFit",
    "StepAnalysis",
    "SweepResponse",
    "TransferFunctionFit",
    "analyse_pass_step",
    "analyse_step",
    "bandwidth_rad_s",
    "check_held",
    "cifer_cost",
    "dead_time_estimates",
    "estimate_slope_db_per_decade",
    "fit_pass_sine",
    "fit_second_order",
    "fit_sine",
    "fit_transfer_function",
    "gain_against_amplitude",
    "hac_covariance",
    "interval95",
    "model_step_metrics",
    "pass_nyquist_hz",
    "rev_per_s_from_passes",
    "rigid_motion_null",
    "select_order",
    "sweep_response",
    "with_gain_scale_uncertainty",
]
