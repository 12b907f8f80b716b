"""Sweep tests (issue 31): the chirp command, the twin's response to it, the manifest's sweeps, a rendered sweep.

Fast: the oracles run on a few seconds of signal, and the one rendered campaign is a 320×256 raw
video of a 2 s sweep (about 2 s to render and track).
"""

from __future__ import annotations

import json
import math
import re

import control
import numpy as np
import pytest
import scipy.signal

from servoscope.campaign.manifest import Campaign, TestSpec, campaign_from_data
from servoscope.errors import ServoscopeError
from servoscope.simulate import PAPER_SERVO, InputSignal, ServoModel, simulate_campaign
from servoscope.simulate.servo import GRID_STEP_S
from servoscope.sysid.inputs import sweep_command, sweep_frequency_hz

SWEEP = dict(from_hz=0.5, to_hz=15.0, duration_s=3.00003)  # a length off the grid: the end is put on it


@pytest.mark.parametrize("shape, method", [("log", "logarithmic"), ("linear", "linear")])
def test_the_sweep_command_is_scipys_chirp_started_at_zero_and_zero_outside(shape, method):
    t = np.linspace(-0.5, 3.5, 40001)
    u = sweep_command(t, 0.2, 0.5, 15.0, 3.0, shape)
    inside = (t >= 0) & (t <= 3.0)
    assert np.array_equal(u[inside], 0.2 * scipy.signal.chirp(t[inside], 0.5, 3.0, 15.0, method=method, phi=-90))
    assert np.all(u[~inside] == 0.0)
    assert sweep_command(0.0, 0.2, 0.5, 15.0, 3.0, shape) == pytest.approx(0.0, abs=1e-15)  # a sine from zero
    assert np.max(np.abs(u)) == pytest.approx(0.2, rel=1e-4)
    f = sweep_frequency_hz(np.array([0.0, 3.0]), 0.5, 15.0, 3.0, shape)
    assert f == pytest.approx([0.5, 15.0])
    # The twin's input and the manifest's test say the same command.
    sig = InputSignal("sweep", 0.2, t0_s=0.7, from_hz=0.5, to_hz=15.0, duration_s=3.0, shape=shape)
    assert np.array_equal(sig.value(t + 0.7), sweep_command((t + 0.7) - 0.7, 0.2, 0.5, 15.0, 3.0, shape))
    spec = TestSpec(None, "sweep", 0.2, from_hz=0.5, to_hz=15.0, duration_s=3.0, shape=shape)
    assert np.array_equal(spec.command(t), u)
    assert sig.end_s == pytest.approx(3.7)


def test_bad_sweep_inputs_are_refused_with_every_reason():
    with pytest.raises(ServoscopeError, match=r"from_hz: must be > 0.*duration_s: missing.*shape: unknown sweep shape "
                                              r"'logg' \(did you mean 'log'\?\)"):
        InputSignal("sweep", 0.1, from_hz=0.0, to_hz=5.0, shape="logg")
    with pytest.raises(ServoscopeError, match=r"to_hz: must be > from_hz"):
        InputSignal("sweep", 0.1, from_hz=5.0, to_hz=2.0, duration_s=1.0)
    assert InputSignal("sweep", 0.1, from_hz=1.0, to_hz=2.0, duration_s=1.0).shape == "log"
    assert InputSignal("sine", 0.1, 2.0, from_hz=1.0).from_hz is None  # other kinds carry no sweep


def _oracle(servo: ServoModel, sig: InputSignal, t: np.ndarray, n: int = 100_001) -> np.ndarray:
    """python-control's forced_response of G to the delayed sweep: on a uniform grid over the sweep (its
    end a grid point), then from the state at its end with no input, interpolated to ``t``."""
    sys = control.ss(servo.transfer_function)
    on = sig.t0_s + servo.dead_time_s
    end = on + sig.duration_s
    rel = np.linspace(0.0, sig.duration_s, n)
    during = control.forced_response(sys, rel, sig.value(sig.t0_s + rel), return_x=True)
    rel2 = np.linspace(0.0, float(t.max()) - end + 1e-3, 20_001)
    after = control.forced_response(sys, rel2, np.zeros_like(rel2), X0=during.states[:, -1])
    grid = np.concatenate([[0.0], on + rel, end + rel2[1:]])
    y = np.concatenate([[0.0], during.outputs, after.outputs[1:]])
    return np.where(t < on, 0.0, np.interp(t, grid, y))


@pytest.mark.parametrize("shape", ["log", "linear"])
def test_the_twins_response_to_a_sweep_is_python_controls(shape):
    """The grid simulation (first-order hold, step ≤ 0.1 ms, the sweep's end on the grid) against
    ``control.forced_response`` on a 3× finer grid, with the paper servo's 85 ms dead time.

    Both interpolate linearly between grid points, the input and the output alike: each errs by at most
    ``|ÿ|·dt²/8`` with ``|ÿ| ≤ |y|max·(2π·to_hz)²`` (2.6e-7 rad here); the tolerance is twice that. Measured:
    6e-8 rad, 3e-6 of the response's peak.
    """
    sig = InputSignal("sweep", 0.1, t0_s=0.3, shape=shape, **SWEEP)
    t = np.arange(0.0, 4.0, 0.01) + 0.0037  # frame times, off the grid, through the sweep's end and after
    y = PAPER_SERVO.response(sig, t)
    expected = _oracle(PAPER_SERVO, sig, t)
    peak = np.max(np.abs(expected))
    tol = 2.0 * peak * (2.0 * math.pi * sig.to_hz * GRID_STEP_S) ** 2 / 8.0
    assert peak > 0.02 and tol < 1e-6
    assert np.max(np.abs(y - expected)) < tol
    assert np.all(y[t < sig.t0_s + PAPER_SERVO.dead_time_s] == 0.0)


def test_the_nonlinear_structures_take_a_sweep():
    """A rate limit too fast to bite is the linear response; play of width b keeps the output within b/2 of it.

    Up to the sweep's end the rate-limited reference is the input itself (exact); the end's jump (to 0
    from the sweep's last value) becomes a ramp over one grid step under a rate limit, shifting it by
    half a step: ``|jump|·dt/2·max|g|`` (g, G's impulse response, ≤ 4.07 /s here), about 2e-5 rad at most.
    """
    sig = InputSignal("sweep", 0.1, t0_s=0.2, from_hz=1.0, to_hz=10.0, duration_s=1.5)
    t = np.arange(0.0, 2.2, 0.005)
    linear = PAPER_SERVO.response(sig, t)
    fast = ServoModel(PAPER_SERVO.num, PAPER_SERVO.den, PAPER_SERVO.dead_time_s, rate_limit_per_s=1e6)
    before_end = t <= sig.end_s + PAPER_SERVO.dead_time_s
    assert np.max(np.abs(fast.response(sig, t) - linear)[before_end]) < 1e-12
    jump = abs(float(sig.value(sig.end_s)))
    assert np.max(np.abs(fast.response(sig, t) - linear)) < jump * GRID_STEP_S / 2 * 4.07 * 1.2
    play = ServoModel(PAPER_SERVO.num, PAPER_SERVO.den, PAPER_SERVO.dead_time_s, backlash=0.004)
    y = play.response(sig, t)
    assert np.max(np.abs(y - linear)) <= 0.002 + 1e-6 and np.max(np.abs(y - linear)) > 0.0015


MANIFEST = {"markers": {"lead": "red", "trail": "green"}}


def _load(tests: list[dict], **extra) -> Campaign:
    from pathlib import Path

    return campaign_from_data({**MANIFEST, "tests": tests, **extra}, Path("/nowhere/campaign.toml"),
                              check_videos=False)


def test_a_manifests_sweeps_are_read_and_every_bad_one_reported_at_once():
    good = {"video": "s.mp4", "kind": "sweep", "from_hz": 0.5, "to_hz": 15, "duration_s": 12, "amplitude": 0.1}
    c = _load([good, {**good, "video": "l.mp4", "shape": "linear"}, {"video": "d.mp4", "kind": "sine",
                                                                        "frequency_hz": 2.0, "amplitude": 0.1}])
    assert [t.shape for t in c.sweep_tests] == ["log", "linear"] and len(c.sine_tests) == 1
    s = c.tests[0]
    assert (s.from_hz, s.to_hz, s.duration_s, s.frequency_hz) == (0.5, 15.0, 12.0, None)
    assert c.tests[2].from_hz is None and c.tests[2].shape is None
    bad = [
        {**good, "video": "1.mp4", "from_hz": 0},                       # 1
        {**good, "video": "2.mp4", "to_hz": 0.4},                       # 2
        {k: v for k, v in {**good, "video": "3.mp4"}.items() if k != "duration_s"},  # 3
        {**good, "video": "4.mp4", "shape": "logarithmic"},             # 4
        {**good, "video": "5.mp4", "frequency_hz": 3.0},                # 5
        {"video": "6.mp4", "kind": "sine", "frequency_hz": 2.0, "amplitude": 0.1, "to_hz": 4.0},  # 6
        {**good, "video": "7.mp4", "amplitude": -0.1},                  # 7
        {**good, "video": "8.mp4", "form_hz": 1.0},                     # 8
    ]
    with pytest.raises(ServoscopeError) as err:
        _load(bad)
    text = str(err.value)
    for expected in ["tests[1].from_hz: must be > 0, got 0",
                     "tests[2].to_hz: must be > from_hz (0.5 Hz), got 0.4",
                     "tests[3].duration_s: missing",
                     "tests[4].shape: unknown sweep shape 'logarithmic'",
                     "tests[5].frequency_hz: a sweep test has from_hz and to_hz, not frequency_hz",
                     "tests[6].to_hz: only a sweep test (kind = \"sweep\") has to_hz",
                     "tests[7].amplitude: must be > 0 for a sweep",
                     "tests[8].form_hz: unknown key (did you mean 'from_hz'?)"]:
        assert expected in text, (expected, text)
    assert "8 problems" in text or "9 problems" in text
    # The frame rate a manifest states bounds to_hz: a frame source's fps, or a plan's.
    with pytest.raises(ServoscopeError, match=re.escape("tests[1].to_hz: 15 Hz is at or above half the frame rate "
                                                        "(25 frames/s)")):
        _load([{k: v for k, v in good.items() if k != "video"} | {"frames": "f/*.tif", "fps": 25}])


def _tiny_sweep(tmp_path, **kw):
    args = dict(width=320, height=256, codec="raw", frequencies_hz=(), include_step=False, sweep=(1.0, 12.0, 2.0),
                pre_roll_s=0.2, settle_s=0.3)
    return simulate_campaign(tmp_path, "quick", 0, **{**args, **kw})


def test_a_rendered_sweep_loads_round_trips_and_is_tracked_as_the_servo_moved(tmp_path):
    """The twin's tiny sweep: its campaign.toml says the sweep and reads back equal; the tracked angle follows
    the servo model's (exposure-averaged) response to it.

    Measured (seed 0, 320×256 raw, 251 frames, pitch peak 0.023 rad): the tracked angle less its rest offset
    differs from the model by 7.7e-5 rad RMS (3.8e-5 at rest, the picture's noise; 8e-5 moving, the
    stickers' centroids on a coarse pixel grid) and 2.3e-4 at most, with no lag (6 µs) and a gain within
    0.07 %. The bounds are twice those (four times for the lag, three for the gain), the LED's date within
    three of its own uncertainties.
    """
    from servoscope.camera import CameraModel
    from servoscope.pipeline import TrackerSettings, track_video
    from servoscope.simulate.campaign import exposure_averaged_response

    toml = _tiny_sweep(tmp_path)
    assert 'kind = "sweep"\nfrom_hz = 1.0\nto_hz = 12.0\nduration_s = 2.0\nshape = "log"\namplitude = 0.1' in toml.read_text()
    c = Campaign.load(toml)
    (spec,) = c.sweep_tests
    assert (spec.from_hz, spec.to_hz, spec.duration_s, spec.shape, spec.amplitude) == (1.0, 12.0, 2.0, "log", 0.1)
    assert Campaign.load(c.save(tmp_path / "copy" / "campaign.toml"), check_videos=False) == c
    truth = json.loads((tmp_path / "truth.json").read_text())
    (test,) = truth["tests"]
    assert {k: test[k] for k in ("kind", "from_hz", "to_hz", "duration_s", "shape")} == {
        "kind": "sweep", "from_hz": 1.0, "to_hz": 12.0, "duration_s": 2.0, "shape": "log"}
    assert test["time_s"][-1] > test["t0_s"] + 2.0 + 0.25  # the video goes on after the sweep
    servo = ServoModel(tuple(truth["model"]["num"]), tuple(truth["model"]["den"]), truth["model"]["dead_time_s"])
    assert servo == PAPER_SERVO

    exposure = truth["video"]["exposure_s"]
    track = track_video(tmp_path / test["video"], TrackerSettings(camera=CameraModel.load(tmp_path / "camera.json"),
                                                                  exposure_s=exposure))
    assert track.n_valid == track.n_frames
    assert abs(track.t0_s - test["t0_s"]) < 3.0 * track.t0_uncertainty_s + 1e-4
    sig = InputSignal("sweep", test["amplitude"], t0_s=test["t0_s"], from_hz=test["from_hz"], to_hz=test["to_hz"],
                      duration_s=test["duration_s"], shape=test["shape"])
    model = exposure_averaged_response(servo, sig, track.time_s, exposure)
    rest = track.time_s < test["t0_s"]
    angle = track.angle_rad - np.median(track.angle_rad[rest])
    err = angle - model
    rms = float(np.sqrt(np.mean(err**2)))
    assert np.max(np.abs(model)) > 0.02
    assert rms < 1.6e-4 and np.max(np.abs(err)) < 5e-4, (rms, np.max(np.abs(err)))
    rate = np.gradient(model, track.time_s)
    lag = -float(np.sum(err * rate) / np.sum(rate * rate))
    gain = float(np.sum(err * model) / np.sum(model * model))
    assert abs(lag) < 2.5e-5 and abs(gain) < 2e-3, (lag, gain)


def test_the_paper_sweep_preset_is_one_12_s_log_sweep_at_the_dwells_amplitude():
    from servoscope.simulate.presets import PRESETS

    p = PRESETS["paper-sweep"]
    assert p.sweep == (0.5, 15.0, 12.0) and p.sweep_shape == "log" and not p.frequencies_hz and not p.include_step
    assert p.sine_amplitude == PRESETS["paper"].sine_amplitude and p.servo == PAPER_SERVO
    assert p.pre_roll_s == PRESETS["paper"].pre_roll_s
    with pytest.raises(ServoscopeError, match="half the frame rate"):
        simulate_campaign("/nonexistent-never-written", "quick", sweep=(1.0, 60.0, 2.0))
