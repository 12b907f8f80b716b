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


# The files that take longest, longest first (pytest --durations on a fresh clone on the 2-core machine,
# 2026-11-26, session 9): `make test` hands whole files to its two workers in collection order, so starting the
# long ones first lets the short ones fill in at the end and both workers finish together (longest processing
# time first).
LONGEST_FIRST = [
    "campaign/test_identify_twin_codecs.py", "campaign/test_identify_twin_raw.py", "campaign/test_rotor_identify.py",
    "test_identify_command.py", "video/test_video_formats.py", "sysid/test_linearity.py",
    "markers/test_monochrome.py", "campaign/test_identify_sweep.py", "sysid/test_sysid_identify.py",
    "campaign/test_joint.py", "campaign/test_plane_twin.py", "camera/test_timing_honesty.py", "sysid/test_modes.py",
    "campaign/test_interrupted_run.py", "camera/test_rolling_shutter.py", "markers/test_gpu.py",
    "camera/test_exposure_blur.py", "campaign/test_end_to_end.py", "campaign/test_joint_linear.py",
    "report/test_report_browser.py", "simulate/test_twin_image_sequence.py", "video/test_memory.py",
    "markers/test_reference_markers.py", "campaign/test_blade_motions.py", "sysid/test_servo_selection.py",
    "sysid/test_sysid_held.py", "test_cli_errors.py", "test_bench.py", "sysid/test_heave_traces.py",
]


def pytest_collection_modifyitems(session, config, items):
    here = Path(__file__).resolve().parent
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}

    def order(item) -> int:
        try:
            name = Path(str(item.path)).resolve().relative_to(here).as_posix()
        except ValueError:
            return len(rank)
        return rank.get(name, len(rank))

    items.sort(key=order)  # stable: within a file, and among the rest, collection order stays
