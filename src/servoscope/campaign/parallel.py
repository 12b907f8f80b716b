"""Tracking many videos at once: in-process, on a local Dask cluster, or on a remote one.

One video is one task: tracking is sequential inside a video (each frame's
search window comes from the previous frame), so videos are the natural unit
of parallelism, and a campaign has a dozen or more of them.

* ``workers=1`` (and no scheduler): tracked one after the other in this
  process; Dask is not even imported.
* ``workers=N``: a :class:`distributed.LocalCluster` of N worker *processes*
  with one thread each (the tracker holds the GIL in Python code between its
  NumPy/OpenCV calls, so threads would not scale).
* ``scheduler="tcp://host:port"``: the tasks go to an existing Dask
  distributed cluster; its workers must have servoscope installed and see
  the videos at the same path as this machine (a shared folder).

Results never depend on where a video was tracked: the same code runs on
the same bytes, and the tracks come back in manifest order. Tracks are
cached (see :mod:`servoscope.campaign.cache`) by the calling process as each
one arrives, so a run stopped half-way keeps everything finished so far.
"""

from __future__ import annotations

import logging
import os
import sys
import time
import uuid
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterator, Protocol, Sequence

from ..errors import ServoscopeError
from ..markers.settings import TrackerSettings, resolve_engine
from ..markers.track import Track
from ..pipeline.tracker import track_video
from ..video.reader import THREADS_ENV
from .cache import TrackCache

__all__ = ["track_many", "default_workers", "start_local_cluster", "ProgressFn", "DoneFn"]

#: ``progress(label, frames_done, test_index)``: in-process, called every 50
#: frames and at the end of each video; on Dask, once per video, when its
#: track arrives (workers do not report frames back).
ProgressFn = Callable[[str, int, int], None]

#: ``on_done(label, status)`` once per video, in completion order, with
#: status ``"cached"``, ``"tracked"`` or ``"failed"``: what a progress bar
#: counting videos needs.
DoneFn = Callable[[str, str], None]

#: How long to wait for a remote scheduler to answer, and for it to have a worker (s).
CONNECT_TIMEOUT_S = 20.0
WORKER_WAIT_S = 60.0


class _TestLike(Protocol):
    label: str
    video: Path


def default_workers() -> int:
    """Cores this process may run on (the local cluster's default size)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - macOS, Windows
        return os.cpu_count() or 1


def track_many(
    tests: Sequence[_TestLike],
    settings: TrackerSettings,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    cache: TrackCache | None = None,
    force: bool = False,
    keep_going: bool = False,
    progress: ProgressFn | None = None,
    on_done: DoneFn | None = None,
) -> tuple[dict[str, Track], dict[str, str]]:
    """Track several videos, reusing cached tracks, in parallel where asked.

    Parameters
    ----------
    tests : sequence of objects with ``label`` and ``video``
        E.g. a campaign's :class:`~servoscope.campaign.TestSpec` list.
    settings : TrackerSettings
        The same for every video.
    workers : int, optional
        Worker processes of a local Dask cluster; None: one per available
        core; 1: in this process, without Dask. Ignored (must be None or 1)
        when ``scheduler`` is given. Never more workers than videos to track
        are started, and a single video to track is tracked in-process.
    scheduler : str, optional
        Address of a running Dask scheduler, e.g. ``"tcp://10.0.0.5:8786"``.
    cache : TrackCache, optional
        Where finished tracks are kept and looked up.
    force : bool
        Track every video again even when cached (the new tracks replace the old).
    keep_going : bool
        A video that fails (unreadable, markers not found, its worker died)
        is left out with its reason in the returned failures instead of raising.
    progress : callable(label, frames_done, test_index), optional
    on_done : callable(label, status), optional

    Returns
    -------
    tracks : dict of label → Track
        In the order of ``tests`` (failed videos left out).
    failures : dict of label → reason
        Empty unless ``keep_going``.

    Raises
    ------
    ServoscopeError
        A video failed (without ``keep_going``), bad ``workers``, or the
        scheduler cannot be reached or has no workers.
    """
    if scheduler is not None:
        if workers not in (None, 1):
            raise ServoscopeError("give either a number of local workers or a scheduler address, not both")
    else:
        workers = default_workers() if workers is None else workers
        if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
            raise ServoscopeError(f"workers must be a whole number ≥ 1, got {workers!r}")

    results: dict[int, Track] = {}
    failed: dict[int, str] = {}
    pending: list[tuple[int, _TestLike, str | None]] = []
    for i, test in enumerate(tests):
        key = None
        if cache is not None:
            try:
                key = cache.key(test.video, settings)
            except OSError:
                key = None  # missing or unreadable: tracking reports it in its own words
        track = cache.load(key) if (cache is not None and key is not None and not force) else None
        if track is not None:
            results[i] = track
            if progress is not None:
                progress(test.label, track.n_frames, i)
            if on_done is not None:
                on_done(test.label, "cached")
        else:
            pending.append((i, test, key))

    def finished(i: int, test: _TestLike, key: str | None, track: Track, seconds: float | None) -> None:
        results[i] = track
        if cache is not None and key is not None:
            extra = {"label": test.label, "tracking_s": seconds}
            cache.store(key, track, video=test.video, extra=extra)
        if on_done is not None:
            on_done(test.label, "tracked")

    def failure(i: int, test: _TestLike, exc: BaseException) -> None:
        if not keep_going:
            raise exc
        failed[i] = str(exc)
        if on_done is not None:
            on_done(test.label, "failed")

    if pending:
        if scheduler is None and (workers == 1 or len(pending) == 1):
            # A cluster costs seconds to start: not worth it for one video.
            _track_here(pending, settings, progress, finished, failure)
        else:
            n = None if scheduler is not None else min(int(workers), len(pending))  # type: ignore[arg-type]
            _track_on_dask(pending, settings, n, scheduler, progress, finished, failure)

    labels = [t.label for t in tests]
    tracks = {labels[i]: results[i] for i in sorted(results)}
    failures = {labels[i]: failed[i] for i in sorted(failed)}
    return tracks, failures


def _track_here(pending, settings, progress, finished, failure) -> None:
    for i, test, key in pending:
        callback = None
        if progress is not None:
            callback = lambda done, _label=test.label, _i=i: progress(_label, done, _i)  # noqa: E731
        start = time.perf_counter()
        try:
            track = track_video(test.video, settings, progress=callback)
        except ServoscopeError as exc:
            failure(i, test, exc)
            continue
        finished(i, test, key, track, time.perf_counter() - start)


def _track_on_dask(pending, settings, n_workers: int | None, scheduler: str | None, progress, finished, failure) -> None:
    from distributed import as_completed
    from distributed.client import FutureCancelledError

    try:
        from distributed import KilledWorker
    except ImportError:  # pragma: no cover - older distributed
        from distributed.scheduler import KilledWorker

    # Settings no engine takes (a retired backend, an unknown engine) are refused here, once,
    # not by every worker after a cluster has started.
    resolve_engine(settings)
    with _client(n_workers, scheduler) as client:
        # Longest first (file size as a proxy for frames): fewer workers
        # idle while the last long video finishes.
        order = sorted(pending, key=lambda p: -_size(p[1].video))
        run = uuid.uuid4().hex[:8]
        futures = {}
        for rank, (i, test, key) in enumerate(order):
            # track_video itself is the task, not a wrapper defined here: a
            # worker unpickles a task by importing its module, and
            # servoscope.pipeline imports in 0.3 s where this package (via
            # servoscope.campaign: SciPy, python-control) takes ~1.8 s.
            future = client.submit(
                track_video, str(test.video), settings,
                key=f"servoscope-track-{test.label}-{run}", pure=False, priority=len(order) - rank, retries=0,
            )
            futures[future] = (i, test, key)
        try:
            for future in as_completed(list(futures)):
                i, test, key = futures[future]
                try:
                    track = future.result()
                except ServoscopeError as exc:
                    if scheduler is not None and str(exc).endswith("video not found"):
                        # The commonest mistake with a remote cluster: say what is needed.
                        exc = ServoscopeError(
                            f"{exc} on a Dask worker (the workers need the videos at the same path as "
                            "this machine, e.g. on a shared folder)"
                        )
                    failure(i, test, exc)
                    continue
                except KilledWorker as exc:
                    failure(i, test, ServoscopeError(f"{test.video}: the Dask worker tracking it died ({exc})"))
                    continue
                except FutureCancelledError as exc:
                    failure(i, test, ServoscopeError(f"{test.video}: tracking was cancelled ({exc})"))
                    continue
                finished(i, test, key, track, None)
                if progress is not None:
                    progress(test.label, track.n_frames, i)
        finally:
            # Stopped early (an error, Ctrl-C): do not leave work running on
            # a shared cluster.
            client.cancel([f for f in futures if not f.done()])


def _size(path) -> int:
    try:
        return Path(path).stat().st_size
    except OSError:
        return 0


def start_local_cluster(n_workers: int | None, threads_per_worker_video: int, *, fork: bool = True,
                        silence_logs: int = logging.CRITICAL):
    """A ``distributed.LocalCluster`` of single-threaded worker processes for tracking.

    Parameters
    ----------
    n_workers : int or None
        Worker processes (None: Dask's default).
    threads_per_worker_video : int
        Threads each worker's video may use (decoder, OpenCV's pool), given to
        the workers as ``SERVOSCOPE_THREADS`` (see
        :func:`servoscope.video.reader.thread_budget`).
    fork : bool
        Fork the workers where that is safe (Linux): they start in ~0.2 s,
        warm, with servoscope, numba's compiled kernels and OpenCV already
        loaded, where spawned ones took 2–3 s to start and import, most of a
        2-core machine's gain. Nothing of this process is used by a worker but
        the imported code, and no decoder thread runs while the cluster
        starts. False (e.g. for CUDA, whose context does not survive a fork):
        spawned.
    silence_logs : int
        Logging level of the workers.
    """
    import cv2
    import dask
    from distributed import LocalCluster

    method = "fork" if fork and sys.platform.startswith("linux") else "spawn"
    share = str(int(threads_per_worker_video))
    # OpenCV's thread pool does not survive a fork: a child that touches a pool
    # this process has used hangs (measured: in pthread_cond_destroy). With one
    # thread the pool has no threads of its own, so it is set to one while the
    # workers are forked, and given back after.
    opencv_threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        with dask.config.set({"distributed.worker.multiprocessing-method": method}):
            return LocalCluster(
                n_workers=n_workers, threads_per_worker=1, processes=True,
                # No dashboard wanted, but None means the default port (8787): with two
                # campaigns at once (two test workers) the second warned on stderr.
                dashboard_address=":0", silence_logs=silence_logs,
                env={"OPENCV_FOR_THREADS_NUM": share, THREADS_ENV: share},
            )
    finally:
        cv2.setNumThreads(opencv_threads)


@contextmanager
def _client(n_workers: int | None, scheduler: str | None) -> Iterator:
    """A Dask client on a fresh local cluster or on ``scheduler``; closed on exit."""
    from distributed import Client

    # CRITICAL, not ERROR: a video that fails is an expected outcome that
    # comes back to us as its exception (and, with keep_going, a warning);
    # the worker's own "Compute Failed" log of it would be a second copy.
    quiet = logging.CRITICAL
    loggers = [logging.getLogger(name) for name in ("distributed", "tornado", "bokeh")]
    levels = [lg.level for lg in loggers]
    for lg in loggers:
        # Start-up, shutdown and heartbeat chatter would bury servoscope's own output.
        lg.setLevel(quiet)
    cluster = client = None
    try:
        if scheduler is None:
            # Each worker is one core's share: its decoder and OpenCV keep to
            # cores / workers threads, as Dask keeps BLAS/OpenMP to one thread
            # per worker (more would fight over the same cores). The tracks are
            # the same bytes whatever the thread count (tested).
            share = max(1, default_workers() // max(1, n_workers or 1))
            cluster = start_local_cluster(n_workers, share, silence_logs=quiet)
            client = Client(cluster)
        else:
            try:
                client = Client(scheduler, timeout=CONNECT_TIMEOUT_S)
            except (OSError, TimeoutError, ValueError) as exc:
                raise ServoscopeError(f"Dask scheduler {scheduler}: cannot connect ({exc})") from None
            try:
                client.wait_for_workers(1, timeout=WORKER_WAIT_S)
            except (TimeoutError, OSError):
                raise ServoscopeError(
                    f"Dask scheduler {scheduler}: no worker joined within {WORKER_WAIT_S:.0f} s"
                ) from None
        yield client
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
        for lg, level in zip(loggers, levels):
            lg.setLevel(level)
