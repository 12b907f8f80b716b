"""Shared fixtures: small rendered campaigns, made once per test session."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

SHARED = Path(__file__).resolve().parents[1].parent / "shared"


def made_once(tmp_path_factory, name: str, make) -> Path:
    """A folder ``make(folder)`` fills, made once for the whole run, whichever test worker asks first.

    pytest-xdist's recipe for session fixtures: each worker is its own process with its own session, so a
    session fixture is otherwise made once a worker. The first worker to ask makes the folder under a file
    lock in the run's shared temporary folder; the others wait for the lock and find it made. Only files are
    shared, never objects, and only what no test changes: a test that writes beside them writes its own names.
    """
    from filelock import FileLock

    if not os.environ.get("PYTEST_XDIST_WORKER"):
        folder = tmp_path_factory.mktemp(name)
        make(folder)
        return folder
    folder = tmp_path_factory.getbasetemp().parent / f"shared-{name}"
    with FileLock(f"{folder}.lock"):
        done = folder / ".made"
        if not done.is_file():
            shutil.rmtree(folder, ignore_errors=True)
            folder.mkdir()
            make(folder)
            done.touch()
    return folder


@pytest.fixture(scope="session")
def quick_campaign(tmp_path_factory) -> Path:
    """The 'quick' preset rendered once for the run: path of its campaign.toml."""
    from servoscope.simulate import simulate_campaign

    return made_once(tmp_path_factory, "quick", lambda folder: simulate_campaign(folder, preset="quick", seed=3)) \
        / "campaign.toml"


@pytest.fixture(scope="session")
def quick_result(quick_campaign, tmp_path_factory):
    """The quick campaign identified once a worker, from tracks made once for the run (tracking is the cost)."""
    from servoscope.campaign import identify, load_campaign, track_campaign

    campaign = load_campaign(quick_campaign)
    cache = made_once(tmp_path_factory, "quick-tracks", lambda folder: track_campaign(campaign, cache_dir=folder))
    return identify(campaign, cache_dir=cache)



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


def pytest_configure(config):
    """Under pytest-xdist, each test worker keeps to its own share of the cores.

    The campaign API's default is one worker process per core the caller may run on
    (:func:`servoscope.campaign.parallel.default_workers`), and the decoder's threads follow the same
    count. With one test worker per core, each identification then started a Dask cluster of as many
    processes as the machine has cores, and its decoders as many threads, on cores the other test
    worker was using: the suite paid for the clusters and the contention and gained nothing. Pinned,
    a test worker's default is what a user's is on a machine of that many cores (one core: in
    process); the parallel path keeps its own tests, which ask for their workers.
    """
    worker = os.environ.get("PYTEST_XDIST_WORKER", "")
    count = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "0") or 0)
    if not worker.startswith("gw") or count < 2 or not hasattr(os, "sched_setaffinity"):
        return
    cores = sorted(os.sched_getaffinity(0))
    _ALL_CORES.extend(cores)
    share = cores[int(worker[2:]) % count::count] if len(cores) >= count else [cores[int(worker[2:]) % len(cores)]]
    os.sched_setaffinity(0, share)


#: The cores this test worker could run on before it was pinned (empty where it was not).
_ALL_CORES: list[int] = []


@pytest.fixture
def all_cores():
    """The test runs on every core the worker had before it was pinned, as a user's process does: a real-time
    test (the rig's 50 Hz stream, its driver and the fake servo controller each a thread) must not share one
    core with whatever else the worker's process runs (session 10: a sample skipped, more than a period late)."""
    if not _ALL_CORES or not hasattr(os, "sched_setaffinity"):
        yield
        return
    pinned = os.sched_getaffinity(0)
    os.sched_setaffinity(0, _ALL_CORES)
    try:
        yield
    finally:
        os.sched_setaffinity(0, pinned)


# The files that take longest, longest first (their junit times in a fresh clone's run on the 2-core machine,
# 2026-11-27, session 12): `make test` hands whole files to its two workers in collection order, so starting the
# long ones first lets the short ones fill in at the end and both workers finish together (longest processing
# time first).
LONGEST_FIRST = [
    "campaign/test_identify_twin_paper.py", "campaign/test_rotor_identify.py", "sysid/test_servo_selection.py",
    "test_identify_command.py", "camera/test_timing_honesty.py", "video/test_video_formats.py",
    "sysid/test_sysid_identify.py", "campaign/test_identify_sweep.py", "sysid/test_modes.py",
    "campaign/test_plane_twin.py", "camera/test_exposure_blur.py", "campaign/test_campaign_parallel.py",
    "campaign/test_joint.py", "campaign/test_joint_linear.py", "sysid/test_linearity.py",
    "campaign/test_end_to_end.py", "markers/test_gpu.py", "markers/test_reference_markers.py",
    "campaign/test_joint_no_step.py", "markers/test_marker_selection.py", "campaign/test_interrupted_run.py",
    "simulate/test_twin_camera_options.py", "markers/test_monochrome.py", "campaign/test_recorded_input.py",
    "report/test_report_browser.py", "campaign/test_blade_motions.py", "simulate/test_rotor_twin.py",
    "camera/test_rolling_shutter.py", "video/test_memory.py", "test_architecture.py",
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
