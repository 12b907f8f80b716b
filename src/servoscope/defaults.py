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

# -- markers: what is not there is not found -----------------------------------------------------
#: A first-frame blob whose hue is further than this from the colour asked is not that marker
#: (OpenCV hue units, 2° each: the candidates' ``hue_distance``, markers/selection.py). Measured on
#: the twin (benchmarks/marker_colour_gate.py: 480×384, 200 frames/s, every 3rd frame, the
#: sticker's candidate against the colour asked): clean H.264/HEVC/MPEG-2/raw 0.6–1.7; 100 Hz
#: flicker of 30 % 1.6 (2.7 at 4 Mbit/s); shake 1 px 1.3; a white-balance cast of ±15 % in
#: red/blue or ±10 % in green 1.2–4.5; H.264 at 0.3–1 Mbit/s 2.5–3.5, HEVC 0.3–2 Mbit/s 3.9–4.2,
#: MPEG-2 1 Mbit/s 3.0; 10 px stickers 3.0 (4 Mbit/s) to 5.4 (and a cool cast); flicker at
#: 1 Mbit/s 4.9; an olive sticker under a cool cast at 1 Mbit/s 5.6, the largest; orange, violet,
#: blue, cyan, pink, olive stickers 0.1–1.9 (pale pink and violet under a ±15 % cast move 10.6–11.9
#: or leave the ±12-unit band: not trackable either way). OpenCV's vtest.avi (pedestrians, no
#: stickers) against the red #d62728: its brown clothing 8.0–11.4 (two specks of 12 and 20 px,
#: 7.0 and 5.1). The gate: 25 % above the largest on footage with the sticker. A flat #883a28
#: is 5.6 from #d62728: colour alone cannot refuse it (the rigid-pair and valid-frame checks do).
MARKER_HUE_GATE = 7.0
#: A track with fewer valid frames than this (and frames left out) is no measurement: ``servoscope
#: track`` ends in an error (exit 2), not a CSV of a handful of rows. The fits' own minimums: a sine dwell needs 5
#: valid frames, a step test 10 (campaign/runner.py, sysid/_sine_window.py); the larger is taken.
MIN_VALID_FRAMES = 10

# -- camera: what a frame's timestamp marks ------------------------------------------------------
#: Which instant of its exposure a frame's timestamp marks: campaign.toml's ``[camera] timestamp``,
#: ``TrackerSettings.timestamp``, ``servoscope track --timestamp`` and the twin's ``timestamp_at``.
#: The first is the default ("middle", as the twin and most containers' players assume).
TIMESTAMPS = ("middle", "start", "end")
TIMESTAMP = TIMESTAMPS[0]

# -- sweeps: dwell lengths and the steady state --------------------------------------------------
#: The word that asks the sine fit to find where each dwell's transient ends (sysid/sine.py's
#: ``fit_sine(settle_s="auto")``: a reference sine fitted to the record's second half, the window
#: starting where the residual falls to :data:`TRANSIENT_SIGMAS` of its noise). ``fit_sine``'s own
#: default, for a record handed to it alone; campaign.toml may ask for it (``[analysis] settle_s =
#: "auto"``).
SETTLE_AUTO = "auto"
#: Time skipped after the input starts before a sine dwell's steady state, s: campaign.toml's
#: ``[analysis] settle_s`` when it says none, ``servoscope plan --settle`` (a plan's dwells last
#: this plus their periods, and the plan writes it as ``[analysis] settle_s``), and a plan read
#: back without one. A number, not "auto", because a plan needs a length for each dwell, and a
#: fixed window is what identify has always used (the fit still warns when a transient outlasts
#: it: ``consider settle_s='auto'``). On the twin's quick campaign "auto" starts the dwells'
#: windows 0.31-0.5 s after t0 and the model agrees with 0.5 s's within 0.05 %.
SETTLE_S = 0.5
#: ``settle_s="auto"``: the transient lasts while the RMS residual over 8 samples exceeds this many
#: noise sigmas of the record's second half (8 samples keep the test's false-alarm rate below 1e-8
#: a window); a numeric settle_s earns a warning when it ends before that.
TRANSIENT_SIGMAS = 3.0
#: Shortest input of a planned dwell, s (``servoscope plan --min-seconds``; a plan read back
#: without ``[plan] min_seconds`` takes it too).
MIN_DWELL_S = 3.0

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

# -- a turning rotor (issue 33) ----------------------------------------------------------------------------
#: Each blade's (lead, trail) sticker colours, blade 0 first, where campaign.toml's [rotor] or the plan names
#: none: blade 0 the static stickers' (tab:red, tab:green), blade 1 blue and magenta, blade 2 cyan and
#: orange: saturated hues at least 28° apart from each other and from the LED's yellow (the twin's too).
ROTOR_BLADE_COLOURS: tuple[tuple[str, str], ...] = ((LEAD_COLOUR, TRAIL_COLOUR), ("#1d4fd8", "#c81dd8"),
                                                    ("#17becf", "#ff7f0e"))
