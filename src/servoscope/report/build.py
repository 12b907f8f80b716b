"""The campaign report: what a test engineer reads after ``servoscope identify``."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from .figures import bode_figure, dwell_figure, overlay_figure, step_figure
from .html import ReportSection, render_html

if TYPE_CHECKING:  # pragma: no cover
    from ..campaign.runner import IdentificationResult

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
    lead, trail = track.lead_xy_px[index], track.trail_xy_px[index]
    camera = result.campaign.camera
    if camera is not None:
        lead, trail = camera.distort_points(np.stack([lead, trail]))
    return lead, trail


def build_report(result: "IdentificationResult") -> str:
    """One self-contained HTML page (figures embedded as PNG)."""
    fr = result.frequency_response
    model = result.model
    summary = result.summary()
    sections: list[ReportSection] = []

    s = ReportSection("Identified model")
    dead = result.dead_time_s
    dead_txt = "not measured" if dead is None else f"{1e3 * dead:.1f} ms"
    s.text(
        f"G(s) = {model.gain:.4g} · {model.natural_frequency_rad_s:.4g}² / "
        f"(s² + 2·{model.damping_ratio:.3g}·{model.natural_frequency_rad_s:.4g}·s + {model.natural_frequency_rad_s:.4g}²)"
        f" · e^(−sτ), τ = {dead_txt}"
    )
    rows = [
        ["gain K (rad per input unit)", model.gain, model.gain_stderr],
        ["natural frequency ωn (rad/s)", model.natural_frequency_rad_s, model.natural_frequency_stderr_rad_s],
        ["damping ratio ζ", model.damping_ratio, model.damping_ratio_stderr],
        ["−3 dB bandwidth (rad/s)", model.bandwidth_rad_s, None],
        ["−3 dB bandwidth (Hz)", model.bandwidth_rad_s / (2 * math.pi), None],
        [f"dead time τ (s), from the {result.dead_time_source or '—'}", dead, None if result.step is None else result.step.dead_time_stderr_s],
        ["dead time from the dwells' phases (s)", model.dead_time_s, model.dead_time_stderr_s],
        ["residual RMS of the fit, magnitude (dB)", model.residual_rms_db, None],
        ["residual RMS of the fit, phase (deg)", model.residual_rms_deg, None],
    ]
    s.text(
        "Fit: " + ("magnitude and phase with a dead time (the input start of every dwell is known from the LED)."
                   if model.mode == "complex" else "magnitude only, as in the paper (the dead time cannot be identified from |G|).")
    )
    s.table(["quantity", "value", "standard error"], rows)
    all_warnings = list(result.warnings) + [w for t in summary["tests"] for w in (f"{t['label']}: {x}" for x in t["warnings"])]
    if all_warnings:
        s.warnings(all_warnings)
    else:
        s.html_parts.append('<p class="ok">No warnings.</p>')
    sections.append(s)

    s = ReportSection("Frequency response")
    omega_grid = np.logspace(np.log10(2 * np.pi * fr.frequency_hz.min() / 2), np.log10(2 * np.pi * fr.frequency_hz.max() * 2), 300)
    fig = bode_figure(
        fr.frequency_hz,
        fr.gain,
        fr.gain_stderr,
        fr.phase_deg,
        omega_grid / (2 * np.pi),
        model.magnitude(omega_grid),
        model_phase_deg(model.transfer_function, omega_grid, model.dead_time_s if model.dead_time_s is not None else dead),
        bandwidth_rad_s=model.bandwidth_rad_s,
    )
    s.figure(fig, "Measured gains (error bars: ±1 standard error) and the fitted 2nd-order model; phase measured from the LED's switch, model phase including the step test's dead time.", "Bode plot")
    s.table(
        ["dwell", "f (Hz)", "gain", "gain (dB)", "phase (deg)", "fidelity"],
        [[r["video"], r["frequency_hz"], r["gain"], r["gain_db"], r["phase_deg"], r["fidelity"]] for r in fr.summary()],
    )
    sections.append(s)

    label = _representative_dwell(result)
    fit = result.sine_fits[label]
    track = result.tracks[label]
    s = ReportSection(f"One dwell: {label}")
    fitted = fit.model(track.time_s)
    s.figure(
        dwell_figure(track.time_s, track.angle_rad, track.valid, fitted, fit.window_s, t0_s=fit_t0(result, label), title=f"{label}: measured angle and fitted sine (paper Fig. 7)"),
        f"Fitted at {fit.frequency_hz:.4g} Hz: amplitude {fit.amplitude:.4g} rad, residual RMS {fit.residual_rms:.3g} rad, fidelity {fit.fidelity:.4f}. Shaded: the steady-state window.",
        "Dwell trace",
    )
    sections.append(s)

    if result.step is not None and result.step_label is not None:
        st = result.step
        strack = result.tracks[result.step_label]
        s = ReportSection(f"Step response: {result.step_label}")
        predicted = st.predicted(strack.time_s)
        s.figure(
            step_figure(strack.time_s, strack.angle_rad, strack.valid, predicted, t0_s=strack.t0_s, dead_time_s=st.dead_time_s),
            "Measured step response and the identified model's prediction (dead time fitted on this test).",
            "Step response",
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
        sections.append(s)

    # Fig. 4: a frame with the centroids and the joining line.
    first = result.campaign.tests[0].label
    track = result.tracks[first]
    if track.snapshot_rgb is not None:
        i = track.snapshot_index
        lead, trail = _track_xy_recorded(result, first, i)
        s = ReportSection("Tracking check")
        s.figure(
            overlay_figure(track.snapshot_rgb, lead, trail, float(track.angle_rad[i]), title=f"{first}, frame {i}: detected centroids (paper Fig. 4)"),
            "Squares: the markers' centroids; solid line: the line joining them; dashed: horizontal reference.",
            "Frame with detected centroids",
        )
        from ..markers.error_analysis import angle_error_analysis, plot_angle_error

        analysis = angle_error_analysis(track)
        if analysis.get("separation_px") and math.isfinite(analysis["separation_px"]):
            s.figure(
                plot_angle_error(analysis),
                f"Angle error against sticker separation (paper Fig. 6): at {analysis['separation_px']:.0f} px, "
                f"a 1 px centroid error bounds the angle error at {analysis['worst_case_deg']:.3f}°; the measured "
                f"centroid noise ({analysis['centroid_sigma_px']:.3f} px) gives {analysis['angle_sigma_deg']:.4f}° (1σ).",
                "Error analysis",
            )
        s.table(
            ["video", "frames", "valid", "t0 (s)", "warnings"],
            [[t["video"], t["frames"], t["valid_frames"], t["t0_s"], "; ".join(t["warnings"]) or "—"] for t in summary["tests"]],
        )
        sections.append(s)

    return render_html("servoscope report", f"{result.campaign.path} · servoscope {summary['servoscope_version']}", sections)


def fit_t0(result: "IdentificationResult", label: str) -> float | None:
    test = next(t for t in result.campaign.tests if t.label == label)
    return test.t0_s if test.t0_s is not None else result.tracks[label].t0_s
