"""The blade's structural mode from its heave after the step (issue 18, builds 3-4, in part).

The twin's blade flaps (a 9 Hz mode with 3 % damping driven by the pitch's acceleration,
seen as heave across the chord); the mode is found from the step's ring-down. Oracles:
the renderer's truth (the mode, each frame's heave) and a hand-made ring-down.
"""

from __future__ import annotations

import json
from dataclasses import replace
import math

import numpy as np
import pytest

from servoscope.sysid.modes import fit_damped_mode


def test_a_ringdown_is_found_within_its_interval():
    rng = np.random.default_rng(2)
    t = np.arange(300) * 0.005
    wn, z = 2 * math.pi * 9.0, 0.03
    y = 1.2 * np.exp(-z * wn * t) * np.cos(wn * math.sqrt(1 - z * z) * t + 0.4) + 0.01 * rng.standard_normal(t.size)
    m = fit_damped_mode(t, y, 0.0)
    assert abs(m.frequency_hz - 9.0) < 3 * m.frequency_stderr_hz and abs(m.damping_ratio - z) < 3 * m.damping_ratio_stderr
    # The stated errors include the systematic part (a codec's, measured on the twin).
    assert m.frequency_stderr_hz >= 0.004 * 9.0 * 0.999 and m.damping_ratio_stderr >= 0.08 * m.damping_ratio * 0.999
    assert m.frequency_hz == pytest.approx(9.0, rel=1e-3) and m.damping_ratio == pytest.approx(z, rel=0.05)
    # Noise alone rings nothing.
    assert fit_damped_mode(t, 0.01 * rng.standard_normal(t.size), 0.0, noise=0.01) is None
    # Nor a decay that does not ring (damping ratio 0.88, as a rigid blade's heave drift once read).
    wn = 2 * math.pi * 13.4
    decay = 1.2 * np.exp(-0.88 * wn * t) * np.cos(wn * math.sqrt(1 - 0.88**2) * t) + 0.001 * rng.standard_normal(t.size)
    assert fit_damped_mode(t, decay, 0.0) is None


def test_a_ring_down_beside_a_forced_sine_and_pooling():
    from servoscope.sysid.modes import MODE_SYSTEMATIC, ModeFit, pool_modes

    rng = np.random.default_rng(5)
    t = np.arange(150) * 0.01
    wn, z = 2 * math.pi * 9.0, 0.03
    forced = 0.8 * np.sin(2 * math.pi * 5.24 * t + 0.3)  # larger than the ring-down
    y = 0.3 * np.exp(-z * wn * t) * np.cos(wn * math.sqrt(1 - z * z) * t) + forced + 0.005 * rng.standard_normal(t.size)
    m = fit_damped_mode(t, y, 0.0, forced_hz=5.24, source="dwells")
    assert m.frequency_hz == pytest.approx(9.0, rel=2e-3) and m.damping_ratio == pytest.approx(z, rel=0.1)
    # Without being told of the dwell, its sine is the biggest line: not the mode.
    plain = fit_damped_mode(t, y, 0.0)
    assert plain is None or abs(plain.frequency_hz - 9.0) > 1.0
    # Pooling: the systematic part is common, added once, never averaged away.
    sys_f = MODE_SYSTEMATIC["frequency"] * 9.0
    a = ModeFit(9.0, math.hypot(0.01, sys_f), 0.03, math.hypot(0.001, 0.08 * 0.03), 1.0, "dwells")
    b = ModeFit(9.01, math.hypot(0.01, MODE_SYSTEMATIC["frequency"] * 9.01), 0.031, math.hypot(0.001, 0.08 * 0.031), 0.5, "dwells")
    p = pool_modes([a, b], "dwells")
    assert p.frequency_hz == pytest.approx(9.005, rel=1e-9) and p.source == "dwells" and p.amplitude == 1.0
    assert p.frequency_stderr_hz == pytest.approx(math.hypot(0.01 / math.sqrt(2), sys_f * 9.005 / 9.0), rel=1e-3)
    far = ModeFit(9.3, math.hypot(0.01, MODE_SYSTEMATIC["frequency"] * 9.3), 0.03, a.damping_ratio_stderr, 1.0, "dwells")
    # Two fits 0.3 Hz apart with 0.01 Hz each disagree: the pooled error grows to their scatter (0.3/2).
    assert pool_modes([a, far], "dwells").frequency_stderr_hz == pytest.approx(
        math.hypot(0.15, MODE_SYSTEMATIC["frequency"] * 9.15), rel=0.01)
    assert pool_modes([], "dwells") is None


def test_the_rigid_quick_campaign_at_full_size_rings_nothing(quick_result):
    # 720×576, seed 3: its step's heave once gave a "mode" at 13.4 Hz with damping ratio 0.88.
    assert quick_result.modes == ()
    assert quick_result.heave_response == ()


@pytest.fixture(scope="module")
def flapping(tmp_path_factory):
    """codec → a flapping blade's campaign: rendered once, raw, and its videos encoded again as H.264 (the
    bytes rendering with H.264 writes). The quick preset's dwells and one at 8.7 Hz, 1 s long: far shorter
    than the mode's settling (4/(ζω) = 2.4 s), where a sine fitted to its window reads the transient
    (issue 32)."""
    from servoscope.simulate import reencode_campaign, simulate_campaign

    raw = simulate_campaign(tmp_path_factory.mktemp("flap_raw"), "quick", 0, width=480, height=384, codec="raw",
                            blade_mode_hz=9.0, blade_mode_damping=0.03, step_after_t0_s=1.5,
                            frequencies_hz=(1.0, 2.289, 3.2, 4.2, 5.241, 6.5, 8.7, 12.0))
    return {"raw": raw, "h264": reencode_campaign(raw, tmp_path_factory.mktemp("flap_h264"), codec="h264")}


@pytest.mark.parametrize("codec", ["raw", "h264"])
def test_twin_flapping_blade_mode_from_the_step(flapping, codec, tmp_path):
    from servoscope.angle import heave_px, pivot_motion
    from servoscope.campaign.runner import identify
    from servoscope.simulate import simulate_campaign

    toml = flapping[codec]
    truth = json.loads(toml.with_name("truth.json").read_text())
    assert truth["video"]["codec"] == codec
    assert truth["modes"][0]["frequency_hz"] == 9.0
    res = identify(toml, workers=1)
    # Found from the step alone and from the dwells alone (each dwell rings down after its sine starts),
    # and from the heave's whole traces (issue 32).
    assert [m.source for m in res.modes][:2] == ["step", "dwells"]
    assert {m.source for m in res.modes} <= {"step", "dwells", "heave_traces"}
    hm = res.heave_model
    assert hm.method == "whole traces"
    # The targets for the whole traces: frequency within 0.5 %, damping within 10 % with its
    # interval holding the truth, κ within 3 % (and its interval holding it).
    assert hm.mode.frequency_hz == pytest.approx(9.0, rel=0.005)
    assert hm.mode.damping_ratio == pytest.approx(0.03, rel=0.10)
    assert hm.gain_px_per_rad == pytest.approx(40.0, rel=0.03)
    for name, true in (("gain_px_per_rad", 40.0), ("frequency_hz", 9.0), ("damping_ratio", 0.03)):
        lo, hi = hm.parameters[name].ci95
        assert lo <= true <= hi, (name, lo, hi)
    # The short dwell near the mode: warned, naming it and the record it needs; its heave the model's.
    short = [w for w in res.warnings if "before the blade's" in w]
    assert len(short) == 1 and short[0].startswith("dwell_07_8.70Hz") and "record at least" in short[0], res.warnings
    sources = {r.label: r.source for r in res.heave_response}
    assert sources.pop("dwell_07_8.70Hz") == "model" and set(sources.values()) == {"measured"}
    # The floor is what the seven dwells away from the mode show about the model (issue 32: 0.03–0.1 px by
    # bit rate and picture where the codec predicts frames, a few thousandths of a px on raw frames).
    from servoscope.sysid.heave import HEAVE_FLOOR_MIN_INTRA_PX, HEAVE_FLOOR_MIN_PX

    assert (HEAVE_FLOOR_MIN_PX <= hm.floor_px < 0.1) if codec == "h264" else (
        HEAVE_FLOOR_MIN_INTRA_PX <= hm.floor_px < 0.005)
    s = res.summary()
    for mode, entry in zip(res.modes, s["modes"]):
        # The targets: frequency within 1 %, damping within 15 % (the quick preset's four dwells
        # leave the heave's own fit wide: its interval says so).
        if mode.source != "heave_response":
            assert mode.frequency_hz == pytest.approx(9.0, rel=0.01)
            assert mode.damping_ratio == pytest.approx(0.03, rel=0.15)
        for key, value in (("frequency_hz", 9.0), ("damping_ratio", 0.03)):
            lo, hi = entry["ci95"][key]
            assert lo <= value <= hi, (mode.source, key, lo, hi)
    # One warning per mode, not one per estimate of it.
    assert sum("the blade's mode at" in w for w in res.warnings) <= 1
    # The heave the markers show is the renderer's, to a few hundredths of a pixel.
    step = res.tracks["step"]
    pivot = pivot_motion(step.lead_xy_px, step.trail_xy_px, step.valid)
    h = heave_px(step.lead_xy_px, step.trail_xy_px, step.valid, pivot.centre_xy_px)
    true_h = np.asarray(truth["tests"][-1]["heave_px"])
    err = (h - np.median(h[:10])) - true_h
    assert np.std(true_h) > 0.3 and np.sqrt(np.nanmean(err**2)) < 0.05
    # Each dwell's heave at its input frequency (issue 18, build 2) against the renderer's, fitted alike:
    # within 3 stated standard errors where it moved more than 0.1 px; on raw footage, where it moved
    # 0.3 px or more, within the issue's 2 % and 2°, and stated so (H.264's 0.05 px floor states 10 %).
    from servoscope.campaign.result import input_start
    from servoscope.sysid.heave import dwell_heave

    rows = {r["video"]: r for r in s["heave_response"]}
    assert sorted(rows) == sorted(res.sine_fits)
    checked = on_target = 0
    servo = truth["model"]
    for test, tt in zip(res.campaign.tests, truth["tests"]):
        if test.kind != "sine":
            continue
        # Every row against the blade's steady heave (the renderer's mode driven by its servo): within 3
        # stated errors, the model's row included.
        w = 2 * np.pi * test.frequency_hz
        pitch = servo["gain"] * servo["natural_frequency_rad_s"] ** 2 / (
            servo["natural_frequency_rad_s"] ** 2 - w**2 + 2j * servo["damping_ratio"] * servo["natural_frequency_rad_s"] * w)
        steady = abs(40.0 * w**2 / ((2 * np.pi * 9.0) ** 2 - w**2 + 2j * 0.03 * 2 * np.pi * 9.0 * w) * pitch)
        assert tt["heave_steady"]["gain_px_per_unit"] == pytest.approx(steady, rel=1e-9)  # truth states it too
        assert abs(rows[test.label]["gain"] - steady) < 3 * rows[test.label]["gain_stderr"], (test.label, steady)
        if rows[test.label]["amplitude_px"] < 0.1 or rows[test.label]["source"] != "measured":
            continue
        track = res.tracks[test.label]
        ref = dwell_heave(np.asarray(tt["time_s"]), np.asarray(tt["heave_px"]), test.frequency_hz,
                          input_start(test, track), test.amplitude, res.sine_fits[test.label].window_s,
                          mode=(res.modes[0].frequency_hz, res.modes[0].damping_ratio))
        # The rows are the blade's heave: the camera's averaging over its exposure undone, as the pitch's is.
        ref = replace(ref, gain=ref.gain / np.sinc(test.frequency_hz * truth["video"]["exposure_s"]))
        row = rows[test.label]
        assert abs(row["gain"] - ref.gain) < 3 * row["gain_stderr"], (test.label, row, ref)
        assert abs(row["phase_deg"] - ref.phase_deg) < 3 * row["phase_stderr_deg"], (test.label, row, ref)
        if codec == "raw" and row["amplitude_px"] > 0.3:
            assert abs(row["gain"] / ref.gain - 1) < 0.02 and abs(row["phase_deg"] - ref.phase_deg) < 2.0
            assert row["gain_stderr"] / row["gain"] < 0.02 and row["phase_stderr_deg"] < 2.0
            on_target += 1
        checked += 1
    assert checked >= 2 and (on_target >= 2 or codec != "raw")
    from servoscope.report.build import build_report

    html = build_report(res)
    assert "heave gain (px per input unit)" in html and "Heave against frequency" in html
    # The pitch identification is not disturbed by the flapping: the heave moves both stickers alike.
    for name in ("gain", "natural_frequency_rad_s"):
        assert s["model"][name] == pytest.approx(truth["model"][name], rel=0.01)
    if codec == "h264":
        return
    # A rigid blade rings nothing.
    rigid = identify(simulate_campaign(tmp_path / "rigid", "quick", 0, width=480, height=384, codec="raw",
                                       step_after_t0_s=1.5), workers=1)
    assert rigid.modes == () and "modes" not in rigid.summary()
    assert rigid.heave_response == () and "heave_response" not in rigid.summary()


def test_a_mode_shape_across_markers():
    """Each marker's share of a ring-down, and its phase against the first's: put in by hand."""
    from servoscope.sysid.modes import ModeFit, ModeShape, fit_mode_shape

    rng = np.random.default_rng(7)
    t = np.arange(400) * 0.005
    wn, z = 2 * math.pi * 9.0, 0.03
    wd = wn * math.sqrt(1 - z * z)
    ring = np.exp(-z * wn * t)
    amps, phases = [1.2, 1.2, 0.6, -0.45], [0.3, 0.3, 0.3, 0.3]  # the last moves against the others
    y = np.column_stack([a * ring * np.cos(wd * t + p) + 5.0 + 0.01 * rng.standard_normal(t.size)
                         for a, p in zip(amps, phases)])
    mode = ModeFit(9.0, 0.01, z, 0.001, 1.2, "step")
    shape = fit_mode_shape(t, y, 0.0, mode, ("lead", "trail", "extra1", "extra2"), ("#a", "#b", "#c", "#d"),
                           systematic_px=0.05)
    assert shape.relative() == pytest.approx([1.0, 1.0, 0.5, -0.375], abs=0.01)
    assert shape.phase_deg[3] == pytest.approx(180.0, abs=1.0) or shape.phase_deg[3] == pytest.approx(-180.0, abs=1.0)
    for a, se in zip(shape.amplitude_px, shape.amplitude_stderr_px):
        assert se >= 0.05  # the systematic part is in
    for a_true, a in zip(amps, shape.amplitude_px):
        assert abs(a - abs(a_true)) < 0.02
    assert ModeShape.from_summary(shape.summary()) == shape
    assert ModeFit.from_summary({**ModeFit(9.0, 0.01, z, 0.001, 1.2, "step", shape).summary()}).shape == shape


def test_the_flapping_response_fitted_as_a_mode():
    """heave/pitch = κω²/(ωm² − ω² + 2jζωmω) with known κ, fm, ζ: recovered within the stated intervals."""
    from servoscope.sysid.heave import HeaveModel, HeaveRow, fit_heave_model

    rng = np.random.default_rng(3)
    kappa, fm, zeta = 40.0, 9.0, 0.03
    rows, pitch = [], {}
    for k, f in enumerate(np.geomspace(1.0, 20.0, 14)):
        w, wm = 2 * math.pi * f, 2 * math.pi * fm
        ratio = kappa * w**2 / (wm**2 - w**2 + 2j * zeta * wm * w)
        g = 0.23 / abs(1 + 1j * w / 37.0)  # a pitch response, its phase any
        ph = -math.atan(w / 37.0) - w * 0.085
        h = ratio * g * np.exp(1j * ph)
        noise = 0.02 * abs(h) * (rng.standard_normal() + 1j * rng.standard_normal()) / math.sqrt(2)
        h = h + noise
        rows.append(HeaveRow(f"d{k}", f, abs(h), 0.02 * abs(h), math.degrees(np.angle(h)), math.degrees(0.02), abs(h)))
        pitch[f"d{k}"] = (g, 1e-5, ph, 1e-4)
    model = fit_heave_model(rows, pitch)
    assert model is not None and model.n_dwells == 14
    assert abs(model.gain_px_per_rad - kappa) < 3 * model.gain_stderr_px_per_rad
    assert abs(model.mode.frequency_hz - fm) < 3 * model.mode.frequency_stderr_hz
    assert abs(model.mode.damping_ratio - zeta) < 3 * model.mode.damping_ratio_stderr
    assert model.mode.frequency_hz == pytest.approx(fm, rel=0.01) and model.mode.source == "heave_response"
    back = HeaveModel.from_summary(model.summary())
    assert back.ratio(np.array([5.0])) == pytest.approx(model.ratio(np.array([5.0])))
    # Two dwells cannot tell three parameters.
    assert fit_heave_model(rows[:2], pitch) is None


def test_two_ring_downs_are_told_apart():
    """A 9 Hz and a 21 Hz ring-down in one signal: both found, strongest first; one alone stays one."""
    from servoscope.sysid.modes import fit_damped_mode, fit_damped_modes

    rng = np.random.default_rng(11)
    t = np.arange(200) * 0.01

    def ring(a, f, z, phase):
        wn = 2 * math.pi * f
        return a * np.exp(-z * wn * t) * np.cos(wn * math.sqrt(1 - z * z) * t + phase)

    y = ring(1.2, 9.0, 0.03, 0.3) + ring(0.4, 21.0, 0.02, 1.0) + 3.0 + 0.01 * rng.standard_normal(t.size)
    found = fit_damped_modes(t, y, 0.0, noise=0.01)
    assert [round(m.frequency_hz) for m in found] == [9, 21]
    for m, (f, z) in zip(found, ((9.0, 0.03), (21.0, 0.02))):
        assert abs(m.frequency_hz - f) < 3 * m.frequency_stderr_hz and abs(m.damping_ratio - z) < 3 * m.damping_ratio_stderr
    # Beside a forced sine (a dwell), too.
    forced = fit_damped_modes(t, y + 0.8 * np.sin(2 * math.pi * 5.24 * t), 0.0, noise=0.01, forced_hz=5.24)
    assert [round(m.frequency_hz) for m in forced] == [9, 21]
    # One mode and noise: one mode, the same as fitted alone.
    one = ring(1.2, 9.0, 0.03, 0.3) + 0.01 * rng.standard_normal(t.size)
    assert fit_damped_modes(t, one, 0.0, noise=0.01) == [fit_damped_mode(t, one, 0.0, noise=0.01)]
