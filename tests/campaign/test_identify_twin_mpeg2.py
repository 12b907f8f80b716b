"""Identification on MPEG-2 twin footage (HDV's codec, the paper's camera's: 25 Mbit/s, GOP 15).

MPEG-2 holds back small sticker motions in the frames it predicts from others (up to −4 % of the
amplitude at 15 Hz on the `paper` preset, docs/accuracy.md "The codec check"), across several
dwells at once, which no delete-one check can see. Its I-frames (one in 15) show the sticker where
it is, up to their own quantization: the codec check fits each dwell's sine to them.
"""

from __future__ import annotations

import json

import control
import numpy as np
import pytest

from servoscope.campaign import identify, load_campaign
from servoscope.simulate import simulate_campaign
from servoscope.report import write_report


@pytest.fixture(scope="module")
def mpeg2_campaign(tmp_path_factory):
    return simulate_campaign(tmp_path_factory.mktemp("mpeg2paper"), preset="paper", seed=0, codec="mpeg2",
                             bit_rate=25_000_000, frequencies_hz=tuple(np.geomspace(0.5, 15.0, 8)),
                             include_step=False)


@pytest.fixture(scope="module")
def truth(mpeg2_campaign):
    return json.loads((mpeg2_campaign.parent / "truth.json").read_text())["model"]


@pytest.fixture(scope="module")
def result(mpeg2_campaign):
    return identify(load_campaign(mpeg2_campaign), fit="complex")


def test_codec_check_removes_most_of_the_codec_bias(result, truth):
    g = control.tf([truth["gain"] * truth["natural_frequency_rad_s"] ** 2],
                   [1.0, 2 * truth["damping_ratio"] * truth["natural_frequency_rad_s"],
                    truth["natural_frequency_rad_s"] ** 2])
    fr = result.frequency_response
    true_gain = np.abs(control.frequency_response(g, 2 * np.pi * fr.frequency_hz).complex)
    fits = [result.sine_fits[label] for label in fr.labels]
    assert all(f.estimator == "intra frames" and f.n_intra >= 8 for f in fits)
    intra_err = fr.gain / true_gain - 1.0
    # The all-frame fit of the same dwell, exposure-corrected alike: gain × (all / intra amplitude).
    all_err = (1.0 + intra_err) * np.array([1.0 + f.codec_gain_bias for f in fits]) - 1.0
    print("gain error, intra frames (%):", np.round(100 * intra_err, 3))
    print("gain error, all frames (%):  ", np.round(100 * all_err, 3))
    # The codec's loss is measured where it is large, and flagged ...
    top = fits[-1]
    assert top.codec_gain_bias < -0.02 and "codec" in top.flags
    # ... and most of it is gone: the fast dwells' errors shrink by more than half, the RMS by 2.
    assert abs(intra_err[-1]) < 0.5 * abs(all_err[-1])
    assert np.sqrt(np.mean(intra_err**2)) < 0.5 * np.sqrt(np.mean(all_err**2))


@pytest.mark.parametrize("fit", ["magnitude", "complex"])
def test_mpeg2_model_within_the_accuracy_targets(mpeg2_campaign, result, truth, fit):
    # The same tracks fitted by magnitude (tracking is the cost, and not what differs).
    model = result.model if fit == "complex" else identify(result.campaign, tracks=result.tracks, fit=fit).model
    for name in ("gain", "natural_frequency_rad_s", "damping_ratio"):
        print(f"{fit} {name}: {model.params[name]:.6g} {model.ci95[name]} truth {truth[name]}")
    assert model.params["gain"] == pytest.approx(truth["gain"], rel=0.003)
    assert model.params["natural_frequency_rad_s"] == pytest.approx(truth["natural_frequency_rad_s"], rel=0.01)
    assert model.params["damping_ratio"] == pytest.approx(truth["damping_ratio"], rel=0.03)


def test_report_shows_the_codec_check(result, tmp_path):
    paths = write_report(result, tmp_path)
    html = paths["report"].read_text()
    # The fast dwell's row: its flag whole, and what the other frames did against its I-frames.
    row = html[html.index("<td>dwell_08_15.00Hz</td><td>15</td>"):]
    row = row[: row.index("</tr>")]
    assert "<td>codec</td>" in row
    top = result.sine_fits["dwell_08_15.00Hz"]
    assert f"({top.n_intra} I-frames)" in row and row.count(" % ± ") == 1
