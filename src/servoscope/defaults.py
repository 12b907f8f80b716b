"""servoscope's defaults, in one home.

Every stage, the command line and the digital twin take their default marker colours and
shared thresholds from here, so that changing one changes it everywhere (and the twin renders
what the tracker looks for by default, which the tests then vary on purpose).
"""

from __future__ import annotations

# -- markers -------------------------------------------------------------------------------------
#: Leading-edge sticker (matplotlib's tab:red, as in the paper's red sticker).
LEAD_COLOUR = "#d62728"
#: Trailing-edge sticker (tab:green).
TRAIL_COLOUR = "#2ca02c"
#: The input-start LED, lit.
LED_COLOUR = "#ffd400"
#: The twin's reference stickers on the airframe (tab:pink, tab:cyan): hues far from the blade's
#: stickers, the LED and the background. Real campaigns name their own.
REFERENCE_COLOURS = ("#e377c2", "#17becf")
#: The twin's extra stickers along the blade (tab:blue, tab:purple), in the order ``extra_stickers``
#: takes them: hues far from the lead, trail, LED and reference stickers. Real campaigns name their own.
EXTRA_COLOURS = ("#1f77b4", "#9467bd")

# -- sysid: when a dwell or a fit earns a warning ------------------------------------------------
#: Sinusoidal fidelity (share of the output's AC power in the fitted sine) below this flags a
#: dwell "low_fidelity" (fit_sine) and earns the transfer-function fit a warning.
LOW_FIDELITY = 0.95
#: THD above this, with harmonics significant at p < 1e-3 (fit_sine's test), flags a dwell
#: "distorted". A servo's own low-pass attenuates the harmonics its nonlinearity makes (a
#: rate-limited triangle has 12 % THD, ~2 % after the paper's servo at 5 Hz), so the threshold
#: is low; the significance test keeps noise from tripping it.
DISTORTED_THD = 0.01
#: THD above this earns the transfer-function fit a distortion warning when no dwell was
#: flagged by fit_sine's test (a hand-made FrequencyResponse): with no test, a plain threshold
#: well above the noise floor of the THD estimate.
DISTORTED_THD_UNTESTED = 0.05
#: Share of invalid frames in a sine dwell's window above which the dwell is flagged.
MAX_INVALID_FRACTION = 0.2
#: Sine frequencies at or above this fraction of the Nyquist frequency are flagged.
NEAR_NYQUIST = 0.8
#: A fit parameter whose delete-one jackknife error exceeds its Jacobian error this many times
#: earns a warning (it rests on one dwell).
JACKKNIFE_WIDENING_WARNING = 2.0
#: A step test's output "moved" when its change exceeds this many noise sigmas; below it the
#: step's metrics are noise, the analysis says "no discernible step response" and identify
#: leaves the step out (StepAnalysis.output_moved).
STEP_DISCERNIBLE_SIGMA = 10.0

# -- camera: a view that is not square-on --------------------------------------------------------
#: The stickers say the camera looks at the blade this many degrees off square or more (its 95 %
#: interval excluding a square-on view), or that angles read at least
#: :data:`OBLIQUE_GAIN_WARNING` small or large (its 95 % interval excluding no error):
#: ``track``, ``identify`` and the report warn and name ``servoscope plane``. A square-on twin's
#: estimate read 4° (its interval holding 0: the tracker's moments carry 4° of their own); 8° off
#: square is a 1 % foreshortening.
OBLIQUE_VIEW_WARNING_DEG = 8.0
OBLIQUE_GAIN_WARNING = 0.005
