"""Issue 14: t0 and the dead time are stated no more precisely than the footage dates them.

The LED's switch is dated by the frame it lit partly; with a shutter shorter
than the frame interval it usually lights none, and then t0 is only known to
lie in the unexposed gap. Checked against switch times drawn at random (unit
level) and against the digital twin's truth with short shutters, given and
not given (campaign level).
"""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest

from servoscope.camera.exposure import estimate_exposure
from servoscope.markers.led_timing import exposure_middle_offset_s, led_switch_time


def _levels(t0_s, time_s, exposure_s, noise, rng):
    lit = np.clip((t0_s - (time_s - exposure_s / 2.0)) / exposure_s, 0.0, 1.0)
    return lit + noise * rng.standard_normal(time_s.size)


@pytest.mark.parametrize("fraction", [0.05, 0.25, 0.5, 0.9, 1.0])
def test_unknown_exposure_interval_always_holds_the_switch(fraction):
    """Exposure not given: whatever the shutter, the stated interval contains t0 and the stated σ is honest."""
    rng = np.random.default_rng(11)
    period = 1 / 240
    time_s = np.arange(80) * period
    inside, z = [], []
    for _ in range(300):
        t0 = period * rng.integers(20, 60) + rng.uniform(0.0, period)
        sw, why = led_switch_time(time_s, _levels(t0, time_s, fraction * period, 0.005, rng), None)
        assert why is None
        inside.append(sw.earliest_s - 1e-9 <= t0 <= sw.latest_s + 1e-9)
        z.append((sw.t0_s - t0) / sw.stderr_s)
    z = np.abs(z)
    # Uniform intervals: |z| ≤ √3 when t0 is inside; a partly lit frame's dated t0 is Gaussian.
    assert np.mean(inside) >= 0.99
    assert np.mean(z > 3.0) < 0.01
    # And not absurdly wide: at most the frame interval.
    sw, _ = led_switch_time(time_s, _levels(0.1003, time_s, fraction * period, 0.0, rng), None)
    assert sw.latest_s - sw.earliest_s <= period * 1.0001


def test_a_given_short_shutter_dates_t0_to_its_gap():
    period, exposure = 1 / 200, 0.0001
    time_s = np.arange(60) * period
    t0 = 0.1 + 0.4 * period  # between exposures (each 0.1 ms around a frame time)
    sw, _ = led_switch_time(time_s, _levels(t0, time_s, exposure, 0.0, np.random.default_rng(0)), exposure)
    gap = period - exposure
    assert sw.how == "gap" and sw.partial_frames == 0
    assert sw.earliest_s <= t0 <= sw.latest_s
    # The figure: gap/√12 (1.4 ms at 200 frames/s), not the 0.02 ms once stated.
    assert sw.stderr_s == pytest.approx(gap / math.sqrt(12), rel=0.02)


def test_timestamp_convention_moves_times_to_the_exposure_middle():
    assert exposure_middle_offset_s("middle", 0.004) == 0.0
    assert exposure_middle_offset_s("start", 0.004) == pytest.approx(0.002)
    assert exposure_middle_offset_s("end", 0.004) == pytest.approx(-0.002)
    assert exposure_middle_offset_s("start", None) == 0.0
    with pytest.raises(ValueError):
        exposure_middle_offset_s("centre", 0.004)


@pytest.mark.parametrize("fraction", [0.1, 0.25, 0.6])
def test_exposure_from_led_switches_interval_covers_truth(fraction):
    """The share of switches that lit a frame partly: its 95 % interval holds the shutter in ≥ 93 % of campaigns."""
    rng = np.random.default_rng(5)
    covered, estimates = 0, []
    trials = 400
    for _ in range(trials):
        n = 12
        partial = rng.random(n) < fraction  # a switch falls inside an exposure with probability e/T
        est = estimate_exposure([(int(p), 0.01) for p in partial])
        if est.value_s is None:
            assert est.source == "unknown" and not partial.any()
            covered += 1  # "unknown" claims nothing (it says the shutter is short)
            continue
        lo, hi = est.ci95_s
        covered += lo <= fraction * 0.01 <= hi
        estimates.append(est.value_s / 0.01)
    assert covered / trials >= 0.93
    assert abs(np.mean(estimates) - fraction) < 0.05 + 0.2 * fraction


def test_exposure_given_wins_and_no_partly_lit_frame_is_unknown():
    assert estimate_exposure([(0, 0.01)] * 5, given_s=0.002).value_s == 0.002
    e = estimate_exposure([(0, 0.01)] * 7)
    assert e.value_s is None and e.source == "unknown" and "shorter" in e.detail
    assert estimate_exposure([]).source == "unknown"


def _identify_hidden_shutter(tmp_path, seed, exposure_s, fps=240, keep_exposure=False, **extra):
    from servoscope.campaign.runner import identify
    from servoscope.simulate import simulate_campaign

    # Uncompressed: at 480×384 H.264 shrinks the 12 Hz dwell's 0.3° swing by 1 % (−4 σ), a codec
    # systematic the fit's statistics cannot see (docs/accuracy.md, "H.264 — not honest"); these
    # tests are about the input's timing.
    extra.setdefault("codec", "raw")
    toml = simulate_campaign(tmp_path, "quick", seed, fps=fps, exposure_s=exposure_s, width=480, height=384, **extra)
    if not keep_exposure:
        toml.write_text(re.sub(r"\nexposure_s = .*", "", toml.read_text()))
    truth = json.loads((tmp_path / "truth.json").read_text())
    return identify(toml), truth


@pytest.mark.parametrize("seed", [1, 2])
def test_short_shutter_not_given_every_interval_holds_the_truth(tmp_path, seed):
    """The issue's case: a quarter-frame shutter at 240 frames/s, exposure not in the manifest."""
    res, truth = _identify_hidden_shutter(tmp_path, seed, exposure_s=1 / 960)
    s = res.summary()
    tm = truth["model"]
    for name in ("gain", "natural_frequency_rad_s", "damping_ratio", "dead_time_s"):
        lo, hi = s["model"]["ci95"][name]
        assert lo <= tm[name] <= hi, (name, lo, tm[name], hi)
    dead = s["dead_time"]
    for key in ("phase", "step"):
        lo, hi = dead[key]["ci95_s"]
        assert lo <= tm["dead_time_s"] <= hi, (key, lo, hi)
    # One name, one estimator: the model's dead time, its stderr and its interval are one estimate's.
    chosen = dead[dead["source"]]
    assert s["model"]["dead_time_s"] == chosen["value_s"]
    assert s["model"]["ci95"]["dead_time_s"] == chosen["ci95_s"]
    # Each clean switch is dated to ±(frame − exposure)/2 = ±1.56 ms; four dwells and a step
    # average that down (the paper preset's six dwells: 84.97 ms for 85.0 on seed 5).
    assert abs(s["model"]["dead_time_s"] - tm["dead_time_s"]) < 1.5e-3
    # The gap is stated, not 0.02 ms: a switch that lit no frame partly is anywhere between
    # two frame times (the exposure is not known), σ = (1/240 s)/√12 = 1.2 ms.
    clean = [t for t in res.tracks.values() if t.led_partial_frames == 0]
    assert clean
    for t in clean:
        assert t.t0_uncertainty_s == pytest.approx(1 / 240 / math.sqrt(12), rel=0.01)
    assert s["exposure"]["source"] in ("LED", "unknown")


def test_short_shutter_given_intervals_hold_the_truth(tmp_path):
    """A 1/2000 s shutter at 200 frames/s, given: t0 dated to the gap, intervals hold the truth."""
    res, truth = _identify_hidden_shutter(tmp_path, 4, exposure_s=1 / 2000, fps=200, keep_exposure=True)
    s = res.summary()
    assert s["exposure"]["source"] == "given"
    for key in ("phase", "step"):
        lo, hi = s["dead_time"][key]["ci95_s"]
        assert lo <= truth["model"]["dead_time_s"] <= hi, (key, lo, hi)
    lo, hi = s["model"]["ci95"]["dead_time_s"]
    assert lo <= truth["model"]["dead_time_s"] <= hi


def _cli(*args):
    from support import run_cli

    return run_cli(*args)  # the command's entry point in this process: no interpreter to start a call


@pytest.mark.parametrize("camera, expected", [
    ("exposure_s = 0", "camera.exposure_s: must be > 0"),
    ("exposure_s = 0.05", "longer than the frame interval"),  # 25 frames/s: 40 ms
    ('timestamp = "centre"', "camera.timestamp"),
])
def test_identify_refuses_an_impossible_shutter(tmp_path, camera, expected):
    from support import GOOD, tiny_video as _tiny_video

    _tiny_video(tmp_path / "a.mp4")
    _tiny_video(tmp_path / "b.mp4")
    manifest = tmp_path / "campaign.toml"
    manifest.write_text(f"[camera]\n{camera}\n" + GOOD)
    out = tmp_path / "out"
    proc = _cli("identify", manifest, "--out", out)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("servoscope: error: "), proc.stderr
    assert expected in lines[0] and str(manifest.name) in lines[0]
    assert not out.exists()


@pytest.mark.parametrize("exposure, expected", [("0", "must be > 0"), ("0.05", "longer than the frame interval")])
def test_track_refuses_an_impossible_shutter(tmp_path, exposure, expected):
    from support import tiny_video as _tiny_video

    video = _tiny_video(tmp_path / "a.mp4")
    out = tmp_path / "t.csv"
    proc = _cli("track", video, "--exposure", exposure, "--out", out)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("servoscope: error: "), proc.stderr
    assert expected in lines[0] and "a.mp4" in lines[0]
    assert not out.exists()


@pytest.fixture(scope="module")
def one_phase_campaign(tmp_path_factory):
    """The footage of the test below, rendered once: the manifest with the exposure, and one without it."""
    from servoscope.simulate import simulate_campaign

    toml = simulate_campaign(tmp_path_factory.mktemp("onephase"), "quick", 1, fps=200, exposure_s=0.0001,
                             width=480, height=384, t0_frame_phase=0.3)
    # What manifest_exposure=False writes (the frames are the same): campaign.toml less its exposure_s line.
    hidden = toml.with_name("campaign_hidden_exposure.toml")
    hidden.write_text(re.sub(r"\nexposure_s = .*", "", toml.read_text()))
    assert hidden.read_text() != toml.read_text()
    return {True: toml, False: hidden}


@pytest.mark.parametrize("given", [True, False])
def test_switches_at_one_point_of_the_frame_clock_are_a_shared_error(one_phase_campaign, given):
    """The issue's second case: a 0.1 ms shutter at 200 frames/s and every switch at the same
    sub-frame phase (one script starts camera and input): every dwell's t0 is off by the same
    +1 ms, which no averaging over dwells removes. The intervals must say so."""
    from servoscope.campaign.runner import identify

    toml = one_phase_campaign[given]
    truth = json.loads((toml.parent / "truth.json").read_text())
    res = identify(toml)
    s = res.summary()
    true_t0 = {t["video"]: t["t0_s"] for t in truth["tests"]}
    errors = [res.tracks[t["label"]].t0_s - true_t0[t["video"]] for t in s["tests"]]
    assert np.ptp(errors) < 1e-5 and abs(errors[0]) > 0.5e-3  # one shared error, not small
    gap = 1 / 200 - (0.0001 if given else 0.0)
    shared = s["dead_time"]["phase"]["shared_t0_stderr_s"]
    assert shared == pytest.approx(gap / math.sqrt(12), rel=0.05)
    assert any("same point of the frame clock" in w for w in s["warnings"])
    tau = truth["model"]["dead_time_s"]
    for key in ("phase", "step"):
        lo, hi = s["dead_time"][key]["ci95_s"]
        assert lo <= tau <= hi, (key, lo, tau, hi)
    lo, hi = s["model"]["ci95"]["dead_time_s"]
    assert lo <= tau <= hi
    for name in ("gain", "natural_frequency_rad_s", "damping_ratio"):
        lo, hi = s["model"]["ci95"][name]
        assert lo <= truth["model"][name] <= hi, name


def test_overlapping_t0_intervals_of_independent_switches_keep_each_phase_honest(tmp_path):
    """A quarter-frame shutter, timestamps at the exposure's start, switches at independent
    points of the frame clock (t0 errors −3 … +2.6 ms): the intervals overlap by chance. Were
    the overlap read as one shared error, the phases would be stated to ±0.1° at 12 Hz while
    each is off by up to 11°, and ωn bent to 34.3 rad/s with an interval excluding 37."""
    from servoscope.campaign.runner import identify
    from servoscope.simulate import simulate_campaign

    # 720×576: at 480×384 the 12 Hz dwell's 0.3° swing loses 1.2 % of its gain to H.264, a
    # separate systematic this test is not about.
    toml = simulate_campaign(tmp_path, "quick", 0, exposure_s=0.0025, timestamp_at="start")
    truth = json.loads((tmp_path / "truth.json").read_text())
    res = identify(toml)
    s = res.summary()
    true_t0 = {t["video"]: t["t0_s"] for t in truth["tests"]}
    errors = np.array([res.tracks[t["label"]].t0_s - true_t0[t["video"]] for t in s["tests"]])
    assert np.ptp(errors) > 2e-3  # independent, not one shared error
    assert s["dead_time"]["phase"]["shared_t0_stderr_s"] > 0  # the footage cannot tell
    fr = res.frequency_response
    for label, f_hz, phase_se in zip(fr.labels, fr.frequency_hz, fr.phase_stderr_deg):
        # each phase keeps its own t0 error: 360·f·σ_t0
        sigma_t0 = res.tracks[label].t0_uncertainty_s
        assert phase_se >= 0.99 * 360 * f_hz * sigma_t0, label
    for name in ("gain", "natural_frequency_rad_s", "damping_ratio", "dead_time_s"):
        lo, hi = s["model"]["ci95"][name]
        assert lo <= truth["model"][name] <= hi, (name, lo, hi)
    assert s["model"]["natural_frequency_rad_s"] == pytest.approx(37.0, rel=0.01)
