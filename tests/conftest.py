"""Shared fixtures: small rendered campaigns, made once per test session."""

from __future__ import annotations

from pathlib import Path

import pytest

SHARED = Path(__file__).resolve().parents[1].parent / "shared"


@pytest.fixture(scope="session")
def quick_campaign(tmp_path_factory) -> Path:
    """The 'quick' preset rendered once: path of its campaign.toml."""
    from servoscope.simulate import simulate_campaign

    return simulate_campaign(tmp_path_factory.mktemp("quick"), preset="quick", seed=3)


@pytest.fixture(scope="session")
def quick_result(quick_campaign):
    """The quick campaign identified once."""
    from servoscope.campaign import identify, load_campaign

    return identify(load_campaign(quick_campaign))



@pytest.fixture(scope="session")
def backlash_identified(tmp_path_factory):
    """The quick preset with play in the linkage (0.004 rad), two amplitudes, raw frames, identified once
    with ``nonlinear="auto"`` and its report written: (result, output folder, the servo rendered)."""
    from dataclasses import replace

    from servoscope.campaign import identify
    from servoscope.report import write_report
    from servoscope.simulate import simulate_campaign
    from servoscope.simulate.presets import get_preset

    root = tmp_path_factory.mktemp("backlash")
    servo = replace(get_preset("quick").servo, backlash=0.004)
    toml = simulate_campaign(root / "c", "quick", 1, width=480, height=384, codec="raw", servo=servo,
                             sine_amplitudes=(0.05, 0.2))
    result = identify(toml, workers=1, nonlinear="auto")
    write_report(result, root / "out")
    return result, root / "out", servo
