"""A recorded input (issue 31): a sweep test's ``input = "u.csv"``, a pilot's stick, identified like a chirp.

Oracle: the twin's truth (truth.json "model": K = 0.23, ωn = 37 rad/s, ζ = 0.65) for a piloted
sweep whose frequency and swing wander (simulate option ``piloted_sweep``); the file's own samples
for :meth:`TestSpec.command`. Small on purpose: 480×384 raw frames, one 8 s piloted sweep, no
dwell and no step.
"""

from __future__ import annotations

import json
import shutil
import tomllib

import numpy as np
import pytest

from servoscope.campaign.manifest import Campaign, TestSpec
from servoscope.campaign.recorded_input import input_band_hz, read_input_file
from servoscope.campaign.result import IdentificationResult
from servoscope.errors import ServoscopeError
from servoscope.simulate import InputSignal, simulate_campaign
from servoscope.simulate.pilot import pilot_input

from support import run_cli


@pytest.fixture(scope="module")
def piloted(tmp_path_factory):
    """The twin's piloted sweep 0.5–10 Hz over 8 s, a second of rest on each side; its manifest."""
    return simulate_campaign(tmp_path_factory.mktemp("piloted") / "c", "quick", 3, width=480, height=384,
                             codec="raw", frequencies_hz=(), include_step=False, piloted_sweep=(0.5, 10.0, 8.0),
                             pre_roll_s=1.0, settle_s=1.0)


def test_the_twin_writes_the_input_beside_the_video_and_names_it(piloted):
    entry, = tomllib.loads(piloted.read_text())["tests"]
    assert entry["kind"] == "sweep" and entry["input"] == "u.csv"
    assert not {"from_hz", "to_hz", "duration_s", "shape"} & set(entry)
    t, u = read_input_file(piloted.parent / "u.csv")
    assert t[0] == 0.0 and u[0] == 0.0 and abs(u[-1]) < 1e-12 and t[-1] == pytest.approx(8.0)
    assert entry["amplitude"] == pytest.approx(np.max(np.abs(u)))
    # The pilot's wander: the swing is not one amplitude (a chirp's would be).
    peaks = [np.max(np.abs(u[(t >= a) & (t < a + 1.0)])) for a in range(1, 7)]
    assert max(peaks) / min(peaks) > 1.2
    lo, hi = input_band_hz(t, u)
    assert 0.1 < lo <= 0.6 and 8.0 <= hi <= 12.0
    truth = json.loads((piloted.parent / "truth.json").read_text())
    assert truth["tests"][0]["input"] == "u.csv" and truth["tests"][0]["kind"] == "sweep"


def test_a_piloted_sweep_identifies_the_servo_through_the_command(piloted, tmp_path):
    out = tmp_path / "out"
    run = run_cli("identify", str(piloted), "--out", str(out), "--workers", "1")
    assert run.returncode == 0, run.stderr
    data = json.loads((out / "result.json").read_text())
    truth = json.loads((piloted.parent / "truth.json").read_text())["model"]
    for name in ("gain", "natural_frequency_rad_s", "damping_ratio"):
        lo, hi = data["model"]["ci95"][name]
        assert lo <= truth[name] <= hi, (name, data["model"][name], (lo, hi), truth[name])
    entry, = data["tests"]
    assert entry["input"] == str(piloted.parent / "u.csv")
    t, u = read_input_file(piloted.parent / "u.csv")
    assert entry["input_samples"]["command"] == u.tolist()
    lo, hi = entry["input_band_hz"]
    assert lo < 1.0 and hi > 8.0
    # The result keeps the samples: it loads (and draws its input) after the file has moved.
    shutil.move(piloted.parent / "u.csv", tmp_path / "u.csv")
    try:
        again = IdentificationResult.load(out)
        assert json.dumps(again.summary(), sort_keys=True) == json.dumps(data, sort_keys=True)
        test, = again.campaign.tests
    finally:
        shutil.move(tmp_path / "u.csv", piloted.parent / "u.csv")
    assert test.recorded and np.array_equal(test.input_command, u) and test.sweep_band_hz == (lo, hi)


BAD = {
    "missing": (None, "no such file"),
    "columns": ("t,u\n0,0\n1,1\n", "no time_s or command column"),
    "short": ("time_s,command\n0,0\n", "1 row(s) of samples: a recorded input needs at least 2"),
    "backwards": ("time_s,command\n0,0\n0.5,1\n0.5,2\n", "time_s is not strictly increasing"),
    "nan": ("time_s,command\n0,0\n0.5,nan\n1,0\n", "not finite"),
    "text": ("time_s,command\n0,0\n0.5,up\n", "row 3 has no number"),
    "negative": ("time_s,command\n-0.5,0\n0.5,1\n", "times are seconds after the input's start"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_a_bad_input_file_is_one_line_naming_it(piloted, case):
    text, message = BAD[case]
    folder = piloted.parent
    csv = folder / f"bad_{case}.csv"
    if text is not None:
        csv.write_text(text)
    manifest = folder / f"bad_{case}.toml"
    manifest.write_text(piloted.read_text().replace('input = "u.csv"', f'input = "bad_{case}.csv"'))
    run = run_cli("identify", str(manifest), "--out", str(folder / f"out_{case}"))
    assert run.returncode == 2
    line, = run.stderr.strip().splitlines()
    assert line.startswith("servoscope: error:") and "tests[1].input" in line and str(csv) in line, line
    assert message in line, line


def test_a_recorded_input_with_a_chirps_length_or_shape_is_refused(piloted):
    manifest = piloted.parent / "bad_duration.toml"
    manifest.write_text(piloted.read_text().replace('input = "u.csv"', 'input = "u.csv"\nduration_s = 8.0'))
    with pytest.raises(ServoscopeError, match=r"tests\[1\]\.duration_s: a recorded input \(u.csv\) has its own "
                                              r"length and shape: leave out duration_s"):
        Campaign.load(manifest, check_videos=False)


def test_only_a_sweep_takes_an_input_and_the_rig_refuses_one(piloted):
    manifest = piloted.parent / "bad_step.toml"
    manifest.write_text(piloted.read_text().replace('kind = "sweep"', 'kind = "step"'))
    with pytest.raises(ServoscopeError, match=r"only a sweep test \(kind = \"sweep\"\) has input"):
        Campaign.load(manifest, check_videos=False)
    plan = piloted.parent / "plan.toml"
    plan.write_text(piloted.read_text() + "\n[plan]\nfps = 100.0\n\n[[plan.dwells]]\nduration_s = 8.0\n")
    run = run_cli("drive", str(plan), "--port", "/dev/null-none")
    assert run.returncode == 2 and "servoscope drive plays sines, steps and chirps, not a recorded input" in run.stderr


def test_save_keeps_the_input_relative_to_the_new_manifest(piloted, tmp_path):
    campaign = Campaign.load(piloted, check_videos=False)
    saved = campaign.save(tmp_path / "elsewhere" / "campaign.toml")
    entry, = tomllib.loads(saved.read_text())["tests"]
    assert not entry["input"].startswith("/") and entry["input"].endswith("/c/u.csv")
    assert (saved.parent / entry["input"]).resolve() == (piloted.parent / "u.csv").resolve()
    again = Campaign.load(saved, check_videos=False)
    (a,), (b,) = campaign.tests, again.tests
    assert a == b and a.input_file == piloted.parent / "u.csv"
    assert np.array_equal(a.input_time_s, b.input_time_s) and np.array_equal(a.input_command, b.input_command)
    # A band given in the manifest is the band analysed, and is written back.
    banded = campaign.save(tmp_path / "banded.toml").read_text()
    banded = banded.replace('input = ', 'from_hz = 1.0\nto_hz = 6.0\ninput = ')
    (tmp_path / "banded.toml").write_text(banded)
    test, = Campaign.load(tmp_path / "banded.toml", check_videos=False).tests
    assert test.sweep_band_hz == (1.0, 6.0) and test.highest_frequency_hz == 6.0
    entry, = tomllib.loads(Campaign.load(tmp_path / "banded.toml", check_videos=False).to_toml())["tests"]
    assert (entry["from_hz"], entry["to_hz"]) == (1.0, 6.0)


def test_the_command_is_the_files_samples_joined_by_straight_lines(tmp_path):
    t = np.array([0.1, 0.3, 0.4, 1.0])
    u = np.array([0.5, -1.0, 2.0, 0.25])
    spec = TestSpec(None, "sweep", 2.0, input_file=tmp_path / "u.csv", input_time_s=t, input_command=u)
    assert np.array_equal(spec.command(t), u)
    assert spec.command(np.array([0.2, 0.35]))[0] == pytest.approx(-0.25)
    assert spec.command(np.array([0.35]))[0] == pytest.approx(0.5)
    # 0 before the start (the LED dates it), the first value from the start on, the last after the end.
    assert list(spec.command(np.array([-0.01, 0.0, 0.05, 1.5, 9.0]))) == [0.0, 0.5, 0.5, 0.25, 0.25]
    assert spec.input_duration_s == 1.0 and spec.recorded
    # The twin's servo sees the same command.
    signal = InputSignal("recorded", 2.0, t0_s=3.0, samples=(t, u))
    times = np.linspace(2.5, 5.0, 101)
    assert np.array_equal(signal.value(times), spec.command(times - 3.0))


def test_the_pilot_is_seeded_and_starts_from_rest():
    a, b, c = (pilot_input(0.5, 10.0, 4.0, 0.2, s) for s in (1, 1, 2))
    assert np.array_equal(a[1], b[1]) and not np.array_equal(a[1], c[1])
    assert a[1][0] == 0.0 and np.all(np.abs(a[1]) <= 0.2 * 2.0)
    with pytest.raises(ServoscopeError):
        InputSignal("recorded", 1.0, samples=(np.array([0.0, 0.0]), np.array([1.0, 2.0])))
