"""Identification on H.264 twin footage with a camcorder's GOP: the codec check on its I-frames.

AVCHD camcorders record an I-frame every 15 frames; the codec check fits each dwell's sine to them.
(The same codec at the same bit rate without the GOP: test_identify_twin_h264.py; a file of its
own so that pytest-xdist's --dist loadfile can run the two rendered campaigns on different workers.)
"""

from __future__ import annotations

import json

import pytest

from servoscope.campaign import identify, load_campaign
from servoscope.simulate import simulate_campaign


@pytest.fixture(scope="module")
def camcorder_gop_campaign(tmp_path_factory):
    import numpy as np

    # An I-frame every 15 frames, as AVCHD camcorders record: the codec check has 20 a dwell.
    return simulate_campaign(tmp_path_factory.mktemp("h264gop15"), preset="paper", seed=1, codec="h264",
                             bit_rate=20_000_000, gop=15, frequencies_hz=tuple(np.geomspace(0.5, 15.0, 8)),
                             include_step=False)


@pytest.fixture(scope="module")
def camcorder_gop_tracks(camcorder_gop_campaign):
    from servoscope.campaign import track_campaign

    campaign = load_campaign(camcorder_gop_campaign)
    return campaign, track_campaign(campaign, workers=1)


@pytest.mark.parametrize("fit", ["magnitude", "complex"])
def test_camcorder_gop_codec_check(camcorder_gop_campaign, camcorder_gop_tracks, fit):
    import dataclasses

    campaign, tracks = camcorder_gop_tracks
    truth = json.loads((camcorder_gop_campaign.parent / "truth.json").read_text())["model"]
    checked = identify(campaign, tracks=tracks, fit=fit)
    # The same tracks without the I-frame marks: every frame fitted alike, as before the codec check.
    blind = identify(campaign, tracks={k: dataclasses.replace(t, intra=None) for k, t in tracks.items()}, fit=fit).model
    model = checked.model
    assert all(f.estimator == "intra frames" for f in checked.sine_fits.values())
    for name in ("gain", "natural_frequency_rad_s", "damping_ratio"):
        low, high = model.ci95[name]
        print(f"{fit} {name}: {model.params[name]:.6g} [{low:.6g}, {high:.6g}] (all frames {blind.params[name]:.6g}), "
              f"truth {truth[name]}")
        assert low <= truth[name] <= high
        # Closer to the truth than the all-frame fit, and with a narrower interval.
        assert abs(model.params[name] - truth[name]) < 0.5 * abs(blind.params[name] - truth[name])
        assert high - low < 0.6 * (blind.ci95[name][1] - blind.ci95[name][0])
    assert model.params["gain"] == pytest.approx(truth["gain"], rel=0.001)
    assert model.params["natural_frequency_rad_s"] == pytest.approx(truth["natural_frequency_rad_s"], rel=0.002)
