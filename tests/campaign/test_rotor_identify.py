"""A turning rotor's campaign identified end to end (issue 33): `servoscope identify` on the twin's footage.

One small campaign, rendered once: the paper's servo on two blades at 20 rev/s, a monochrome high-speed
camera's 12-bit MRAW at 2,000 frames/s (passes of ~6 frames), three dwells up to 70 % of the passes'
Nyquist frequency (14 Hz of 20) and a step, blade 1 rigged 0.2° above blade 0. Settings other than the
preset's (frame rate, dwells, camera): the tracker must not lean on the preset it was built beside.
The command runs once, ``--beside`` the session's static quick campaign, so the report's "Under rotation"
(the passes drawn on a frame, the response beside the static one) is checked on the same run; a short
colour clip checks the frame figure on colour footage. The figure's marks are held to the twin's own
sticker centres (its geometry, not the tracker), the comparison's numbers to the two result.json files.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from support import cli


@pytest.fixture(scope="module")
def rotor_campaign(tmp_path_factory):
    from servoscope.simulate import simulate_campaign

    return simulate_campaign(tmp_path_factory.mktemp("rotor") / "c", "paper-rotor", 5, monochrome=True, fps=2000,
                             frequencies_hz=(3.0, 8.0, 14.0), min_dwell_s=0.6)


@pytest.fixture(scope="module")
def static_out(quick_result, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("static") / "out"
    quick_result.write(out)
    return out


@pytest.fixture(scope="module")
def identified(rotor_campaign, static_out, tmp_path_factory):
    import contextlib
    import io

    from servoscope.cli import main

    out = tmp_path_factory.mktemp("rotor_out") / "out"
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        try:
            main(["identify", str(rotor_campaign), "--out", str(out), "--beside", str(static_out / "result.json")])
            code = 0
        except SystemExit as exc:
            code = int(exc.code or 0)
    return code, stdout.getvalue(), stderr.getvalue(), out


def test_the_command_identifies_the_servo_from_the_passes(rotor_campaign, identified):
    code, stdout, stderr, out = identified
    assert code == 0, stderr
    truth = json.loads((rotor_campaign.parent / "truth.json").read_text())["model"]
    result = json.loads((out / "result.json").read_text())
    params = result["model"]["parameters"]
    for name, rel in (("gain", 0.01), ("natural_frequency_rad_s", 0.01), ("damping_ratio", 0.03)):
        p = params[name]
        assert p["value"] == pytest.approx(truth[name], rel=rel), (name, p)
        assert p["ci95"][0] <= truth[name] <= p["ci95"][1], (name, p)
    tau = params["dead_time_s"]
    assert abs(tau["value"] - truth["dead_time_s"]) < 1e-3
    assert tau["ci95"][0] <= truth["dead_time_s"] <= tau["ci95"][1]
    assert "gain K" in stdout and "report:" in stdout
    # The passes' pitch scale (monochrome: 0.5 %) is in the gain's error: at least that much of it.
    from servoscope.campaign.rotor import ROTOR_SCALE_STDERR_MONO

    assert params["gain"]["stderr"] >= ROTOR_SCALE_STDERR_MONO * params["gain"]["value"]


def test_result_json_states_the_rotor_and_the_report_shows_it(rotor_campaign, identified):
    code, _, stderr, out = identified
    assert code == 0, stderr
    truth = json.loads((rotor_campaign.parent / "truth.json").read_text())
    result = json.loads((out / "result.json").read_text())
    rotor = result["rotor"]
    assert len(rotor["blades"]) == 2 and [t["label"] for t in rotor["tests"]] == [t["label"] for t in result["tests"]]
    from servoscope.markers.track import Track
    from servoscope.simulate.rotor_campaign import rotor_rig_of_test

    for i, (entry, test) in enumerate(zip(rotor["tests"], truth["tests"])):
        # The rotor's mean speed over the passes tracked (the tracks' samples are the passes), as the rig turned.
        passes = Track.from_csv(out / "tracks" / f"{entry['label']}.csv").time_s
        rig = rotor_rig_of_test(truth, i)
        assert entry["rev_per_s"] == pytest.approx(rig.mean_rev_per_s(float(passes[0]), float(passes[-1])), rel=1e-4)
        # At 2,000 frames/s a pass shows 6-7 frames, and one with fewer than 4 whole ones is left out:
        # about half are (docs/rotor.md); the rest carry the identification above.
        assert entry["passes"] >= 0.4 * len(test["passes"])
    # Monochrome footage tells the blades apart by their order only: blade 0 is each video's first seen (which
    # the passes kept do not say), so the rigging difference is ±0.2°, and it is not pooled over the videos.
    assert rotor["identified_by"] == "order" and rotor["blade_differences"] == []
    # The pitch's scale uncertainty the gain's interval carries, and why (monochrome: 0.5 %).
    from servoscope.campaign.rotor import ROTOR_AMPLITUDE_STDERR_MONO_RAD, ROTOR_SCALE_STDERR_MONO

    assert rotor["systematic"]["pitch_scale_relative_stderr"] == ROTOR_SCALE_STDERR_MONO
    assert rotor["systematic"]["dwell_amplitude_stderr_rad"] == ROTOR_AMPLITUDE_STDERR_MONO_RAD
    assert "monochrome" in rotor["systematic"]["why"]
    # Each dwell's amplitude error carries it (at least that much).
    dwell_fits = [t["sine_fit"] for t in result["tests"] if t.get("sine_fit")]
    assert len(dwell_fits) == 3
    assert all(f["amplitude_stderr"] >= ROTOR_AMPLITUDE_STDERR_MONO_RAD for f in dwell_fits)
    dwells = [entry for entry in rotor["tests"] if "blade_differences" in entry]
    assert len(dwells) == 3
    for entry in dwells:
        (difference,) = entry["blade_differences"]
        want = math.copysign(math.radians(0.2), difference["difference_rad"])
        assert abs(difference["difference_rad"] - want) < math.radians(0.03), (entry["label"], difference)
        assert difference["ci95_rad"][0] <= want <= difference["ci95_rad"][1], (entry["label"], difference)
        # Each blade's constant bias (its stickers cross the same rows every revolution) is in it: √2 of it.
        assert difference["difference_stderr_rad"] >= math.sqrt(2) * ROTOR_AMPLITUDE_STDERR_MONO_RAD
    html = (out / "report.html").read_text()
    assert "Under rotation" in html and "rotor speed (rev/s)" in html
    # The saved result loads back with its rotor and its pass fits.
    from servoscope.campaign import IdentificationResult
    from servoscope.sysid.pass_result import PassSineFit

    loaded = IdentificationResult.load(out)
    assert loaded.rotor == result["rotor"]
    assert all(isinstance(f, PassSineFit) for f in loaded.sine_fits.values())
    assert loaded.summary()["model"]["parameters"] == result["model"]["parameters"]


def test_the_pitch_scale_follows_the_footage(rotor_campaign, quick_campaign, tmp_path):
    """Colour footage (chroma at half resolution; a codec) states the larger pitch-scale uncertainty, a static
    campaign none: the gain's interval carries what the twin measured of each (docs/rotor.md)."""
    from servoscope.campaign import load_campaign
    from servoscope.campaign.rotor import (ROTOR_AMPLITUDE_STDERR_COLOUR_RAD, ROTOR_AMPLITUDE_STDERR_MONO_RAD,
                                           ROTOR_SCALE_STDERR_COLOUR, ROTOR_SCALE_STDERR_MONO, codec_warning,
                                           rotor_scale_error, rotor_systematics)
    from servoscope.video.writer import VideoWriter

    mono = load_campaign(rotor_campaign)
    assert rotor_scale_error(mono)[0] == ROTOR_SCALE_STDERR_MONO and codec_warning(mono) is None
    clip = tmp_path / "colour.mp4"
    with VideoWriter(clip, 64, 48, 4000) as writer:
        for k in range(4):
            writer.write(np.full((48, 64, 3), 40 * k, np.uint8))
    colour = replace(mono, rotor=replace(mono.rotor, blades=(("#d62728", "#2ca02c"), ("#1f77b4", "#ff7f0e"))),
                     tests=tuple(replace(t, video=clip) for t in mono.tests))
    sigma, why = rotor_scale_error(colour)
    assert sigma == ROTOR_SCALE_STDERR_COLOUR > ROTOR_SCALE_STDERR_MONO and "h264-compressed colour" in why
    assert rotor_systematics(colour).amplitude_stderr_rad == ROTOR_AMPLITUDE_STDERR_COLOUR_RAD \
        > rotor_systematics(mono).amplitude_stderr_rad == ROTOR_AMPLITUDE_STDERR_MONO_RAD
    assert "h264" in codec_warning(colour) and "±1.3 %" in codec_warning(colour)
    assert rotor_scale_error(load_campaign(quick_campaign)) is None


def test_a_rotor_whose_colours_are_never_seen_is_one_clear_error(rotor_campaign, tmp_path, capsys):
    text = rotor_campaign.read_text()
    toml = rotor_campaign.parent / "wrong_colours.toml"
    start = text.index("[rotor]")
    line_end = text.index("\n", text.index("blades", start))
    toml.write_text(text[:text.index("blades", start)] + 'blades = [{lead = "#00c8ff", trail = "#ff00c8"}]'
                    + text[line_end:])
    code, out, err = cli(capsys, "identify", toml, "--out", tmp_path / "o")
    assert code == 2
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("servoscope: error: "), err
    assert not (tmp_path / "o" / "result.json").exists()


# --- The report's "Under rotation": a pass on its frames, beside a static campaign -----------------------

EXPOSURE_S = 1 / 40000


def _truth_centres(rig, view, blade: int, pitch_rad: float, width: int, height: int):
    """The twin's sticker centres at each frame of the view (its geometry at the frames' times)."""
    psi = rig.azimuth_rad(view.time_s, blade)
    return rig.sticker_centres_px(psi, np.full(psi.shape, pitch_rad), width, height)


def _check_marks_on_truth(view, fig, rig, true_blade: int, true_pitch_rad: float, width: int, height: int, *,
                          foreshortened: bool = False):
    lead, trail = _truth_centres(rig, view, true_blade, true_pitch_rad, width, height)
    whole = view.whole
    assert whole.sum() >= 4
    # Every measured centroid of the pass on the twin's sticker centre (the tracker's sub-pixel accuracy).
    assert np.max(np.abs(view.lead_xy_px[whole] - lead[whole])) < 0.5
    assert np.max(np.abs(view.trail_xy_px[whole] - trail[whole])) < 0.5
    # The figure draws the drawn frame's marks there.
    k = view.drawn
    for gid, xy in (("drawn-lead", lead[k]), ("drawn-trail", trail[k])):
        (mark,) = [a for a in fig.findobj() if getattr(a, "get_gid", lambda: None)() == gid]
        assert np.hypot(mark.get_xdata()[0] - xy[0], mark.get_ydata()[0] - xy[1]) < 0.5, gid
    # Its azimuth is the frame's nearest ψ = 0, as the rig turned (the crossing is read ~80 µs late: 0.6°).
    true_psi = math.remainder(float(rig.azimuth_rad(view.time_s[k], true_blade)), 2 * math.pi)
    assert abs(view.azimuth_rad[k] - true_psi) < math.radians(1.0)
    assert abs(view.azimuth_rad[k]) == pytest.approx(np.min(np.abs(view.azimuth_rad[whole])))
    assert abs(view.pitch_rad - true_pitch_rad) < math.radians(0.06)
    if foreshortened:
        # The foreshortening the fit removes, on the twin's own stickers (its geometry, free of the tracker's
        # noise): their line overstates the pitch away from ψ = 0, and the figure's correction (the fitted k,
        # the fitted ψ) takes it out; the measured line follows the twin's.
        from servoscope.angle.geometry import angle_rad_from_centroids
        from servoscope.angle.passes import foreshortening

        phi_true = angle_rad_from_centroids(lead, trail)
        corrected = np.arctan(np.tan(phi_true) / foreshortening(view.azimuth_rad, view.foreshortening_k))
        assert np.max(phi_true[whole] - true_pitch_rad) > math.radians(0.08)
        assert np.max(np.abs(corrected[whole] - true_pitch_rad)) < math.radians(0.02)
        assert np.max(np.abs(view.image_angle_rad[whole] - phi_true[whole])) < math.radians(0.1)


def test_the_pass_on_a_colour_frame_marks_the_stickers(tmp_path):
    from servoscope.markers.settings import TrackerSettings
    from servoscope.report.rotor_frame import pass_frame_figure, pass_on_frame
    from servoscope.simulate.rotor import ROTOR_BLADE_COLOURS, RotorRig
    from servoscope.simulate.rotor_render import render_rotor_clip

    rig = RotorRig(blades=ROTOR_BLADE_COLOURS[:2], rev_per_s=20.0, azimuth0_rad=0.4)
    pitch = math.radians(5.0)  # a steady collective: the foreshortening shows plainly
    truth = render_rotor_clip(tmp_path / "clip.mp4", rig, lambda t: np.full(np.shape(t), pitch), duration_s=0.12,
                              fps=4000, exposure_s=EXPOSURE_S, width=320, height=160, noise_seed=4)
    view = pass_on_frame(tmp_path / "clip.mp4", ROTOR_BLADE_COLOURS[:2], TrackerSettings(exposure_s=EXPOSURE_S))
    fig = pass_frame_figure(view)
    _check_marks_on_truth(view, fig, rig, view.blade, pitch, 320, 160, foreshortened=True)
    assert len(truth["passes"]) >= 4 and view.rgb.shape[1:] == (160, 320, 3)
    fig.savefig(tmp_path / "pass.png", dpi=60)
    assert (tmp_path / "pass.png").stat().st_size > 5000


def test_the_command_puts_the_frame_and_the_static_campaign_in_the_report(rotor_campaign, identified, static_out):
    code, stdout, stderr, out = identified
    assert code == 0, stderr
    html = (out / "report.html").read_text()
    part = html[html.index("Under rotation"):]
    assert 'alt="A pass drawn on its frames"' in part
    assert 'alt="Frequency response static and under rotation"' in part
    assert "Beside the static campaign" in part and "natural frequency ωn (rad/s)" in part
    assert (out / "figures" / "rotor_pass_frame.png").stat().st_size > 5000
    assert "beside the static campaign" in stdout and "z " in stdout
    # The report's frame, rebuilt here: its marks on the twin's stickers (monochrome: blades by their order).
    from servoscope.campaign import load_campaign
    from servoscope.markers.settings import TrackerSettings
    from servoscope.report.rotor_frame import pass_frame_figure, pass_on_frame
    from servoscope.simulate.rotor_campaign import rotor_rig_of_test

    truth = json.loads((rotor_campaign.parent / "truth.json").read_text())
    campaign = load_campaign(rotor_campaign)
    i = max(range(len(campaign.tests)), key=lambda i: campaign.tests[i].frequency_hz or 0)
    view = pass_on_frame(campaign.tests[i].video, campaign.rotor,
                         TrackerSettings(led=campaign.led, exposure_s=campaign.exposure_s))
    rig = rotor_rig_of_test(truth, i)
    true_pass = min(truth["tests"][i]["passes"], key=lambda p: abs(p["time_s"] - view.pass_time_s))
    assert abs(true_pass["time_s"] - view.pass_time_s) < 2e-4
    _check_marks_on_truth(view, pass_frame_figure(view), rig, true_pass["blade"], true_pass["pitch_rad"],
                          truth["video"]["width"], truth["video"]["height"])


def test_the_comparison_is_the_two_results_parameters(identified, static_out):
    code, _, stderr, out = identified
    assert code == 0, stderr
    rotating = json.loads((out / "result.json").read_text())
    static = json.loads((static_out / "result.json").read_text())
    recorded = rotating["rotor"]["beside_static"]
    assert recorded["static_result"] == str((static_out / "result.json").resolve())
    names = ["gain", "natural_frequency_rad_s", "damping_ratio", "dead_time_s"]
    assert [p["name"] for p in recorded["parameters"]] == names
    for p in recorded["parameters"]:
        s, r = static["model"]["parameters"][p["name"]], rotating["model"]["parameters"][p["name"]]
        assert (p["static"], p["static_stderr"], p["static_ci95"]) == (s["value"], s["stderr"], s["ci95"])
        assert (p["rotating"], p["rotating_stderr"], p["rotating_ci95"]) == (r["value"], r["stderr"], r["ci95"])
        assert p["difference"] == pytest.approx(r["value"] - s["value"], rel=1e-12)
        assert p["difference_stderr"] == pytest.approx(math.hypot(r["stderr"], s["stderr"]), rel=1e-12)
        assert p["z"] == pytest.approx(p["difference"] / p["difference_stderr"], rel=1e-12)
        assert p["differs"] == (abs(p["z"]) > 1.96)
    # The notebook's numbers are the report's: the API on the two saved results.
    from servoscope.campaign import IdentificationResult
    from servoscope.campaign.compare import compare_results

    api = compare_results(IdentificationResult.load(static_out), IdentificationResult.load(out),
                          static_path=static_out)
    assert api.summary()["static_result"] == recorded["static_result"]
    for mine, theirs in zip(api.summary()["parameters"], recorded["parameters"]):
        for key in ("static", "rotating", "difference", "difference_stderr", "z"):
            assert mine[key] == pytest.approx(theirs[key], rel=1e-9, abs=1e-15), (mine["name"], key)
    table = api.to_pandas()
    assert list(table.index) == names
    assert table.loc["gain", "static"] == pytest.approx(recorded["parameters"][0]["static"])
    with pytest.raises(Exception, match="turning rotor's result"):
        compare_results(IdentificationResult.load(out), IdentificationResult.load(static_out))


def test_a_report_whose_footage_is_gone_says_so(identified, tmp_path):
    code, _, stderr, out = identified
    assert code == 0, stderr
    from servoscope.campaign import IdentificationResult
    from servoscope.report.rotor_section import rotor_section

    loaded = IdentificationResult.load(out)
    gone = replace(loaded, campaign=replace(loaded.campaign, path=tmp_path / "moved" / "campaign.toml",
                                            tests=tuple(replace(t, video=tmp_path / "moved" / t.video.name)
                                                        for t in loaded.campaign.tests)))
    html = "".join(rotor_section(gone, None).html_parts)
    assert "The passes drawn on a frame are left out" in html
    assert "Beside the static campaign" in html  # the comparison was recorded: it stays


@pytest.mark.parametrize("case", ["missing", "not json", "rotor result", "static campaign"])
def test_a_bad_beside_is_one_line_before_any_tracking(case, rotor_campaign, identified, quick_campaign, tmp_path,
                                                      capsys):
    campaign, beside = rotor_campaign, tmp_path / "nothing" / "result.json"
    if case == "not json":
        beside = tmp_path / "result.json"
        beside.write_text("servoscope? no\n")
    elif case == "rotor result":
        beside = identified[3] / "result.json"
    elif case == "static campaign":
        campaign, beside = quick_campaign, identified[3] / "result.json"
    code, _, err = cli(capsys, "identify", campaign, "--out", tmp_path / "o", "--beside", beside)
    assert code == 2
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("servoscope: error: "), err
    assert ("--beside" in lines[0]) and (str(beside) in lines[0] or str(campaign) in lines[0]), lines[0]
    assert not (tmp_path / "o").exists()  # refused before the output folder, before any tracking
