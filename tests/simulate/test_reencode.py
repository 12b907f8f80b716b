"""One render, many codecs (simulate/reencode.py): a raw twin campaign's videos encoded again.

The oracle is the twin itself: the same campaign rendered directly with each codec. Re-encoding is
only a saving if it writes those very bytes (the tests that share one render between their raw and
H.264 cases rely on it: tests/sysid/test_modes.py, tests/camera/test_exposure_blur.py).
"""

from __future__ import annotations

import hashlib
import json

import pytest

from servoscope.errors import ServoscopeError
from servoscope.simulate import reencode_campaign, simulate_campaign

SMALL = dict(width=160, height=128, frequencies_hz=(2.0, 5.0), min_dwell_s=0.3)


def _digests(folder):
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir()) if p.is_file()}


@pytest.fixture(scope="module")
def raw(tmp_path_factory):
    return simulate_campaign(tmp_path_factory.mktemp("raw"), "quick", 3, codec="raw", **SMALL)


@pytest.mark.parametrize("codec, options", [("h264", {}), ("h264", {"gop": 7}), ("mpeg2", {"bit_rate": 6_000_000})])
def test_reencoded_campaign_is_the_directly_rendered_one_byte_for_byte(raw, tmp_path, codec, options):
    direct = simulate_campaign(tmp_path / "direct", "quick", 3, codec=codec, **options, **SMALL)
    again = reencode_campaign(raw, tmp_path / "again", codec=codec, **options)
    assert again.name == "campaign.toml"
    want, got = _digests(direct.parent), _digests(again.parent)
    assert sorted(got) == sorted(want) and any(name.endswith((".mp4", ".mpg", ".m2v", ".ts")) for name in got)
    assert got == want  # the videos, campaign.toml, truth.json and camera.json alike
    truth = json.loads((again.parent / "truth.json").read_text())
    assert truth["video"]["codec"] == codec and truth["video"]["gop"] == options.get("gop")


def test_what_cannot_be_reencoded_is_one_clear_error(raw, tmp_path):
    lossy = reencode_campaign(raw, tmp_path / "lossy", codec="h264")
    with pytest.raises(ServoscopeError, match="codec='raw'"):
        reencode_campaign(lossy, tmp_path / "twice", codec="mpeg2")  # a lossy source would add its losses
    with pytest.raises(ServoscopeError, match="lossy codecs"):
        reencode_campaign(raw, tmp_path / "raw_again", codec="raw")
    with pytest.raises(ServoscopeError, match="holds a campaign"):
        reencode_campaign(raw, tmp_path / "lossy", codec="h264")
    with pytest.raises(ServoscopeError, match="not a twin campaign"):
        reencode_campaign(tmp_path / "nowhere" / "campaign.toml", tmp_path / "x")
