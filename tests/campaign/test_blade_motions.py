"""More markers along the blade: bending, mode shapes, the flapping response (issue 18, builds 1, 2, 4, 5).

The twin renders extra stickers between the lead and trail ones and a 9 Hz mode that bends
the blade (a sticker halfway moves half the heave, one a quarter of the way 62.5 %); truth
lists each sticker's share. Oracles: the renderer's truth (each frame's heave, each
sticker's share) and the two-marker identification of the same footage.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from servoscope.errors import ServoscopeError

EXTRAS = (("#1f77b4", 0.5), ("#9467bd", 0.25))


def _render(tmp_path, **kw):
    from servoscope.simulate import simulate_campaign

    args = dict(width=480, height=384, codec="raw", blade_mode_hz=9.0, blade_mode_damping=0.03, blade_mode_bend=0.5,
                step_after_t0_s=1.5, extra_stickers=EXTRAS)
    args.update(kw)
    toml = simulate_campaign(tmp_path, "quick", 0, **args)
    return toml, json.loads((tmp_path / "truth.json").read_text())


def test_extra_markers_bend_as_rendered_and_leave_the_pitch_alone(tmp_path):
    """Square stickers under H.264 (not the defaults the tracker was tuned on): each marker's bending is the
    renderer's, and the pitch is the two-marker pitch bit for bit."""
    from servoscope.camera import CameraModel
    from servoscope.pipeline import TrackerSettings, track_video

    _, truth = _render(tmp_path, frequencies_hz=(), codec="h264", sticker_shape="square")
    test = truth["tests"][0]
    settings = TrackerSettings(camera=CameraModel.load(tmp_path / "camera.json"),
                               exposure_s=truth["video"]["exposure_s"])
    two = track_video(tmp_path / test["video"], settings)
    many = track_video(tmp_path / test["video"], TrackerSettings(**{**settings.__dict__,
                                                                     "extra": tuple(c for c, _ in EXTRAS)}))
    assert many.n_valid == two.n_valid > 0.95 * two.n_frames
    v = many.valid
    assert np.array_equal(many.angle_rad[v], two.angle_rad[v])
    assert np.array_equal(many.angle_sigma_rad[v], two.angle_sigma_rad[v])
    heave = np.asarray(test["heave_px"])
    shares = truth["modes"][0]["shape"]["extra"]
    assert shares == pytest.approx([0.5, 0.625])
    for k, share in enumerate(shares):
        b = many.bending_px[v, 2 + k]
        expected = (share - 1.0) * heave[v]
        err = (b - np.median(b)) - (expected - np.median(expected))
        assert np.std(expected) > 0.2 and np.sqrt(np.mean(err**2)) < 0.05, (k, np.sqrt(np.mean(err**2)))
    assert np.allclose(many.bending_px[v, :2], 0.0, atol=1e-9)
    # The table carries every marker's columns, and reads back.
    from servoscope.markers import Track

    many.to_csv(tmp_path / "t.csv")
    back = Track.from_csv(tmp_path / "t.csv")
    assert np.array_equal(back.bending_px[v], many.bending_px[v]) and back.extra_xy_px.shape == (many.n_frames, 2, 2)


def test_a_campaign_with_extra_markers_end_to_end(tmp_path):
    """Two modes: the 9 Hz one bending the middle less, a 21 Hz one (2 % damping) bending it more."""
    from servoscope.campaign import IdentificationResult
    from servoscope.campaign.result import input_start
    from servoscope.campaign.runner import identify
    from servoscope.report.build import build_report
    from servoscope.sysid.heave import dwell_heave

    toml, truth = _render(tmp_path, blade_mode2=(21.0, 0.02, 40.0, -1.0))
    assert 'extra = ["#1f77b4", "#9467bd"]' in toml.read_text()
    res = identify(toml, workers=1)
    s = res.summary()
    assert s["extra_markers"] == ["#1f77b4", "#9467bd"]
    # Both modes from the step alone (strongest first), the 1 % and 15 %, intervals holding the truth.
    step_modes = [m for m in res.modes if m.source == "step"]
    assert [round(m.frequency_hz) for m in step_modes] == [9, 21]
    true_modes = truth["modes"]
    for mode, true in zip(step_modes, true_modes):
        assert mode.frequency_hz == pytest.approx(true["frequency_hz"], rel=0.01)
        assert mode.damping_ratio == pytest.approx(true["damping_ratio"], rel=0.15)
        assert abs(mode.frequency_hz - true["frequency_hz"]) < 3 * mode.frequency_stderr_hz
        assert abs(mode.damping_ratio - true["damping_ratio"]) < 3 * mode.damping_ratio_stderr
        # Which markers move, and how: each one's share of the mode against the renderer's, within 3 σ.
        shape = mode.shape
        assert shape.markers == ("lead", "trail", "extra1", "extra2")
        assert shape.colours[2:] == ("#1f77b4", "#9467bd")
        rel = shape.relative()
        true_rel = [1.0, 1.0, *true["shape"]["extra"]]
        for k in (2, 3):
            se = abs(rel[k]) * np.hypot(shape.amplitude_stderr_px[k] / shape.amplitude_px[k],
                                        shape.amplitude_stderr_px[0] / shape.amplitude_px[0])
            assert abs(rel[k] - true_rel[k]) < 3 * se and abs(rel[k] / true_rel[k] - 1) < 0.05, (k, rel[k], se)
            assert abs(shape.phase_deg[k]) < 3 * shape.phase_stderr_deg[k] + 1e-9
    # Each marker's bending per dwell against the renderer's, fitted alike, within 3 stated errors.
    rows = s["bending_response"]
    assert {(r["marker"], r["video"]) for r in rows} == {(m, t) for m in ("extra1", "extra2") for t in res.sine_fits}
    checked = 0
    for r in rows:
        k = int(r["marker"][-1]) - 1
        tt = next(t for t in truth["tests"] if t["video"].startswith(r["video"]))
        test = next(t for t in res.campaign.tests if t.label == r["video"])
        # The marker's bending: each mode's heave times its share there less the chord line's.
        bend = sum((m["shape"]["extra"][k] - 1.0) * np.asarray(q) for m, q in zip(true_modes, tt["mode_heave_px"]))
        ref = dwell_heave(np.asarray(tt["time_s"]), bend, test.frequency_hz, input_start(test, res.tracks[test.label]),
                          test.amplitude, res.sine_fits[test.label].window_s,
                          mode=[(m.frequency_hz, m.damping_ratio) for m in step_modes])
        assert abs(r["gain"] - ref.gain) < 3 * r["gain_stderr"], (r, ref)
        if r["amplitude_px"] > 0.1:
            assert abs(r["phase_deg"] - ref.phase_deg) < 3 * r["phase_stderr_deg"], (r, ref)
            checked += 1
    assert checked >= 2
    # The flapping response fitted as modes to the heave's whole traces (issue 32): the step's ring-down and
    # the dwells tell both modes (the four dwells' ratios alone could not tell the second's frequency and
    # damping, once held at the step's); every interval holds the renderer's.
    hm = s["heave_model"]
    assert hm["method"] == "whole traces"
    for term, (f, zeta) in zip(hm["modes"], ((9.0, 0.03), (21.0, 0.02))):
        assert not term.get("held", False)
        for key, value in (("frequency_hz", f), ("damping_ratio", zeta)):
            assert abs(term[key] - value) < 3 * term["stderr"][key], (key, term)
        assert abs(term["gain_px_per_rad"] - 40.0) < 3 * term["gain_stderr_px_per_rad"], term
    # A step cut short after the servo settles cannot show the ring-down: said, with how long to record.
    from dataclasses import replace

    from servoscope.campaign.blade import axis_of, blade_modes, step_ringdown_warning

    step_track = res.tracks["step"]
    assert step_ringdown_warning(res.step, step_track, res.model, "step", res.modes) is None
    cut = replace(step_track, valid=step_track.valid & (step_track.angle_time_s < res.step.t0_s + 0.6))
    pivot = axis_of(res.tracks, res.sine_fits, step_track)
    assert len(blade_modes(res.step, step_track, res.model, pivot)) == 2
    assert blade_modes(res.step, cut, res.model, pivot) == []
    others = [m for m in res.modes if m.source != "step"]
    why = step_ringdown_warning(res.step, cut, res.model, "step", others)
    assert why is not None and "too short to fit its ring-down; record at least" in why
    # The report's blade motions: the mode shape's table and frame.
    html = build_report(res)
    assert "Blade motions" in html and "Blade motions frame" in html and "relative to the lead" in html
    assert "bending gain (px per input unit)" in html and "Bending against frequency" in html
    assert html.count("marker (mode at") == 2  # a shape table for each of the step's modes
    # Saved and read back to the byte.
    res.write(tmp_path / "out")
    back = IdentificationResult.load(tmp_path / "out")
    assert back.summary() == s
    # The same footage with two markers: every pitch number as with four.
    two = toml.read_text().replace('extra = ["#1f77b4", "#9467bd"]\n', "")
    (tmp_path / "two.toml").write_text(two)
    res2 = identify(tmp_path / "two.toml", workers=1)
    s2 = res2.summary()
    assert s2["frequency_response"] == s["frequency_response"] and s2["model"] == s["model"]
    assert s2["heave_response"] == s["heave_response"] and "bending_response" not in s2
    assert [m for m in s2["modes"] if m["source"] != "step"] == [m for m in s["modes"] if m["source"] != "step"]


def test_extra_markers_bad_input(tmp_path):
    from servoscope.campaign.manifest import load_campaign
    from servoscope.pipeline import TrackerSettings, track_video

    toml, truth = _render(tmp_path, frequencies_hz=(), extra_stickers=EXTRAS[:1], step_after_t0_s=0.4)
    video = tmp_path / truth["tests"][0]["video"]
    # A colour that matches nothing in the picture: named, with the closest blobs.
    with pytest.raises(ServoscopeError, match=r"extra marker 1 \(#9467bd\)'s colour #9467bd matches nothing"):
        track_video(video, TrackerSettings(extra=("#9467bd",)))
    # Another marker's colour, or one that finds the lead's sticker.
    with pytest.raises(ServoscopeError, match="same colour as the lead marker"):
        track_video(video, TrackerSettings(extra=("#d62728",)))
    with pytest.raises(ServoscopeError, match="same blob|found on the lead marker"):
        track_video(video, TrackerSettings(extra=("#c83030",)))
    with pytest.raises(ServoscopeError, match="told by colour"):
        track_video(video, TrackerSettings(extra=("bright",)))
    # The manifest says which entry is wrong.
    text = toml.read_text()
    for bad, why in (('extra = ["#1f77b4", "#1f77b4"]', r"markers.extra\[1\].*colour of its own"),
                     ('extra = ["#2ca02c"]', r"markers.extra\[0\].*same colour as the trail"),
                     ('extra = "#1f77b4"', "markers.extra: the colours"),
                     ('extra = ["nonsense-colour"]', r"markers.extra\[0\]")):
        (tmp_path / "bad.toml").write_text(text.replace('extra = ["#1f77b4"]', bad))
        with pytest.raises(ServoscopeError, match=why):
            load_campaign(tmp_path / "bad.toml")


def test_a_rolling_shutter_is_said_beside_the_bending(tmp_path):
    """Markers on other rows are seen at other times under a rolling shutter: the track says by how much."""
    from servoscope.pipeline import TrackerSettings, track_video
    from servoscope.simulate import simulate_campaign

    simulate_campaign(tmp_path, "quick", 0, codec="raw", width=320, height=256, fps=50, exposure_s=0.02,
                      readout_s=0.015, frequencies_hz=(), step_after_t0_s=0.3, extra_stickers=EXTRAS[:1])
    truth = json.loads((tmp_path / "truth.json").read_text())
    video = tmp_path / truth["tests"][0]["video"]
    tr = track_video(video, TrackerSettings(readout_s=0.015, extra=("#1f77b4",)))
    said = [w for w in tr.warnings if w.startswith("rolling shutter")]
    assert tr.n_valid == tr.n_frames and len(said) == 1
    # Its numbers: the rows apart and the time apart, 15 ms over 256 rows.
    rows = float(said[0].split(" rows apart")[0].rsplit(" ", 1)[1])
    ms = float(said[0].split(" ms apart")[0].rsplit(" ", 1)[1])
    assert ms == pytest.approx(15.0 * rows / 256, rel=0.05)
    assert not any(w.startswith("rolling shutter") for w in track_video(video, TrackerSettings(readout_s=0.015)).warnings)


def test_command_line_extra_markers(tmp_path):
    """`servoscope track --extra`: the bending line and columns; a colour of another marker's: one line, exit 2."""
    from support import run_cli  # the command's entry point in this process, as a child ran it

    _, truth = _render(tmp_path, frequencies_hz=(), extra_stickers=EXTRAS[:1], step_after_t0_s=0.4)
    video = tmp_path / truth["tests"][0]["video"]
    run = ["track", str(video)]
    ok = run_cli(*run, "--extra", "#1f77b4", "--out", str(tmp_path / "t.csv"))
    assert ok.returncode == 0, ok.stderr
    assert "bending across the lead–trail line, RMS: extra1 (#1f77b4)" in ok.stdout
    header = (tmp_path / "t.csv").read_text().splitlines()[0].split(",")
    assert {"extra1_x_px", "extra1_y_px", "extra1_bending_px", "lead_bending_px"} <= set(header)
    bad = run_cli(*run, "--extra", "#d62728", "--out", str(tmp_path / "bad.csv"))
    assert bad.returncode == 2 and not (tmp_path / "bad.csv").exists()
    assert bad.stderr.strip().splitlines() == [
        "servoscope: error: extra marker 1: #d62728 has the same colour as the lead marker: give each marker a "
        "colour of its own"]
