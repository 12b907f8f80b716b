"""Identification from a frequency sweep (issue 31, build 3): one recording, the whole frequency response.

Oracle: the twin's truth (its servo: K = 0.23, ωn = 37 rad/s, ζ = 0.65, dead time 85 ms). The
campaign is small on purpose (320×256 raw frames, a 6 s sweep and two dwells): the same code runs
on the 12 s paper-sweep preset (docs/accuracy.md gives its figures).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from servoscope.campaign import identify
from servoscope.campaign.result import IdentificationResult
from servoscope.simulate import simulate_campaign

from support import run_cli

TRUTH = {"gain": 0.23, "natural_frequency_rad_s": 37.0, "damping_ratio": 0.65, "dead_time_s": 0.085}


@pytest.fixture(scope="module")
def sweep_campaign(tmp_path_factory):
    """A 6 s log sweep 0.5–12 Hz beside two dwells (2 and 8 Hz), no step, with a second of rest around the sweep."""
    return simulate_campaign(tmp_path_factory.mktemp("sweep") / "c", "quick", 2, width=320, height=256, codec="raw",
                             frequencies_hz=(2.0, 8.0), include_step=False, sweep=(0.5, 12.0, 6.0),
                             pre_roll_s=1.0, settle_s=1.0)


def test_a_sweep_and_two_dwells_give_one_response_and_the_servo(sweep_campaign):
    result = identify(sweep_campaign, workers=1)
    fr = result.frequency_response
    (label, sweep), = result.sweeps.items()
    sweep_points = [lab for lab in fr.labels if lab.startswith(label)]
    dwell_points = [lab for lab in fr.labels if not lab.startswith(label)]
    # One response: every coherent sweep frequency and both dwells, sorted by frequency.
    assert len(dwell_points) == 2 and len(sweep_points) == int(sweep.kept.sum()) >= 10
    assert list(fr.frequency_hz) == sorted(fr.frequency_hz)
    assert min(sweep.coherence[sweep.kept]) >= 0.6
    p = result.parameters
    for name, true in TRUTH.items():
        assert p[name].holds(true), (name, p[name], true)
    assert abs(p["gain"].value - 0.23) < 0.005 * 0.23
    assert abs(p["natural_frequency_rad_s"].value - 37.0) < 0.01 * 37.0
    assert abs(p["damping_ratio"].value - 0.65) < 0.02 * 0.65
    assert abs(p["dead_time_s"].value - 0.085) < 0.001


def test_the_command_writes_the_sweep_and_reads_it_back(sweep_campaign, tmp_path):
    out = tmp_path / "out"
    # With the time-domain fit too: its report section draws the dwells' describing function, not the sweep's points.
    run = run_cli("identify", str(sweep_campaign), "--out", str(out), "--workers", "1", "--nonlinear", "linear")
    assert run.returncode == 0, run.stderr
    data = json.loads((out / "result.json").read_text())
    (label, sweep), = data["sweeps"].items()
    assert len(sweep["frequency_hz"]) == len(sweep["coherence"]) == len(sweep["kept"])
    entry = next(t for t in data["tests"] if t["kind"] == "sweep")
    assert (entry["from_hz"], entry["to_hz"], entry["duration_s"], entry["shape"]) == (0.5, 12.0, 6.0, "log")
    report = (out / "report.html").read_text()
    assert "Frequency sweeps" in report and "coherence" in report and "One model for the sines and the step" in report
    assert data["model"]["time_domain"]["candidates"][0]["structure"] == "linear"
    assert (out / "figures" / f"{label}_response.png").exists() and (out / "figures" / f"{label}_time.png").exists()
    again = IdentificationResult.load(out)
    assert json.dumps(again.summary(), sort_keys=True) == json.dumps(data, sort_keys=True)
    assert "gain K" in run.stdout  # the headline table


def test_the_report_draws_the_sweep_as_the_fit_takes_it(sweep_campaign):
    """The CIFER figure's sweep points are the ones the fit takes: the exposure's averaging undone, as the
    dwells' squares are (a full shutter once drew the sweep 3–4 % under the model at 12–14 Hz)."""
    from servoscope.report import sweep_section

    result = identify(sweep_campaign, workers=1)
    (label, sweep), = result.sweeps.items()
    assert result.campaign.exposure_s and result.campaign.exposure_s > 0
    fig = sweep_section._cifer_figure(result, label)
    f, gain_db = (np.asarray(v, float) for v in fig.axes[0].lines[0].get_data())
    fr = result.frequency_response
    taken = {round(float(fq), 9): g for lab, fq, g in zip(fr.labels, fr.frequency_hz, fr.gain) if lab.startswith(label)}
    drawn = {round(float(fq), 9): 10 ** (g / 20) for fq, g in zip(f, gain_db)}
    assert taken and set(taken) <= set(drawn)
    for fq, g in taken.items():
        assert drawn[fq] == pytest.approx(g, rel=1e-9), fq
    # ...and not the frames' own: at the top frequency the two differ by the box filter's sinc.
    top = max(taken)
    assert drawn[top] / sweep.gain[np.argmin(abs(sweep.frequency_hz - top))] == pytest.approx(
        1 / np.sinc(top * result.campaign.exposure_s), rel=1e-9)


def test_a_codec_that_lags_the_stickers_widens_the_dead_time_and_says_so(sweep_campaign, tmp_path):
    """H.264 at 1000 frames/s and 10 kbit a frame shows the stickers late in its predicted frames; a sweep has
    no codec check, so the lag behind the I-frames is measured and added to the dead time's error (issue 31)."""
    from servoscope.campaign.sweeps import codec_lag_s

    toml = simulate_campaign(tmp_path / "c", "quick", 3, width=320, height=256, fps=1000, exposure_s=0.0005,
                             codec="h264", bit_rate=10_000_000, frequencies_hz=(), include_step=False,
                             sweep=(1.0, 15.0, 3.0), pre_roll_s=0.5, settle_s=0.5)
    result = identify(toml, workers=1)
    (track,) = result.tracks.values()
    lag, lag_se = codec_lag_s(track)
    # Oracle: the lag at which the rendered angle best matches the tracked one.
    truth = json.loads((tmp_path / "c" / "truth.json").read_text())["tests"][0]
    y = np.where(track.valid, track.angle_rad, np.nan)
    ok = np.isfinite(y)
    shifts = np.linspace(-3e-3, 3e-3, 121)
    seen = shifts[int(np.argmin([np.std((y - np.interp(track.angle_time_s - s, truth["time_s"], truth["angle_rad"]))[ok])
                                 for s in shifts]))]
    assert seen > 0.5e-3 and abs(lag - seen) < 0.5e-3 and lag > 3 * lag_se, (lag, lag_se, seen)
    assert any("later than its I-frames" in w for w in result.warnings), result.warnings
    p = result.parameters["dead_time_s"]
    assert p.holds(TRUTH["dead_time_s"]) and p.stderr >= lag
    # Raw footage: every frame is an I-frame, nothing to tell and nothing added.
    (raw,) = [t for label, t in identify(sweep_campaign, workers=1).tracks.items() if label.startswith("sweep")]
    assert codec_lag_s(raw) is None
