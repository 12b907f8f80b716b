"""campaign.toml's ``[rotor]`` (issue 33): read, written back, and its mistakes named in one clear error."""

from __future__ import annotations

import pytest

from servoscope.campaign.manifest import Campaign, RotorSpec
from servoscope.errors import ServoscopeError

HEAD = """[markers]
lead = "#d62728"
trail = "#2ca02c"
led = "#ffd400"
"""
TESTS = """
[input]
units = "normalized"

[[tests]]
video = "rotor_dwell_01_14.00Hz.mp4"
kind = "sine"
frequency_hz = 14.0
amplitude = 0.1
"""
ROTOR = """
[rotor]
blades = [{lead = "#d62728", trail = "#2ca02c"}, {lead = "#1d4fd8", trail = "#c81dd8"}]
rev_per_s = 20.0
camera_distance_m = 0.62
tip_radius_m = 0.3
"""


def write(tmp_path, text: str, name: str = "campaign.toml"):
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_rotor_round_trips(tmp_path):
    """[rotor] reads to a RotorSpec, writes back to the same text, and reads back to an equal campaign."""
    text = HEAD + ROTOR + TESTS
    c = Campaign.load(write(tmp_path, text), check_videos=False)
    assert c.rotor == RotorSpec(blades=(("#d62728", "#2ca02c"), ("#1d4fd8", "#c81dd8")), rev_per_s=20.0,
                                camera_distance_m=0.62, tip_radius_m=0.3)
    assert c.to_toml() == text
    again = Campaign.load(c.save(tmp_path / "again" / "campaign.toml"), check_videos=False)
    assert again == c and again.rotor == c.rotor


def test_rotor_optional_numbers(tmp_path):
    """Only the blades are needed: the speed (measured from the passes), distance and radius may be left out."""
    text = HEAD + '\n[rotor]\nblades = [{lead = "red", trail = "lime"}, {lead = "blue", trail = "magenta"}, ' \
                  '{lead = "cyan", trail = "orange"}]\n' + TESTS
    c = Campaign.load(write(tmp_path, text), check_videos=False)
    assert len(c.rotor.blades) == 3 and c.rotor.rev_per_s is None and c.rotor.tip_radius_m is None
    assert c.to_toml() == text


def test_static_campaign_has_no_rotor(tmp_path):
    """A static campaign: rotor None, and its text says no [rotor]."""
    c = Campaign.load(write(tmp_path, HEAD + TESTS), check_videos=False)
    assert c.rotor is None
    assert "[rotor]" not in c.to_toml() and c.to_toml() == HEAD + TESTS


@pytest.mark.parametrize("rotor, says", [
    ('[rotor]\nblades = [{lead = "#d62728", trail = "#2ca02c"}]\nrev_per_sec = 20.0\n',
     "rotor.rev_per_sec: unknown key (did you mean 'rev_per_s'?)"),
    ('[rotor]\nblades = [{lead = "#d62728", trail = "#2ca02c"}, {lead = "#1d4fd8"}]\n',
     "rotor.blades[1].trail: missing: give blade 1's trail sticker's colour"),
    ('[rotor]\nblades = [{lead = "#d62728", trail = "#2ca02c"}, {lead = "#1d4fd8", trail = "#d62728"}]\n',
     "rotor.blades[1].trail: #d62728 is also blades[0].lead's colour"),
    ('[rotor]\nblades = [{lead = "#d62728", trail = "auto"}]\n', "rotor.blades[0].trail: must be a colour"),
    ('[rotor]\nblades = [{lead = "#d62728", trail = "#2ca02c", lag = "#000000"}]\n',
     "rotor.blades[0].lag: unknown key"),
    ('[rotor]\nrev_per_s = 20.0\n', "rotor.blades: missing"),
    ('[rotor]\nblades = [{lead = "#d62728", trail = "#2ca02c"}]\nrev_per_s = -3\n', "rotor.rev_per_s: must be > 0"),
    ('[rotor]\nblades = [{lead = "#d62728", trail = "#2ca02c"}]\ncamera_distance_m = 0.2\ntip_radius_m = 0.3\n',
     "rotor.tip_radius_m: must be less than camera_distance_m"),
])
def test_rotor_mistakes_one_clear_error(tmp_path, rotor, says):
    """Each mistake is one line naming the file, the key and what to do."""
    path = write(tmp_path, HEAD + "\n" + rotor + TESTS)
    with pytest.raises(ServoscopeError) as err:
        Campaign.load(path, check_videos=False)
    message = str(err.value)
    assert message.startswith(str(path)) and says in message and "\n" not in message
    assert message.count("rotor") >= 1 and "problems" not in message  # one problem, said once


def test_a_raw_colour_rotor_campaign_is_written_in_nut_and_read_at_its_frame_rate(tmp_path):
    """Raw (lossless) colour at a high-speed camera's rate: NUT (AVI cannot time 2,000 frames/s), whose stream
    states no average rate; the reader takes the frame interval from the timestamps, not FFmpeg's guess (the
    time base, 64,000 frames/s), so the manifest's shutter check and every frame's time hold."""
    from servoscope.campaign import load_campaign
    from servoscope.simulate import simulate_campaign
    from servoscope.video.reader import iter_frames, probe_video

    toml = simulate_campaign(tmp_path / "c", "paper-rotor", 1, codec="raw", fps=2000, frequencies_hz=(6.0,),
                             min_dwell_s=0.1, min_periods=0.5, pre_roll_s=0.02, settle_s=0.02, include_step=False,
                             height=120)
    campaign = load_campaign(toml)  # before: "exposure 25 µs longer than the frame interval (0.0156 ms)"
    (test,) = campaign.tests
    assert test.video.suffix == ".nut"
    info = probe_video(test.video)
    assert info.codec == "rawvideo" and info.frame_rate_hz == pytest.approx(2000.0)
    times = [f.time_s for _, f in zip(range(5), iter_frames(test.video))]
    assert times == pytest.approx([k / 2000.0 for k in range(5)])
