"""The campaign report: what a test engineer reads after ``servoscope identify``."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .figures import (amplitude_figure, bode_figure, candidate_traces_figure, describing_function_figure, dwell_figure,
                      overlay_figure, servo_traces_figure, step_figure)
from .html import ReportSection, render_html
from .blade_section import blade_section
from .plane_section import plane_section
from .rotor_section import rotor_section
from .sweep_section import sweep_section
from ..campaign.headline import SOURCE_KEYS
from ..numbers import format_interval, format_value, format_with_uncertainty
from ..camera.plane_map import recorded_points
from ..sysid.model_text import PARAM_LABELS, model_equation
from ..sysid.plotting import on_branch_deg

if TYPE_CHECKING:  # pragma: no cover
    from ..campaign.result import IdentificationResult

__all__ = ["build_report", "model_phase_deg"]


def model_phase_deg(tf, omega_rad_s: np.ndarray, dead_time_s: float | None) -> np.ndarray:
    """Unwrapped phase of G(jω)·e^(−jωτ) in degrees."""
    response = np.asarray(tf(1j * np.asarray(omega_rad_s))).ravel()
    phase = np.unwrap(np.angle(response))
    if dead_time_s is not None:
        phase = phase - np.asarray(omega_rad_s) * dead_time_s
    return np.degrees(phase)


def _representative_dwell(result: "IdentificationResult") -> str:
    # The dwell nearest the bandwidth shows the dynamics best (the paper's Fig. 7 shows one).
    labels = list(result.sine_fits)
    target = result.model.bandwidth_rad_s / (2 * math.pi) / 2.0
    return min(labels, key=lambda k: abs(math.log(result.sine_fits[k].frequency_hz / target)))


def _track_xy_recorded(result: "IdentificationResult", label: str, index: int) -> tuple[np.ndarray, np.ndarray]:
    """Centroids of one frame in the recorded (distorted) image, for drawing on it."""
    track = result.tracks[label]
    lead, trail = recorded_points(np.stack([track.lead_xy_px[index], track.trail_xy_px[index]]),
                                  result.campaign.camera, result.campaign.plane)
    return lead, trail


def _codec_cell(fit) -> str:
    """The codec check of one dwell, for the report's dwell table."""
    if fit is None or fit.codec_gain_bias is None:
        return "—" if fit is None or not fit.n_intra else f"not checked ({fit.n_intra} I-frames)"
    bias, err = format_with_uncertainty(100.0 * fit.codec_gain_bias, 100.0 * fit.codec_gain_bias_stderr)
    used = "" if fit.estimator == "intra frames" else "; all frames used"
    return f"{bias} % ± {err} % ({fit.n_intra} I-frames{used})"


def dead_time_stderr_s(result: "IdentificationResult") -> float | None:
    """Standard error of ``result.dead_time_s``, from the same estimate (step test or dwells' phases)."""
    return result.dead_time_stderr_s


def dead_time_rows(result: "IdentificationResult") -> list[list[str]]:
    """One row per dead-time estimate (dwells' phases, step): value ± stderr and 95 % interval, in ms."""
    rows = []
    estimates = result.dead_time_estimates
    chosen = SOURCE_KEYS.get(result.dead_time_source or "")
    for key, label in (("phase", "frequency response's phases"), ("step", "step test")):
        e = estimates.get(key)
        if e is None:
            continue
        value, err_text = format_with_uncertainty(1e3 * e.value_s, 1e3 * e.stderr_s)
        note = " (the model's)" if key == chosen else ""
        if e.shared_t0_stderr_s:
            note += f"; includes ±{1e3 * e.shared_t0_stderr_s:.2f} ms of input-start timing the dwells may share"
        lo, hi = e.ci95_s
        rows.append([f"dead time τ (ms), from the {label}{note}",
                     f"{value} ± {err_text}, 95 % {format_interval(1e3 * lo, 1e3 * hi, 1e3 * e.stderr_s)}"])
    return rows or [["dead time τ (ms)", "not measured"]]


def exposure_text(result: "IdentificationResult") -> str:
    """The camera exposure and where it came from, for the report."""
    e = result.exposure
    if e is None:
        return "—"
    if e.value_s is None:
        return f"unknown: {e.detail}"
    if e.source == "given":
        return f"{1e3 * e.value_s:.4g} ms (given)"
    where = {"LED": "the LED", "blur": "the stickers' motion blur", "LED+blur": "the LED and the motion blur"}
    return (f"{1e3 * e.value_s:.3g} ms, 95 % {1e3 * e.ci95_s[0]:.3g}–{1e3 * e.ci95_s[1]:.3g} ms, from "
            f"{where.get(e.source, e.source)}: {e.detail}")


def build_report(result: "IdentificationResult", figures_dir: Path | None = None) -> str:
    """One self-contained HTML page (figures embedded as PNG).

    Parameters
    ----------
    result : IdentificationResult
    figures_dir : Path, optional
        Also write every figure there as PNG and SVG.
    """
    import matplotlib

    summary = result.summary()
    # Titles at the top of their axes (rc "axes.titley"), not placed by matplotlib's search above tick labels
    # and offset texts, which it repeats at each of a figure's three draws (the layout, the PNG, the SVG): no
    # report figure has ticks or labels above its axes, and the search was ~15 % of a report's time. The twin's
    # reports' figures are the same to the pixel.
    with matplotlib.rc_context({"axes.titley": 1.0}):
        sections = _sections(result, summary, figures_dir)
    return render_html("servoscope report", f"{result.campaign.path} · servoscope {summary['servoscope_version']}",
                       [s for s in sections if s is not None])


def _sections(result: "IdentificationResult", summary: dict, figures_dir: Path | None) -> list:
    return [
        model_section(result, summary, figures_dir),
        frequency_response_section(result, figures_dir),
        sweep_section(result, figures_dir),
        rotor_section(result, figures_dir),
        plane_section(result, figures_dir),
        blade_section(result, figures_dir) if result.modes or result.heave_response or result.bending_response
        else None,
        _servo_model_section(result, figures_dir) if result.servo_model is not None else None,
        dwell_section(result, figures_dir),
        step_section(result, figures_dir),
        tracking_section(result, summary, figures_dir),
    ]


def _fit_text(model) -> str:
    """How the model was fitted: the fit's mode, its order, CIFER's J and the information criteria."""
    fit_info = model.summary().get("fit") or {}
    return (
        ("Fit: magnitude and phase with a dead time (every dwell's input start is known from the LED)"
         if model.mode == "complex" else "Fit: magnitude only, as in the paper (the dead time cannot be identified from |G|)")
        + f"; order (nb, na) = {tuple(model.order)}"
        + (f"; CIFER's J = {fit_info['J']:.3g} ({model.J_rating})" if fit_info.get("J") is not None else "")
        + (f"; AIC {fit_info['AIC']:.4g}, BIC {fit_info['BIC']:.4g}" if fit_info.get("AIC") is not None else "")
        + "."
    )


def parameter_table(result: "IdentificationResult") -> tuple[list[str], list[list[str]]]:
    """The model's parameters: value, standard error, intervals (and bootstrap's, and the dwell each rests on most)."""
    model = result.model
    boot = model.ci95_bootstrap or {}
    influence = model.influence or {}
    header = (["parameter", "value", "standard error", "95 % interval"] + (["95 % bootstrap"] if boot else [])
              + (["dwell it rests on most: value without it"] if influence else []))
    rows = []
    phase_dead = result.dead_time_estimates.get("phase")
    for name in model.param_names:
        lo_hi = model.ci95.get(name)
        err = model.stderr.get(name)
        if name == "dead_time_s" and phase_dead is not None:
            # With the input-start timing the dwells may share (not in the fit's own error).
            lo_hi, err = phase_dead.ci95_s, phase_dead.stderr_s
        value_text, err_text = format_with_uncertainty(model.params.get(name), err)
        held = model.held.get(name, {})
        label = PARAM_LABELS.get(name, name) + (
            " (held fixed)" if "fixed" in held else
            f" (bounded {held['bounds'][0]:.4g}–{held['bounds'][1]:.4g})" if "bounds" in held else "")
        row = [label, value_text, err_text,
               "—" if lo_hi is None else format_interval(lo_hi[0], lo_hi[1], err)]
        if boot:
            b = boot.get(name)
            row.append("—" if b is None else format_interval(b[0], b[1], err))
        if influence:
            inf = influence.get(name)
            row.append("—" if inf is None else
                       f"{inf['dwell']}: {format_with_uncertainty(inf['without'], err)[0]} "
                       f"({inf['shift_stderr']:+.1f} σ)")
        rows.append(row)
    return header, rows


def _quantities(result: "IdentificationResult") -> list[list]:
    """The model's other quantities: bandwidth, dead times, exposure, the fit's residuals."""
    model = result.model
    return [
        ["−3 dB bandwidth (rad/s)", result.bandwidth_rad_s],
        ["−3 dB bandwidth (Hz)", result.bandwidth_rad_s / (2 * math.pi)],
        *dead_time_rows(result),
        ["camera exposure (shutter)", exposure_text(result)],
        ["residual RMS of the frequency-domain fit, magnitude (dB)", model.residual_rms_db],
        ["residual RMS of the frequency-domain fit, phase (deg)", model.residual_rms_deg],
    ]


def _add_warnings(s: ReportSection, result: "IdentificationResult", summary: dict) -> None:
    """Every warning, the campaign's and each test's (each once), or a line saying there are none."""
    all_warnings = list(result.warnings) + [w for t in summary["tests"] for w in (f"{t['label']}: {x}" for x in t["warnings"])]
    if all_warnings:
        s.warnings(list(dict.fromkeys(all_warnings)))
    else:
        s.html_parts.append('<p class="ok">No warnings.</p>')


def _add_order_selection(s: ReportSection, selection) -> None:
    """How the model's order was chosen (``order="auto"``): the slope and the candidates compared."""
    s.text(
        f"Order selection: the gain falls by {selection.slope_db_per_decade:.1f} dB/decade at the top of the data "
        f"(relative degree ≥ {selection.relative_degree_estimate}); candidates compared by BIC and J:"
    )
    cols = ["order", "n_params", "J", "AIC", "BIC", "residual_rms_db", "determined", "chosen"]
    s.table(cols, [[str(tuple(r["order"])) if k == "order" else r.get(k) for k in cols] for r in selection.table])


def model_section(result: "IdentificationResult", summary: dict, figures_dir) -> ReportSection:
    """The identified model: its equation, how it was fitted, its parameters and quantities, the warnings.

    The first table is the headline's (:func:`servoscope.campaign.headline.headline`), the numbers
    ``identify`` prints and result.json's ``model`` holds. When a nonlinear structure was selected,
    the transfer function fitted to the dwells follows under its own name: a describing function.
    """
    model = result.model
    head = result.headline
    s = ReportSection("Identified model", figures_dir=figures_dir)
    s.text(head.equation)
    if head.domain == "time domain":
        s.text(f"Fit: the {head.structure} model, selected from the whole traces (the dwells and the step "
               "together; see \"One model for the sines and the step\").")
        s.table(["parameter", "value", "standard error", "95 % interval"], head.rows())
        s.table(["quantity", "value"], _quantities(result))
        s.text(f"The transfer function fitted to the dwells' fundamentals, below, describes the {head.structure} "
               "servo at the dwells' input amplitudes (a describing function), not its linear part: its gain and "
               "natural frequency are not the servo's.")
        s.text(_fit_text(model))
        s.table(*parameter_table(result))
    else:
        s.text(_fit_text(model))
        s.table(*_headline_table(result))
        s.table(["quantity", "value"], _quantities(result))
    if model.stderr_jackknife is not None:
        s.text("Standard errors: the larger of the Jacobian's (scaled by the misfit when the residuals exceed their "
               "stated errors) and the delete-one-dwell jackknife's, which refits the model with each dwell left "
               "out: a dwell with an error its own statistics cannot show (the codec shrinking the smallest "
               "motions, a resonance the model lacks) widens the interval of what rests on it.")
    _add_warnings(s, result, summary)
    if model.order_selection is not None:
        _add_order_selection(s, model.order_selection)
    return s


def _headline_table(result: "IdentificationResult") -> tuple[list[str], list[list[str]]]:
    """The headline's rows with the transfer-function fit's bootstrap and influence columns where they are its."""
    head = result.headline
    header, rows = parameter_table(result)
    extra = {name: row[4:] for name, row in zip(result.model.param_names, rows)}
    out = []
    for name, row in zip(head.parameters, head.rows()):
        # The bootstrap's and the influence's columns are the transfer function's: not the step's dead time.
        own = name != "dead_time_s" or head.dead_time_source == "frequency response (phase)"
        cells = extra.get(name, []) if own else []
        out.append(row + cells + ["—"] * (len(header) - 4 - len(cells)))
    return header, out


def _dwell_rows(result: "IdentificationResult") -> tuple[list[str], list[list], bool]:
    """The frequency response's table, one row per dwell; whether the codec check's column is in it."""
    fr = result.frequency_response
    dwell_rows = []
    fits_in_order = [result.sine_fits.get(label) for label in fr.labels]
    checked = any(f is not None and f.codec_gain_bias is not None for f in fits_in_order)
    for r, sine_fit in zip(fr.summary(), fits_in_order):
        gain, gain_se = format_with_uncertainty(r["gain"], r.get("gain_stderr"))
        phase, phase_se = format_with_uncertainty(r["phase_deg"], r.get("phase_stderr_deg"))
        gain_db_se = None if r.get("gain_stderr") is None else 20.0 / math.log(10.0) * r["gain_stderr"] / r["gain"]
        gain_db = format_with_uncertainty(r["gain_db"], gain_db_se)[0]
        row = [r["video"], format_value(r["frequency_hz"], 4), gain, gain_se, gain_db, phase, phase_se,
               format_value(r["fidelity"], 5), format_value(r.get("thd"), 2), ", ".join((r.get("flags") or "").split()) or "—"]
        if checked:
            row.append(_codec_cell(sine_fit))
        dwell_rows.append(row)
    header = (["dwell", "f (Hz)", "gain", "± s.e.", "gain (dB)", "phase (deg)", "± s.e.", "fidelity", "THD", "flags"]
              + (["codec: other frames against the I-frames"] if checked else []))
    return header, dwell_rows, checked


def frequency_response_section(result: "IdentificationResult", figures_dir) -> ReportSection:
    """The Bode plot, the gain against the input amplitude, and the dwells' table."""
    fr = result.frequency_response
    model = result.model
    dead = result.dead_time_s
    s = ReportSection("Frequency response", figures_dir=figures_dir)
    omega_grid = np.logspace(np.log10(2 * np.pi * fr.frequency_hz.min() / 2), np.log10(2 * np.pi * fr.frequency_hz.max() * 2), 300)
    tau = model.dead_time_s if model.dead_time_s is not None else dead
    # Each measured phase drawn on the model's branch (modulo 360°): the dwells' own unwrapping cannot
    # follow a dead time across dwells far apart in frequency (a rotor's 3, 8, 14 Hz: more than 180° apart).
    model_phase = model_phase_deg(model.transfer_function, omega_grid, tau)
    phase = on_branch_deg(fr.phase_deg, np.interp(2 * np.pi * np.asarray(fr.frequency_hz), omega_grid, model_phase))
    fig = bode_figure(
        fr.frequency_hz,
        fr.gain,
        fr.gain_stderr,
        phase,
        omega_grid / (2 * np.pi),
        model.magnitude(omega_grid),
        model_phase,
        bandwidth_rad_s=model.bandwidth_rad_s,
    )
    s.figure(fig, "Measured gains (error bars: ±1 standard error) and the fitted 2nd-order model; phase measured from the LED's switch, model phase including the step test's dead time.", "Bode plot", name="bode")
    if result.amplitude_checks:
        verdicts = "; ".join(f"{c.frequency_hz:.3g} Hz: {100 * c.change:+.2f} % from {c.amplitudes[0]:g} to "
                             f"{c.amplitudes[-1]:g} (p = {c.p_value:.2g}, {'linear' if c.linear else 'NOT linear'})"
                             for c in result.amplitude_checks)
        s.figure(amplitude_figure(result.amplitude_checks),
                 f"Each frequency's gains at its input amplitudes, against their weighted mean: a linear servo's agree "
                 f"within their errors (χ² test, not linear below p = 0.001). {verdicts}.",
                 "Gain against input amplitude", name="amplitude")
    header, dwell_rows, checked = _dwell_rows(result)
    s.table(header, dwell_rows)
    if checked:
        s.text("Where a dwell has enough I-frames (frames the codec coded on their own), its gain and phase are "
               "fitted to them alone: the codec's motion prediction cannot hold the sticker back there. The last "
               "column is how much the other frames' amplitude differs (docs/accuracy.md, \"The codec check\").")
    return s


def dwell_section(result: "IdentificationResult", figures_dir) -> ReportSection | None:
    """One dwell's trace with its fitted sine (the dwell nearest the bandwidth), then every dwell's thumbnail;
    None for a campaign without dwells (a sweep's)."""
    if not result.sine_fits:
        return None
    label = _representative_dwell(result)
    fit = result.sine_fits[label]
    track = result.tracks[label]
    s = ReportSection(f"One dwell: {label}", figures_dir=figures_dir)
    fitted = fit.model(track.time_s)
    s.figure(
        dwell_figure(track.time_s, track.angle_rad, track.valid, fitted, fit.window_s, t0_s=fit_t0(result, label), title=f"{label}: measured angle and fitted sine (paper Fig. 7)"),
        f"Fitted at {fit.frequency_hz:.4g} Hz: amplitude {fit.amplitude:.4g} rad, residual RMS {fit.residual_rms:.3g} rad, fidelity {fit.fidelity:.4f}. Shaded: the steady-state window.",
        "Dwell trace",
    )
    s.text("Every dwell (click to enlarge):")
    import matplotlib.pyplot as plt

    # All open at once until the thumbnails encode (and close) them: a campaign of 28 dwells
    # would make matplotlib warn of more than 20 open figures.
    with plt.rc_context({"figure.max_open_warning": 0}):
        thumbs = []
        for other, other_fit in result.sine_fits.items():
            t = result.tracks[other]
            fig = dwell_figure(t.time_s, t.angle_rad, t.valid, other_fit.model(t.time_s), other_fit.window_s,
                               t0_s=fit_t0(result, other), title=f"{other}: {other_fit.frequency_hz:.3g} Hz")
            thumbs.append((fig, f"{other}: amplitude {other_fit.amplitude:.4g} rad, fidelity {other_fit.fidelity:.4f}",
                           f"trace_{other}"))
        s.thumbnails(thumbs)
    return s


def step_section(result: "IdentificationResult", figures_dir) -> ReportSection | None:
    """The step test measured against the model's prediction, and its metrics; None without a step."""
    if result.step is None or result.step_label is None:
        return None
    model = result.model
    st = result.step
    strack = result.tracks[result.step_label]
    s = ReportSection(f"Step response: {result.step_label}", figures_dir=figures_dir)
    predicted = st.predicted(strack.time_s)
    s.figure(
        step_figure(strack.time_s, strack.angle_rad, strack.valid, predicted, t0_s=strack.t0_s, dead_time_s=st.dead_time_s),
        "Measured step response and the identified model's prediction (dead time fitted on this test).",
        "Step response",
        name="step",
    )
    from ..sysid import model_step_metrics

    # Predicted with the same dead time, so that both columns count from the input start.
    predicted_metrics = model_step_metrics(model.transfer_function, dead_time_s=st.dead_time_s or 0.0)
    s.table(
        ["metric", "measured", "predicted by the model"],
        [
            ["10–90 % rise time (s)", st.rise_time_s, predicted_metrics.get("rise_time_s")],
            ["overshoot (%)", st.overshoot_pct, predicted_metrics.get("overshoot_pct")],
            ["2 % settling time (s)", st.settling_time_s, predicted_metrics.get("settling_time_s")],
            ["dead time, model fit (s)", st.dead_time_s, None],
            ["dead time, first visible motion (s)", st.dead_time_threshold_s, None],
        ],
    )
    return s


def tracking_section(result: "IdentificationResult", summary: dict, figures_dir) -> ReportSection | None:
    """The tracking check (paper Fig. 4, 6): a frame with the centroids, the segmentation, the error analysis, the
    videos' table; None without a snapshot."""
    # Fig. 4: a frame with the centroids and the joining line.
    first = result.campaign.tests[0].label
    track = result.tracks[first]
    if track.snapshot_rgb is None:
        return None
    i = track.snapshot_index
    lead, trail = _track_xy_recorded(result, first, i)
    s = ReportSection("Tracking check", figures_dir=figures_dir)
    s.figure(
        overlay_figure(track.snapshot_rgb, lead, trail, float(track.angle_rad[i]), title=f"{first}, frame {i}: detected centroids (paper Fig. 4)"),
        "Squares: the markers' centroids; solid line: the line joining them; dashed: horizontal reference.",
        "Frame with detected centroids",
        name="overlay",
    )
    segmentation = _segmentation(result, track, lead, trail)
    if segmentation is not None:
        s.figure(segmentation, "Pixels within each marker's colour band, or past its brightness threshold on monochrome footage (before the soft, subpixel weighting), and each marker zoomed with its centroid.", "Segmentation", name="segmentation")
    from ..markers.error_analysis import angle_error_analysis, plot_angle_error

    analysis = angle_error_analysis(track)
    if analysis.get("separation_px") and math.isfinite(analysis["separation_px"]):
        s.figure(
            plot_angle_error(analysis),
            f"Angle error against sticker separation (paper Fig. 6): at {analysis['separation_px']:.0f} px, "
            f"a 1 px centroid error bounds the angle error at {analysis['worst_case_deg']:.3f}°; the measured "
            f"centroid noise from the pixels ({analysis['centroid_sigma_px']:.3f} px) gives "
            f"{analysis['angle_sigma_deg']:.4f}° (1σ)"
            + (f"; the tracking error measured on the two markers' rigid-motion null channel, codec errors "
               f"included, is {analysis['measured_noise_deg']:.4f}° RMS." if analysis.get("measured_noise_deg")
               else "."),
            "Error analysis",
            name="error_analysis",
        )
    with_reference = any(t.get("reference_motion_rad") for t in summary["tests"])

    def turned(t: dict) -> str:
        m = t.get("reference_motion_rad")
        return "—" if not m else (f"{math.degrees(m['peak_to_peak']):.3f}° p-p, "
                                  f"{math.degrees(m['rms']):.3f}° RMS")

    s.table(
        ["video", "frames", "valid", "t0 (s)"] + (["reference line turned (taken off)"] if with_reference else [])
        + ["warnings"],
        [[t["video"], t["frames"], t["valid_frames"], t["t0_s"]] + ([turned(t)] if with_reference else [])
         + ["; ".join(t["warnings"]) or "—"] for t in summary["tests"]],
    )
    return s


def _servo_model_section(result: "IdentificationResult", figures_dir) -> ReportSection:
    """The time-domain models (``identify --nonlinear``): candidates, the selected one, the cross-validation."""
    selection = result.servo_model
    sel = selection.selected
    s = ReportSection("One model for the sines and the step", figures_dir=figures_dir)
    s.text("Each candidate simulated for every test and fitted to the whole measured traces (the dwells' harmonics "
           "and transients, and the step), each data set weighted by its own noise; selected by BIC (a nonlinear "
           "structure must beat the linear model by 10). CIFER's J compares each model's fundamentals with the "
           "measured frequency response; the step's fit is MATLAB compare's, 100·(1 − ‖y − ŷ‖/‖y − ȳ‖).")
    s.table(["structure", "BIC", "CIFER J (dwells)", "step fit (%)", "selected"],
            [[c.structure, format_value(c.bic, 6), format_value(c.J, 3),
              "—" if c.step_fit_percent is None else f"{c.step_fit_percent:.2f}", "✓" if c is sel else ""]
             for c in selection.candidates])
    rows = []
    for name, value in sel.params.items():
        v, e = format_with_uncertainty(value, sel.stderr.get(name))
        lo, hi = sel.ci95[name]
        held = " (held fixed)" if name in sel.fixed else f" (tied: {sel.tied[name]})" if name in sel.tied else ""
        rows.append([PARAM_LABELS.get(name, name) + held, v, e,
                     format_interval(lo, hi, sel.stderr[name])])
    s.table([f"{sel.structure} model", "value", "± s.e.", "95 % interval"], rows)
    s.text(f"Cross-validation: {selection.cross_validation.get('verdict')}.")
    if sel.traces:
        s.figure(servo_traces_figure(sel), f"Each test measured (dots) and simulated by the {sel.structure} model "
                 "(lines), its rest angle taken off, tests stacked.", "Measured and modelled traces", name="servo_traces")
        shown = [sel] + [c for c in selection.candidates if c is not sel and c.structure == "linear"]
        amplitude = {t.label: t.amplitude for t in result.campaign.tests}
        fr = result.frequency_response
        measured: dict[float, list] = {}
        for label, f, g, se, ph in zip(fr.labels, fr.frequency_hz, fr.gain, fr.gain_stderr, fr.phase_deg):
            if label in amplitude:  # the dwells' points; a sweep's (label@f) have no one amplitude of their own
                measured.setdefault(round(float(f), 6), []).append((amplitude[label], g, se, ph))
        if measured:
            s.figure(describing_function_figure(shown, measured), "Each dwell's measured gain and phase (points, ±1 "
                     "standard error) against its input amplitude, and the models' describing functions (their "
                     "fundamentals, simulated): a linear model's is flat; a nonlinearity's bends.",
                     "Describing function", name="describing_function")
        dwells = [tr for tr in sel.traces if tr.kind == "sine"]
        if dwells:
            # The dwell where the candidates disagree most shows what tells them apart.
            worst = max(dwells, key=lambda tr: max(float(np.std(c.predict(tr) - sel.predict(tr)))
                                                   for c in selection.candidates if c.traces))
            s.figure(candidate_traces_figure(worst, [c for c in selection.candidates if c.traces]),
                     f"{worst.label}, where the candidates differ most: measured (dots) and each candidate's "
                     "simulation.", "Candidates against one trace", name="candidate_traces")
    return s


def _segmentation(result: "IdentificationResult", track, lead, trail):
    from ..markers.colour import AUTO, parse_colour, seed_model
    from .figures import segmentation_figure

    specs = {"lead": parse_colour(result.campaign.lead), "trail": parse_colour(result.campaign.trail)}
    if AUTO in specs.values():
        return None
    frame = track.snapshot_rgb
    # A colour's band, or a brightness marker's threshold from the frame's levels (monochrome footage).
    models = {name: seed_model(spec, frame) for name, spec in specs.items()}
    masks = {name: model.mask(frame) for name, model in models.items()}
    return segmentation_figure(frame, masks, {name: model.rgb for name, model in models.items()},
                               {"lead": lead, "trail": trail})


def fit_t0(result: "IdentificationResult", label: str) -> float | None:
    test = next(t for t in result.campaign.tests if t.label == label)
    return test.t0_s if test.t0_s is not None else result.tracks[label].t0_s
