"""System identification: sine-dwell fits, frequency response, transfer-function
fit and step-response analysis.

Typical use::

    fits = [fit_sine(t, angle_rad, f_hz, t0_s=t0) for ...]
    fr = FrequencyResponse.from_sine_fits(fits, input_amplitudes=0.1, labels=names)
    tf_fit = fit_second_order(fr)                  # paper eq. 5, magnitude only
    step = analyse_step(t, angle_rad, t0_s=t0, step_size=0.5,
                        model=tf_fit.transfer_function)
"""

from servoscope.sysid.frequency_response import FrequencyResponse
from servoscope.sysid.sine import SineFit, fit_sine
from servoscope.sysid.step import StepAnalysis, analyse_step, model_step_metrics
from servoscope.sysid.tf_fit import TransferFunctionFit, bandwidth_rad_s, fit_second_order

__all__ = [
    "FrequencyResponse",
    "SineFit",
    "StepAnalysis",
    "TransferFunctionFit",
    "analyse_step",
    "bandwidth_rad_s",
    "fit_second_order",
    "fit_sine",
    "model_step_metrics",
]
