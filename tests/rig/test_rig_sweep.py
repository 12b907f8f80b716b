"""Sweep (chirp) tests on the rig: planned to fit the camera, their coherence foreseen, driven."""

from __future__ import annotations

import math
import tomllib
from dataclasses import replace

import numpy as np
import pytest
import scipy.signal
from click.testing import CliRunner

from servoscope.errors import ServoscopeError
from servoscope.rig.cli import drive as drive_command
from servoscope.rig.cli import plan as plan_command
from servoscope.rig.driver import RigSettings, drive_plan
from servoscope.rig.chirp import MIN_COHERENCE, nominal_gain, plan_chirp, sweep_coherence, sweep_cycles
from servoscope.rig.plan import read_plan, write_plan

from test_rig_drive import CENTRE_QUS, LED, LED_OFF_QUS, LED_ON_QUS, SERVO, UPDATE_HZ, FakeMaestro, maestro  # noqa: F401


def chirp_oracle(t, amplitude, f0, f1, duration_s, shape="log"):
    method = {"log": "logarithmic", "linear": "linear"}[shape]
    return amplitude * scipy.signal.chirp(t, f0, duration_s, f1, method=method, phi=-90)


# -- planning ---------------------------------------------------------------------------------------

@pytest.mark.parametrize("shape", ["log", "linear"])
def test_a_sweep_fits_the_camera_and_ends_at_zero(shape):
    plan = plan_chirp(100, 0.5, 20, 12, shape=shape, record_s=14, lead_in_s=1.0, tail_s=0.5)
    assert [d.kind for d in plan.dwells] == ["sweep", "step"]
    sweep = plan.dwells[0]
    assert (sweep.from_hz, sweep.to_hz, sweep.shape, sweep.amplitude) == (0.5, 20, shape, 0.1)
    # Rounded up to a whole number of cycles (less than one mean period longer): the command ends at 0.
    cycles = sweep_cycles(0.5, 20, sweep.duration_s, shape)
    assert cycles == pytest.approx(round(cycles), abs=1e-9)
    assert 12 <= sweep.duration_s < 12 + 12 / sweep_cycles(0.5, 20, 12, shape)
    t = np.linspace(0, sweep.duration_s, 20001)
    assert np.allclose(sweep.input_at(t[:-1]), chirp_oracle(t[:-1], 0.1, 0.5, 20, sweep.duration_s, shape))
    assert abs(chirp_oracle(sweep.duration_s, 0.1, 0.5, 20, sweep.duration_s, shape)) < 1e-9
    assert sweep.input_at(sweep.duration_s) == 0.0 and sweep.input_at(-0.01) == 0.0
    assert sweep.warnings == ()  # 20 Hz is 5 frames per period at 100 fps, no PWM ripple at 0.5–20 Hz
    assert [d.kind for d in plan_chirp(100, 0.5, 20, 12, step=False).dwells] == ["sweep"]


def test_a_sweep_that_does_not_fit_is_refused_in_one_line():
    with pytest.raises(ServoscopeError, match=r"--record-seconds 13\b") as err:
        plan_chirp(100, 0.5, 20, 12, record_s=13, lead_in_s=1.0, tail_s=0.5)
    assert "\n" not in str(err.value)
    with pytest.raises(ServoscopeError, match="at or above half the frame rate"):
        plan_chirp(40, 0.5, 20, 12)
    with pytest.raises(ServoscopeError, match="--sweep-shape"):
        plan_chirp(100, 0.5, 20, 12, shape="cubic")
    with pytest.raises(ServoscopeError, match="top frequency must be above"):
        plan_chirp(100, 5, 2, 12)
    # Below Nyquist but with few frames per period, and the PWM ripple inside the band: warned, not refused.
    warned = plan_chirp(60, 0.5, 20, 12).dwells[0].warnings
    assert any("3.0 frames per period" in w for w in warned)
    assert any("PWM ripple" in w and "10 Hz" in w for w in warned)  # 50 Hz folds to 10 Hz at 60 fps


# -- the coherence foreseen -------------------------------------------------------------------------

def test_coherence_estimate_matches_the_closed_form_and_a_simulated_response():
    fps, f0, f1, amplitude, sigma_deg = 100.0, 0.5, 20.0, 0.1, 0.005
    duration_s = plan_chirp(fps, f0, f1, 12, step=False).dwells[0].duration_s
    est = sweep_coherence(amplitude, f0, f1, duration_s, fps, noise_deg=sigma_deg)

    # Closed form for this case: SNR = c·fps·Y²/(4σ²·√(2ḟ)), c = max (C² + S²)/X ≈ 0.8012 at X ≈ 1.02.
    w = 2 * math.pi * f1
    y_deg = math.degrees(amplitude * abs(0.23 * 37**2 / ((1j * w) ** 2 + 2 * 0.65 * 37 * 1j * w + 37**2)))
    rate = f1 * math.log(f1 / f0) / duration_s
    assert est.response_deg == pytest.approx(y_deg, rel=1e-12)
    assert est.snr == pytest.approx(0.8012 * fps * y_deg**2 / (4 * sigma_deg**2 * math.sqrt(2 * rate)), rel=1e-3)
    assert est.coherence == pytest.approx(est.snr / (1 + est.snr))
    assert est.window_s == pytest.approx(1.024 / math.sqrt(2 * rate), rel=2e-3)

    # Direct: the nominal servo's response to the chirp, filmed at fps; the Fourier coefficient at f1
    # of the best window ending with the sweep, against white noise's N·σ².
    t = np.arange(0, duration_s, 1 / fps)
    u = chirp_oracle(t, amplitude, f0, f1, duration_s)
    servo = scipy.signal.lti([0.23 * 37**2], [1, 2 * 0.65 * 37, 37**2])
    _, y, _ = scipy.signal.lsim(servo, u, t)
    y = np.degrees(y)
    snr_direct = max(abs(np.sum(y[-n:] * np.exp(-2j * np.pi * f1 * t[-n:]))) ** 2 / (n * sigma_deg**2)
                     for n in range(5, 200))
    assert est.snr == pytest.approx(snr_direct, rel=0.1)

    # The SNR falls as σ², rises as √T and as the amplitude squared.
    assert sweep_coherence(amplitude, f0, f1, duration_s, fps, noise_deg=2 * sigma_deg).snr == pytest.approx(est.snr / 4)
    assert sweep_coherence(amplitude, f0, f1, 4 * duration_s, fps, noise_deg=sigma_deg).snr == pytest.approx(2 * est.snr)
    assert sweep_coherence(2 * amplitude, f0, f1, duration_s, fps, noise_deg=sigma_deg).snr == pytest.approx(4 * est.snr)
    assert nominal_gain(0.0) == pytest.approx(0.23)


def test_a_low_coherence_is_warned_with_what_to_do():
    plan = plan_chirp(100, 0.5, 20, 12, amplitude=0.01, noise_deg=0.05)
    est = sweep_coherence(0.01, 0.5, 20, plan.dwells[0].duration_s, 100, noise_deg=0.05)
    assert est.coherence < MIN_COHERENCE
    [warning] = [w for w in plan.warnings if "coherence" in w]
    assert f"{est.coherence:.2f}" in warning and "--duration" in warning and "--amplitude" in warning
    assert not any("coherence" in w for w in plan_chirp(100, 0.5, 20, 12).warnings)


# -- the command line -------------------------------------------------------------------------------

def test_plan_command_plans_a_sweep_and_says_its_coherence(tmp_path):
    out = tmp_path / "plan.toml"
    result = CliRunner().invoke(plan_command, ["--fps", "100", "--sweep", "0.5:20", "--duration", "12",
                                               "--record-seconds", "20", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "log sweep 0.5–20 Hz" in result.output and "expected coherence at 20 Hz: γ² ≈ 0.99" in result.output
    data = tomllib.loads(out.read_text())
    sweep, step = data["tests"]
    assert {k: sweep[k] for k in ("kind", "from_hz", "to_hz", "shape", "amplitude")} == {
        "kind": "sweep", "from_hz": 0.5, "to_hz": 20.0, "shape": "log", "amplitude": 0.1}
    assert sweep["duration_s"] == pytest.approx(data["plan"]["dwells"][0]["duration_s"]) and step["kind"] == "step"
    back = read_plan(out)
    assert back.dwells[0] == replace(plan_chirp(100, 0.5, 20, 12).dwells[0])
    text = out.read_text()
    (tmp_path / "bad.toml").write_text(text.replace(f"duration_s = {sweep['duration_s']!r}\nshape", "duration_s = 11.0\nshape"))
    with pytest.raises(ServoscopeError, match="disagree"):
        read_plan(tmp_path / "bad.toml")
    result = CliRunner().invoke(plan_command, ["--fps", "100", "--sweep", "0.5:20", "--duration", "12", "--no-step",
                                               "--sweep-shape", "linear", "--out", str(out)])
    assert result.exit_code == 0 and [t["kind"] for t in tomllib.loads(out.read_text())["tests"]] == ["sweep"]


@pytest.mark.parametrize("args, message", [
    (["--sweep", "0.5:20", "--duration", "12", "--record-seconds", "12"], "--record-seconds 12"),
    (["--sweep", "0.5:80", "--duration", "12"], "above half the frame rate"),
    (["--sweep", "0.5:20"], "--duration"),
    (["--sweep", "0.5-20", "--duration", "12"], "F0:F1"),
    (["--sweep", "0.5:20", "--duration", "12", "--from", "1"], "drop --from"),
    (["--from", "1", "--to", "5", "--duration", "12"], "go with --sweep"),
    ([], "--sweep F0:F1"),
])
def test_plan_command_refuses_a_bad_sweep(tmp_path, args, message):
    result = CliRunner().invoke(plan_command, ["--fps", "100", *args, "--out", str(tmp_path / "p.toml")])
    assert isinstance(result.exception, ServoscopeError) and message in str(result.exception), result.output
    assert "\n" not in str(result.exception) and not (tmp_path / "p.toml").exists()


def test_help_reads_well():
    plan_help = CliRunner().invoke(plan_command, ["--help"], terminal_width=200).output
    for option in ("--sweep F0:F1", "--duration", "--sweep-shape [log|linear]", "--noise-deg", "--record-seconds"):
        assert option in plan_help
    assert "sweep" in CliRunner().invoke(drive_command, ["--help"], terminal_width=200).output


# -- driving ----------------------------------------------------------------------------------------

def test_drive_streams_the_chirp_and_switches_the_led_at_its_start(maestro, tmp_path):
    plan = plan_chirp(100, 1.0, 5.0, 2.0, amplitude=0.3, step=False, update_hz=UPDATE_HZ,
                      lead_in_s=0.1, tail_s=0.05, rest_s=0.0)
    sweep = plan.dwells[0]
    write_plan(plan, tmp_path / "plan.toml")
    events = []
    result = drive_plan(read_plan(tmp_path / "plan.toml"), maestro.port,
                        settings=RigSettings(channel=SERVO, led_channel=LED, center_us=1500, us_per_unit=500),
                        camera=lambda e, i, d, v: events.append((e, i, v)), campaign_path=tmp_path / "campaign.toml")
    maestro.stop()
    assert maestro.errors == []
    video = "sweep_01_1-5Hz.mp4"
    assert events == [("start", 1, video), ("stop", 1, video)]
    cmds = maestro.commands
    led = maestro.targets(LED)
    assert [c.value for c in led] == [LED_ON_QUS, LED_ON_QUS, LED_OFF_QUS, LED_ON_QUS]
    i_off, i_on = cmds.index(led[2]), cmds.index(led[3])
    servo = [c for c in cmds[i_off:i_on] if c.command == 0x84 and c.channel == SERVO]
    assert cmds[i_off + 1] is servo[0], "the first chirp command goes out with the LED switch"
    assert servo[0].time_s - led[2].time_s < 1e-3
    assert all(c.value == CENTRE_QUS for c in cmds[:i_off] if c.command == 0x84 and c.channel == SERVO)

    n = math.ceil(sweep.duration_s * UPDATE_HZ - 1e-9)
    assert len(servo) == n + 2 and servo[-1].value == CENTRE_QUS  # n + 1 samples, then centre with the LED
    k = np.arange(n + 1)
    oracle = chirp_oracle(k / UPDATE_HZ, 0.3, 1.0, 5.0, sweep.duration_s)
    oracle[k / UPDATE_HZ >= sweep.duration_s] = 0.0
    got = np.array([c.value for c in servo[: n + 1]])
    assert np.max(np.abs(got - 4 * (1500 + 500 * oracle))) <= 0.5 + 1e-9
    assert got.max() > 6500 and got.min() < 5500  # the sweep's swing got through
    # Each command arrives on its schedule t0 + k/update_hz (loosely: the pty's delivery is not the driver's).
    arrival_ms = (np.array([c.time_s for c in servo[: n + 1]]) - led[2].time_s - k / UPDATE_HZ) * 1e3
    assert np.median(np.abs(arrival_ms)) < 5.0

    data = tomllib.loads(result.campaign.read_text())
    assert data["tests"][0]["video"] == video and data["tests"][0]["kind"] == "sweep"
    assert data["plan"]["dwells"][0]["max_late_ms"] >= 0
