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


#: The slowest files (seconds of one worker, measured 2026-11-26 on 2 cores): scheduled first, so that
#: `-n auto --dist loadfile` does not end with one worker alone on a long file (longest first, as a
#: greedy scheduler should). Files not named keep their order after these.
_SLOW_FILES = {
    "test_identify_twin_h264.py": 95, "test_servo_selection.py": 43, "test_identify_twin_mpeg2.py": 40,
    "test_timing_honesty.py": 39, "test_identify_twin_raw.py": 37, "test_sysid_identify.py": 31,
    "test_gpu.py": 28, "test_joint.py": 27, "test_cli_errors.py": 24, "test_exposure_blur.py": 24,
    "test_monochrome.py": 23, "test_reference_markers.py": 21, "test_identify_command.py": 20,
    "test_rolling_shutter.py": 19, "test_plane_twin.py": 18,
}


def pytest_collection_modifyitems(session, config, items):
    items.sort(key=lambda item: -_SLOW_FILES.get(item.path.name, 0))  # stable: in-file order kept
