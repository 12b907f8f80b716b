"""One campaign file format (issue 30): Campaign.to_toml / save, read back equal; the twin's and rig's bytes kept.

Fast: no video is rendered (the twin's render_test is replaced by one that returns the test's
input), and manifests are read with check_videos=False.
"""

from __future__ import annotations

import json
import tomllib
from dataclasses import replace
from pathlib import Path

import pytest

import servoscope.simulate.campaign as twin
from servoscope.campaign.manifest import Campaign, TestSpec, campaign_from_data
from servoscope.errors import ServoscopeError
from servoscope.rig.plan import plan_sweep, plan_to_toml, read_plan, with_videos, write_plan
from servoscope.simulate.presets import PRESETS

BEFORE = json.loads((Path(__file__).parents[1] / "data" / "campaign_toml_before.json").read_text())["texts"]

#: The twin's variants the fixture holds (preset + these overrides), by suffix.
VARIANTS = {
    "": {},
    "+tiff": dict(frames_format="tiff16"),
    "+mraw-mono": dict(frames_format="mraw", monochrome=True, bit_depth=12),
    "+ref-extra-ts-ro": dict(reference_stickers=True, extra_stickers=(("#1f77b4", 0.3),), timestamp_at="start",
                             readout_s=0.004, exposure_s=0.002, manifest_exposure=True),
}
TWINS = sorted(key.removeprefix("twin-") for key in BEFORE if key.startswith("twin-"))


def _rig_plans():
    """The rig's plans the fixture holds, by name."""
    driven = replace(with_videos(plan_sweep(100, 2, 2, points=1), ["dwell_01_2.00Hz.mp4", "step.mp4"]),
                     settle_auto=True, drive={"protocol": "maestro", "channel": 0, "led_channel": -1,
                                              "center_us": 1500.0, "us_per_unit": 500.0, "log": "drive_log.csv"})
    driven = replace(driven, dwells=tuple(replace(d, max_late_ms=1.25, label="a" if i == 0 else None)
                                          for i, d in enumerate(driven.dwells)))
    return {
        "default": plan_sweep(120, 0.5, 15, points=5),
        "amps-markers": plan_sweep(100, 1, 10, points=3, amplitudes=[0.1, 0.2], settle_s=0.75,
                                   markers={"lead": "red", "trail": "#00ff00", "led": "#ffd400"}, units='deg "x"\\y'),
        "nostep": plan_sweep(30, 1, 12, points=4, step=False),
        "driven": driven,
    }


@pytest.fixture
def no_render(monkeypatch):
    """simulate_campaign without footage: each test's record is its input; no truth.json series, no board photo."""
    def fake_render(path, preset, scene, signal, duration_s, noise_seed):
        rec = {"kind": signal.kind}
        if signal.kind == "sine":
            rec["frequency_hz"] = signal.frequency_hz
        elif signal.kind == "sweep":
            rec.update(from_hz=signal.from_hz, to_hz=signal.to_hz, duration_s=signal.duration_s, shape=signal.shape)
        rec["amplitude"] = signal.amplitude
        return rec

    built = []
    real = twin.twin_campaign

    def keep(*args, **kwargs):
        built.append(real(*args, **kwargs))
        return built[-1]

    monkeypatch.setattr(twin, "render_test", fake_render)
    monkeypatch.setattr(twin, "_truth", lambda *a, **k: {})
    monkeypatch.setattr(twin, "_write_board", lambda *a, **k: {})
    monkeypatch.setattr(twin, "twin_campaign", keep)
    return built


def _twin(tmp_path: Path, name: str, no_render) -> tuple[Path, Campaign]:
    preset, _, variant = name.partition("+")
    path = twin.simulate_campaign(tmp_path / "twin", preset, seed=3, **VARIANTS["+" + variant if variant else ""])
    return path, no_render[-1]


@pytest.mark.parametrize("name", TWINS)
def test_the_twins_campaign_toml_is_byte_for_byte_the_old_writers(tmp_path, no_render, name):
    path, _ = _twin(tmp_path, name, no_render)
    assert path.read_text() == BEFORE[f"twin-{name}"]


@pytest.mark.parametrize("name", sorted(_rig_plans()))
def test_the_rigs_plan_is_byte_for_byte_the_old_writers(tmp_path, name):
    plan = _rig_plans()[name]
    assert plan_to_toml(plan) == BEFORE[f"rig-{name}"]
    assert plan_to_toml(plan, include_plan=False) == BEFORE[f"rig-{name}-bare"]
    assert write_plan(plan, tmp_path / "p.toml").read_text() == BEFORE[f"rig-{name}"]
    assert read_plan(tmp_path / "p.toml") == plan


@pytest.mark.parametrize("preset", sorted(PRESETS))
def test_every_presets_campaign_round_trips(tmp_path, no_render, preset):
    path, built = _twin(tmp_path, preset, no_render)
    loaded = Campaign.load(path, check_videos=False)
    assert loaded == built  # what the twin meant is what the file says
    assert loaded.camera is not None and loaded.camera_file == (path.parent / "camera.json").resolve()
    again = Campaign.load(loaded.save(tmp_path / "copy" / "campaign.toml"), check_videos=False)
    assert again == loaded  # another folder: paths written relative to it name the same files
    # Saved where it was read: the same text, less the twin's comment line.
    assert Campaign.load(loaded.save(), check_videos=False) == loaded
    if f"twin-{preset}" in BEFORE:  # presets newer than the old writers (paper-sweep) have no old bytes
        assert path.read_text() == BEFORE[f"twin-{preset}"].split("\n", 1)[1]


@pytest.mark.parametrize("variant", ["+tiff", "+mraw-mono", "+ref-extra-ts-ro"])
def test_frame_sources_and_camera_options_round_trip(tmp_path, no_render, variant):
    path, built = _twin(tmp_path, "quick" + variant, no_render)
    loaded = Campaign.load(path, check_videos=False)
    assert loaded == built
    assert Campaign.load(loaded.save(tmp_path / "elsewhere.toml"), check_videos=False) == loaded


def test_a_rig_plan_round_trips_as_a_campaign(tmp_path):
    for name, plan in _rig_plans().items():
        path = write_plan(plan, tmp_path / name / "plan.toml")
        c = Campaign.load(path, check_videos=False, planned=True)
        assert c.plan["dwells"] and c.plan["fps"] == plan.fps
        back = Campaign.load(c.save(tmp_path / name / "again.toml"), check_videos=False, planned=True)
        assert back == c
        # The same text, less the plan's comment line and the blank line after it.
        assert (tmp_path / name / "again.toml").read_text() == path.read_text().split("\n", 2)[2]


def test_everything_a_campaign_holds_round_trips(tmp_path):
    """Pinned markers, reference and extra stickers, model fix/bound/tie, settle "auto", t0, labels, frames options."""
    (tmp_path / "rec").mkdir()
    text = '''[camera]
calibration = "cal/camera.json"
exposure_s = 0.001
timestamp = "end"
readout_s = 0.002
plane = "plane.json"

[markers]
lead = {colour = "#d62728", near = [10.5, 20.0]}
trail = {brightness = "dark", near = [30.0, 40.0]}
led = {colour = "#ffd400", near = [1.0, 2.0]}
reference = ["#e377c2", "#17becf"]
extra = ["#1f77b4", "#9467bd"]

[input]
units = "deg"

[analysis]
settle_s = "auto"

[model]
fix = {damping_ratio = 0.8}
bound = {natural_frequency_rad_s = [20.0, 80.0]}
tie = {rate_limit_rad_s = "4*gain"}

[[tests]]
video = "sub/a.mp4"
label = "first"
kind = "sine"
frequency_hz = 1.5
amplitude = 0.2
t0_s = 0.25

[[tests]]
frames = "rec/*.tif"
fps = 2000.0
start_s = 0.5
timestamps = "rec/times.txt"
bayer = "RGGB"
bits = 12
kind = "step"
amplitude = -0.5

[plan]
fps = 2000.0
note = "kept as written"
'''
    path = tmp_path / "campaign.toml"
    c = campaign_from_data(tomllib.loads(text), path, check_videos=False, read_files=False)
    assert c.lead_near == (10.5, 20.0) and c.trail == "dark" and c.model_ties == {"rate_limit_rad_s": "4*gain"}
    assert c.tests[1].frames and c.tests[1].label == "rec" and c.settle_s == "auto"
    assert c.to_toml() == text
    out = tmp_path / "deeper" / "campaign.toml"
    moved = replace(c, path=out)
    assert campaign_from_data(tomllib.loads(moved.to_toml()), out, check_videos=False, read_files=False) == c
    assert 'video = "../sub/a.mp4"' in moved.to_toml()


def test_a_campaign_whose_camera_has_no_file_is_not_saved_without_it(tmp_path):
    c = Campaign(path=tmp_path / "campaign.toml", lead="red", trail="green", led=None, camera=object(),
                 exposure_s=None, input_units="normalized", settle_s=0.5,
                 tests=(TestSpec(tmp_path / "a.mp4", "step", 1.0),))
    with pytest.raises(ServoscopeError, match="calibration"):
        c.to_toml()


def test_read_plan_reports_every_problem_at_once(tmp_path):
    text = plan_to_toml(plan_sweep(100, 1, 2, points=2))
    text = (text.replace("fps = 100.0", "fps = -1.0").replace('kind = "step"', 'kind = "ramp"')
            .replace("lead_in_s = 1.0", "lead_in_s = 1.0\nspeed = 3", 1)
            .replace("[input]", "[input]\nunit = 1", 1))
    text = text[: text.rindex("[[plan.dwells]]")]  # one dwell short
    bad = tmp_path / "bad.toml"
    bad.write_text(text)
    with pytest.raises(ServoscopeError) as err:
        read_plan(bad)
    message = str(err.value)
    for where in ("problems", "input.unit: unknown key", "tests[3].kind", "plan.speed: unknown key",
                  "plan.fps: must be > 0", "one entry per [[tests]] (3)"):
        assert where in message, (where, message)
    assert message.startswith(f"{bad}: ")


def test_sweep_tests_round_trip_and_add_keys_only_to_sweeps(tmp_path):
    """Issue 31: a sweep test's from_hz, to_hz, duration_s and shape are written and read back; the other
    tests' tables keep their keys (the byte-identity fixtures above hold them)."""
    sweep = dict(from_hz=0.5, to_hz=15.0, duration_s=12.0)
    c = Campaign(path=tmp_path / "campaign.toml", lead="red", trail="green", led="#ffd400", camera=None,
                 exposure_s=None, input_units="normalized", settle_s=0.5,
                 tests=(TestSpec(tmp_path / "a.mp4", "sine", 0.1, 2.0, label="a"),
                        TestSpec(tmp_path / "s.mp4", "sweep", 0.1, label="s", shape="log", **sweep),
                        TestSpec(tmp_path / "l.mp4", "sweep", 0.2, t0_s=1.25, label="fast", shape="linear", **sweep),
                        TestSpec(tmp_path / "b.mp4", "step", 0.5, label="b")))
    text = c.to_toml()
    assert ('[[tests]]\nvideo = "s.mp4"\nkind = "sweep"\nfrom_hz = 0.5\nto_hz = 15.0\nduration_s = 12.0\n'
            'shape = "log"\namplitude = 0.1\n') in text
    assert '[[tests]]\nvideo = "a.mp4"\nkind = "sine"\nfrequency_hz = 2.0\namplitude = 0.1\n' in text
    assert '[[tests]]\nvideo = "b.mp4"\nkind = "step"\namplitude = 0.5\n' in text
    back = Campaign.load(c.save(), check_videos=False)
    assert back == c and [t.label for t in back.sweep_tests] == ["s", "fast"]
    assert Campaign.load(back.save(tmp_path / "elsewhere" / "c.toml"), check_videos=False) == c
    # A sweep without a shape is a logarithmic one.
    data = tomllib.loads(text.replace('shape = "log"\n', ""))
    assert campaign_from_data(data, c.path, check_videos=False) == c
