"""Campaigns tracked on Dask: a local cluster and a real scheduler with two workers.

The reference is the quick campaign identified in-process (``quick_result``,
tracked one video after the other): tracks made on Dask workers must be
bit-identical to it.
"""

from __future__ import annotations

import dataclasses
import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from servoscope.campaign import TestSpec, load_campaign, track_campaign
from servoscope.campaign import parallel
from servoscope.campaign.cache import tracks_equal
from servoscope.errors import ServoscopeError

pytest.importorskip("distributed")


def _assert_same_tracks(tracks, reference, labels) -> None:
    assert list(tracks) == list(labels)  # manifest order, whatever the completion order
    for label in labels:
        assert tracks_equal(tracks[label], reference[label]), f"{label}: track differs from the in-process one"


def test_local_cluster_tracks_are_identical_and_failures_are_kept(quick_campaign, quick_result, tmp_path):
    campaign = load_campaign(quick_campaign)
    broken = tmp_path / "broken.mp4"
    broken.write_bytes(b"this is not a video\n" * 100)
    with_broken = dataclasses.replace(
        campaign, tests=campaign.tests + (TestSpec(broken, "sine", 0.1, frequency_hz=3.0, label="broken"),)
    )
    failures: dict[str, str] = {}
    progress_calls: list[tuple] = []
    done: list[tuple[str, str]] = []
    tracks = track_campaign(
        with_broken, workers=2, keep_going=True, failures=failures,
        progress=lambda *a: progress_calls.append(a), on_done=lambda *a: done.append(a),
    )
    labels = [t.label for t in campaign.tests]
    _assert_same_tracks(tracks, quick_result.tracks, labels)
    assert list(failures) == ["broken"]
    assert "not a readable video" in failures["broken"]
    assert sorted(done) == sorted([(label, "tracked") for label in labels] + [("broken", "failed")])
    # On Dask, progress comes once per finished video, with its frame count and manifest index.
    assert sorted(progress_calls, key=lambda a: a[2]) == [
        (label, quick_result.tracks[label].n_frames, i) for i, label in enumerate(labels)
    ]


def test_bad_worker_options_are_refused(quick_campaign):
    campaign = load_campaign(quick_campaign)
    with pytest.raises(ServoscopeError, match="workers"):
        track_campaign(campaign, workers=0)
    with pytest.raises(ServoscopeError, match="not both"):
        track_campaign(campaign, workers=2, scheduler="tcp://127.0.0.1:1")


def test_a_retired_backend_is_refused_before_a_cluster_starts(tmp_path, monkeypatch):
    from servoscope.markers.settings import TrackerSettings

    def no_cluster(*args, **kwargs):
        raise AssertionError("a cluster was started for settings no worker can track with")

    monkeypatch.setattr(parallel, "start_local_cluster", no_cluster)
    tests = [TestSpec(tmp_path / f"{n}.mp4", "sine", 0.1, 1.0, None, n) for n in ("a", "b")]
    with pytest.raises(ServoscopeError, match='backend: \'cuda\'.*backend="auto"'):
        parallel.track_many(tests, TrackerSettings(backend="cuda"), workers=2, keep_going=True)


def test_unreachable_scheduler_is_a_clear_error(quick_campaign, monkeypatch):
    monkeypatch.setattr(parallel, "CONNECT_TIMEOUT_S", 1.0)
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with pytest.raises(ServoscopeError, match="cannot connect"):
        track_campaign(load_campaign(quick_campaign), scheduler=f"tcp://127.0.0.1:{port}")


# -- a real `dask scheduler` and two `dask worker` processes ------------------------------------


def _dask_command(sub: str) -> list[str]:
    # The `dask` entry point of this environment; the module form where it is missing.
    exe = Path(sys.executable).with_name("dask")
    if exe.exists():
        return [str(exe), sub]
    return [sys.executable, "-m", f"distributed.cli.dask_{sub}"]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _stop(proc: subprocess.Popen) -> None:
    """Stop one process we started (its own process group), politely then firmly."""
    if proc.poll() is not None:
        return
    try:
        os.killpg(proc.pid, signal.SIGTERM)
    except ProcessLookupError:
        return
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)


@pytest.fixture(scope="module")
def dask_scheduler(tmp_path_factory):
    """Address of a scheduler on loopback with two single-threaded workers; all stopped afterwards."""
    from distributed import Client

    logs = tmp_path_factory.mktemp("dask-logs")
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    procs: list[subprocess.Popen] = []

    def start(args: list[str], name: str) -> None:
        log = open(logs / f"{name}.log", "wb")
        # A process group of its own: stopping it reaches any child it spawned.
        procs.append(subprocess.Popen(args, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                      start_new_session=True))
        log.close()

    def show_logs() -> str:
        return "\n".join(f"--- {p.name}\n{p.read_text(errors='replace')[-2000:]}" for p in sorted(logs.iterdir()))

    try:
        start(_dask_command("scheduler") + ["--host", "127.0.0.1", "--port", str(port), "--no-dashboard"], "scheduler")
        for k in range(2):
            start(_dask_command("worker") + [address, "--host", "127.0.0.1", "--nthreads", "1", "--no-nanny",
                                             "--no-dashboard", "--memory-limit", "0", "--death-timeout", "60",
                                             "--name", f"w{k}"], f"worker{k}")
        try:
            with Client(address, timeout=60) as client:
                client.wait_for_workers(2, timeout=60)
                assert len(client.scheduler_info()["workers"]) == 2
        except Exception as exc:  # the logs say why a process did not come up
            pytest.fail(f"dask cluster did not start: {exc}\n{show_logs()}")
        yield address
    finally:
        for proc in reversed(procs):  # workers first, then the scheduler
            _stop(proc)


def test_remote_scheduler_tracks_are_identical_and_cached(dask_scheduler, quick_campaign, quick_result, tmp_path, monkeypatch):
    campaign = load_campaign(quick_campaign)
    labels = [t.label for t in campaign.tests]
    cache_dir = tmp_path / ".cache"
    tracks = track_campaign(campaign, scheduler=dask_scheduler, cache_dir=cache_dir)
    _assert_same_tracks(tracks, quick_result.tracks, labels)

    # What the workers tracked was cached by this process: a local run reads it all back.
    def no_tracking(*args, **kwargs):
        raise AssertionError("tracked again although cached")

    monkeypatch.setattr(parallel, "track_video", no_tracking)
    again = track_campaign(campaign, cache_dir=cache_dir)
    _assert_same_tracks(again, quick_result.tracks, labels)


def test_remote_worker_without_the_video_says_what_is_needed(dask_scheduler, quick_campaign, tmp_path):
    campaign = load_campaign(quick_campaign)
    missing = dataclasses.replace(
        campaign, tests=(TestSpec(tmp_path / "elsewhere.mp4", "sine", 0.1, frequency_hz=1.0, label="elsewhere"),
                         TestSpec(tmp_path / "elsewhere2.mp4", "sine", 0.1, frequency_hz=2.0, label="elsewhere2"))
    )
    with pytest.raises(ServoscopeError, match="same path"):
        track_campaign(missing, scheduler=dask_scheduler)


def test_a_local_cluster_says_nothing_when_the_dashboard_port_is_taken():
    """Two campaigns at once (two test workers, two users) must not print Dask's "Port 8787 is
    already in use" into servoscope's output: the cluster asks for no fixed dashboard port."""
    import socket
    import warnings

    from servoscope.campaign.parallel import start_local_cluster

    holder = socket.socket()
    try:
        holder.bind(("127.0.0.1", 8787))
        holder.listen()
    except OSError:
        pass  # already taken by someone else: the same situation
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            cluster = start_local_cluster(1, 1)
            cluster.close()
        assert not [w for w in caught if "8787" in str(w.message)]
    finally:
        holder.close()
