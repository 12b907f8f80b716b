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

