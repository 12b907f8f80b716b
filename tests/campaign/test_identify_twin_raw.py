"""Identification against truth on uncompressed twin footage: estimates and their uncertainty.

Uncompressed, so that what is tested is the chain footage → tracks → fits and
its stated uncertainty; H.264's small bias on subpixel motion is measured
separately (docs/twin.md, docs/accuracy.md "Identification: stated
uncertainty").
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from servoscope.campaign import identify, load_campaign
from servoscope.simulate import simulate_campaign

# Short dwells (1.2 s of steady state, no step test) keep two more seeds cheap.
SHORT = dict(
    codec="raw", frequencies_hz=tuple(np.geomspace(0.8, 15.0, 6)), pre_roll_s=0.2, settle_s=0.3,
    min_dwell_s=1.2, min_periods=0.0, include_step=False,
)


@pytest.fixture(scope="module")
def raw_campaign(tmp_path_factory):
    return simulate_campaign(
        tmp_path_factory.mktemp("rawpaper"), preset="paper", seed=4, codec="raw",
        frequencies_hz=tuple(np.geomspace(0.5, 15.0, 8)),
    )


@pytest.fixture(scope="module")
def short_campaigns(tmp_path_factory):
    return [simulate_campaign(tmp_path_factory.mktemp(f"short{s}"), preset="paper", seed=s, **SHORT) for s in (1, 3)]


_TRACKS: dict = {}


def _tracked(campaign):
    """The campaign and its tracks, tracked once for both fit modes (tracking is the cost, not what differs)."""
    from servoscope.campaign import track_campaign

    if campaign not in _TRACKS:
        loaded = load_campaign(campaign)
        _TRACKS[campaign] = (loaded, track_campaign(loaded))
    return _TRACKS[campaign]


def _names(fit):
    return ["gain", "natural_frequency_rad_s", "damping_ratio"] + (["dead_time_s"] if fit == "complex" else [])


def _errors(campaign, fit, model=None):
    """(name, error / half-width of the 95 % interval) per parameter; prints σ-errors."""
    truth = json.loads((campaign.parent / "truth.json").read_text())
    if model is None:
        loaded, tracks = _tracked(campaign)
        model = identify(loaded, tracks=tracks, fit=fit).model
    out = []
    for name in _names(fit):
        value, (low, high) = model.params[name], model.ci95[name]
        true = truth["model"][name]
        stderr = model.stderr[name]
        print(f"{campaign.parent.name} {fit} {name}: {value:.6g}, 95 % [{low:.6g}, {high:.6g}], truth {true}, "
              f"error {(value - true) / stderr:+.2f} σ")
        assert low < value < high and stderr > 0
        assert low <= true <= high, (campaign, fit, name, low, true, high)
        out.append((name, abs(value - true) / (0.5 * (high - low))))
    return model, truth, out


@pytest.mark.parametrize("fit", ["magnitude", "complex"])
def test_paper_model_and_intervals(raw_campaign, fit):
    loaded, tracks = _tracked(raw_campaign)
    result = identify(loaded, tracks=tracks, fit=fit)
    model = result.model
    truth = json.loads((raw_campaign.parent / "truth.json").read_text())
    # The stated 95 % intervals contain the truth (HAC per-dwell errors,
    # covariance scaled by max(1, χ²/dof)); see docs/accuracy.md.
    _errors(raw_campaign, fit, model)
    # The accuracy targets: K, ωn within 1 %, ζ within 3 %, bandwidth 1 %, τ 2 ms.
    assert model.params["gain"] == pytest.approx(truth["model"]["gain"], rel=0.01)
    assert model.params["natural_frequency_rad_s"] == pytest.approx(truth["model"]["natural_frequency_rad_s"], rel=0.01)
    assert model.params["damping_ratio"] == pytest.approx(truth["model"]["damping_ratio"], rel=0.03)
    assert model.bandwidth_rad_s == pytest.approx(truth["bandwidth_rad_s"], rel=0.01)
    assert result.dead_time_s == pytest.approx(truth["model"]["dead_time_s"], abs=0.002)


@pytest.mark.parametrize("fit", ["magnitude", "complex"])
def test_intervals_contain_truth_over_seeds(short_campaigns, fit):
    for campaign in short_campaigns:
        model, truth, errs = _errors(campaign, fit)
        assert model.params["natural_frequency_rad_s"] == pytest.approx(truth["model"]["natural_frequency_rad_s"], rel=0.01)
        # The intervals stay well inside the accuracy targets: they
        # say something (K, ωn to better than ±0.5 %, ζ ±1.5 %).
        for name, limit in (("gain", 0.005), ("natural_frequency_rad_s", 0.005), ("damping_ratio", 0.015)):
            low, high = model.ci95[name]
            assert (high - low) / 2 < limit * truth["model"][name], (name, low, high)
