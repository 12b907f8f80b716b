"""What ``servoscope identify``, ``demo``, ``markers`` and ``track`` print: the model, the time-domain models,
the blobs, a track's counts.

Part of the command line (:mod:`servoscope.cli`), kept apart so that the commands stay a
thin layer over the API.
"""

from __future__ import annotations

import math

from pathlib import Path

import click

__all__ = ["fmt", "print_blade_motions", "print_candidates", "print_model", "print_servo_model",
           "print_track_counts"]


def print_model(result, truth: dict | None = None) -> None:
    """The identified model as a table (against the truth when given), then the warnings on stderr."""
    from rich.console import Console
    from rich.table import Table

    from .campaign.headline import SOURCE_KEYS
    from .numbers import format_interval, format_with_uncertainty

    head = result.headline
    title = head.equation if head.domain == "frequency domain" else f"{head.equation} ({head.domain}, selected)"
    table = Table(title=title)
    table.add_column("quantity")
    table.add_column("identified", justify="right")
    table.add_column("± std. error", justify="right")
    table.add_column("95 % interval", justify="right")
    if truth is not None:
        table.add_column("truth", justify="right")
        table.add_column("error", justify="right")
    truth_model = (truth or {}).get("model", {})
    # The headline's own cells (Parameter.cells): the numbers the report and the notebook show.
    for (name, p), cells in zip(head.parameters.items(), head.rows()):
        true = truth_model.get(name)
        if truth is not None:
            diff = "—" if true is None else (f"{1e3 * (p.value - true):+.2f} ms" if name == "dead_time_s"
                                             else f"{100 * (p.value - true) / true:+.2f} %")
            cells = cells + [fmt(true), diff]
        table.add_row(*cells)
    rows = [("−3 dB bandwidth (rad/s)", result.bandwidth_rad_s, None, None, (truth or {}).get("bandwidth_rad_s"))]
    true_dead = truth_model.get("dead_time_s")
    short = {"step": "step test", "phase": "frequency response's phases"}
    chosen = SOURCE_KEYS.get(result.dead_time_source or "")
    for key, e in result.dead_time_estimates.items():
        if e is not None and key != chosen:
            rows.append((f"  other dead-time estimate (ms): {short[key]}", 1e3 * e.value_s, 1e3 * e.stderr_s,
                         [1e3 * v for v in e.ci95_s], None if true_dead is None else 1e3 * true_dead))
    for name, value, err, ci, true in rows:
        value_text, err_text = format_with_uncertainty(value, err)
        if err is None:
            value_text = fmt(value)
        cells = [name, value_text, err_text if err is not None else "—",
                 "—" if ci is None else format_interval(ci[0], ci[1], err)]
        if truth is not None:
            if value is None or true is None:
                diff = "—"
            elif "(ms)" in name:
                diff = f"{value - true:+.2f} ms"
            else:
                diff = f"{100 * (value - true) / true:+.2f} %"
            cells += [fmt(true), diff]
        table.add_row(*cells)
    Console(highlight=False, width=112).print(table)
    if result.servo_model is not None:
        print_servo_model(result, truth)
    if result.modes:
        print_blade_motions(result, truth)
    if result.plane is not None:
        # Which plane the angles are the plane's of: a board photo's, or the stickers' own estimate.
        plane = result.plane
        view = plane.get("view_angle_deg")
        click.echo(f"angles measured in the blade's plane: {Path(str(plane.get('source'))).name}"
                   + ("" if view is None else f" (the camera {view:.1f}° off square)"))
    # Warnings to stderr, as `track` does: the table on stdout stays what a script parses.
    for w in result.warnings:
        click.echo(f"warning: {w}", err=True)


def print_servo_model(result, truth: dict | None) -> None:
    """The time-domain models: each candidate's BIC, J and step fit; the selected one's parameters."""
    from rich.console import Console
    from rich.table import Table

    sel = result.servo_model.selected
    table = Table(title=f"time-domain models (fitted to the whole traces): {sel.structure} selected")
    for col in ("structure", "BIC", "CIFER J (dwells)", "step fit"):
        table.add_column(col, justify="right")
    for c in result.servo_model.candidates:
        table.add_row(c.structure + (" ✓" if c is sel else ""), f"{c.bic:.1f}", f"{c.J:.3g}",
                      "—" if c.step_fit_percent is None else f"{c.step_fit_percent:.2f} %")
    params = Table(title=f"{sel.structure} model")
    for col in ("parameter", "identified", "± std. error", "95 % interval", *(("truth",) if truth else ())):
        params.add_column(col, justify="right")
    true = (truth or {}).get("model", {})
    for name, p in sel.parameters.items():
        params.add_row(name + p.held_text(), *p.cells(), *((fmt(true.get(name)),) if truth else ()))
    console = Console(highlight=False, width=112)
    console.print(table)
    console.print(params)
    console.print(f"cross-validation: {result.servo_model.cross_validation.get('verdict')}")


def print_blade_motions(result, truth: dict | None) -> None:
    """The blade's modes (each source), the first shape across the markers, the flapping response's fit."""
    from rich.console import Console
    from rich.table import Table

    from .numbers import format_interval, format_with_uncertainty
    from .sysid.modes import MODE_SOURCES

    true = ((truth or {}).get("modes") or [{}])[0]
    table = Table(title="the blade's modes (its heave across the chord)")
    for col in ("from", "frequency (Hz)", "95 % interval", "damping ratio", "95 % interval",
                *(("truth",) if true else ())):
        table.add_column(col, justify="right")
    for m in result.modes:
        f, fe = format_with_uncertainty(m.frequency_hz, m.frequency_stderr_hz)
        z, ze = format_with_uncertainty(m.damping_ratio, m.damping_ratio_stderr)
        table.add_row(MODE_SOURCES.get(m.source, m.source), f"{f} ± {fe}",
                      format_interval(*m.ci95["frequency_hz"], m.frequency_stderr_hz),
                      f"{z} ± {ze}",
                      format_interval(*m.ci95["damping_ratio"], m.damping_ratio_stderr),
                      *((f"{fmt(true.get('frequency_hz'))} Hz, {fmt(true.get('damping_ratio'))}",) if true else ()))
    console = Console(highlight=False, width=112)
    console.print(table)
    for shaped in (m for m in result.modes if m.shape is not None):
        sh = shaped.shape
        shape = Table(title=f"its shape at {shaped.frequency_hz:.4g} Hz: each marker's ring-down across the chord line")
        for col in ("marker", "colour", "amplitude (px)", "relative to the lead", "phase (deg)"):
            shape.add_column(col, justify="right")
        for m, c, a, sa, r, p, sp in zip(sh.markers, sh.colours, sh.amplitude_px, sh.amplitude_stderr_px,
                                         sh.relative(), sh.phase_deg, sh.phase_stderr_deg):
            shape.add_row(m, c, " ± ".join(format_with_uncertainty(a, sa)), f"{r:.3f}",
                          " ± ".join(format_with_uncertainty(p, sp)))
        console.print(shape)
    if result.heave_model is not None:
        hm = result.heave_model
        kappas = ", ".join(f"{' ± '.join(format_with_uncertainty(k, kse))} px/rad at {m.frequency_hz:.4g} Hz"
                           for k, kse, m in zip(hm.gains_px_per_rad, hm.gain_stderrs_px_per_rad, hm.modes))
        over = (f"the whole traces ({hm.n_dwells} dwells and the other tests)" if hm.method == "whole traces"
                else f"{hm.n_dwells} dwells")
        console.print(f"flapping response fitted over {over}: heave/pitch = Σ κ·ω²/(ωm² − ω² + "
                      f"2jζωm·ω), κ = {kappas}")


def fmt(value) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "—"
    return f"{value:.4g}"


def print_candidates(title: str, rgb) -> list:
    """``servoscope markers``' table of a frame's blobs, then how to pin one; returns the candidates.

    Coloured blobs, or on a frame without colour (monochrome footage) the bright
    blobs, which ``--lead bright@x,y`` pins.
    """
    from rich.console import Console
    from rich.table import Table

    from .markers.candidates import find_brightness_candidates, find_candidates, is_gray

    gray = is_gray(rgb)
    found = find_brightness_candidates(rgb) if gray else find_candidates(rgb)
    table = Table(title=f"{title}: {'bright' if gray else 'coloured'} blobs")
    for name in ("#", "colour", "hue (deg)", "x (px)", "y (px)", "area (px)", "solidity", "at border"):
        table.add_column(name, justify="right")
    for c in found:
        table.add_row(str(c.number), c.colour_hex, "—" if math.isnan(c.hue_deg) else f"{c.hue_deg:.0f}",
                      f"{c.x_px:.1f}", f"{c.y_px:.1f}", str(c.area_px), f"{c.solidity:.2f}",
                      "yes" if c.touches_border else "")
    Console(highlight=False).print(table)
    if not found:
        click.echo("no bright blob found" if gray else "no saturated blob found", err=True)
    elif gray:
        click.echo("monochrome footage: markers are told by brightness; stickers are solid (>= 0.9), not at the "
                   "border, and of like size; to choose one yourself, pin it with x, y from this table: track --lead "
                   "bright@x,y, or in campaign.toml lead = {brightness = \"bright\", near = [x, y]}")
    else:
        # Stickers are solid (≥ 0.9), whole (not at the border) and alike in size; to make sure, pin them.
        click.echo("stickers are solid (>= 0.9), not at the border, and of like size; to choose one yourself, pin it "
                   "with its colour and x, y from this table: track --lead '#rrggbb@x,y', or in campaign.toml "
                   "lead = {colour = \"#rrggbb\", near = [x, y]}")
    return found


def print_track_counts(name: str, result, out_csv: Path) -> None:
    """``servoscope track``'s first lines: frames, valid ones, separation, angle noise, t0, the CSV; the bending."""
    s = result.summary()
    t0 = "none" if result.t0_s is None else f"{result.t0_s:.4f} s ± {1e3 * (result.t0_uncertainty_s or 0.0):.2f} ms"
    if result.t0_earliest_s is not None and result.led_partial_frames == 0:
        t0 += f" (no frame partly lit: between {result.t0_earliest_s:.4f} and {result.t0_latest_s:.4f} s)"
    sep = "n/a" if s["mean_separation_px"] is None else f"{s['mean_separation_px']:.1f} px"
    noise = "n/a" if s["angle_noise_rad"] is None else f"{math.degrees(s['angle_noise_rad']):.4f}° from pixel noise"
    if s.get("angle_noise_measured_rad") is not None:
        noise = f"{math.degrees(s['angle_noise_measured_rad']):.4f}° measured ({noise})"
    if s.get("camera_shake_px"):
        # The measured noise then comes from the markers' separation, which shake leaves alone.
        noise += f", camera shake {s['camera_shake_px']:.2f} px RMS"
    click.echo(f"{name}: {result.n_frames} frames, {result.n_valid} valid ({100 * s['valid_fraction']:.1f} %), "
               f"sticker separation {sep}, angle noise {noise}, LED switch t0 = {t0}; wrote {out_csv}")
    if result.bending_px is not None and result.n_valid:
        # Each extra marker's bending: how far it moved across the lead–trail line (its columns in the CSV).
        import numpy as np

        spread = np.nanstd(result.bending_px[result.valid, 2:], axis=0)
        click.echo(f"{name}: bending across the lead–trail line, RMS: " + ", ".join(
            f"extra{k + 1} ({c}) {v:.3f} px" for k, (c, v) in enumerate(zip(result.extra_colours, spread))))
