"""Benchmark: tracking a campaign with 1 and 2 workers, and identify with a warm cache.

Not a test: it prints wall times for docs/performance.md. Run from the
repository root::

    .venv/bin/python benchmarks/campaign_parallel.py [--dir /tmp/servoscope-bench] [--workers 2]

It renders the 14-dwell ``paper`` campaign once (reused on later runs), then

1. hashes every video (the cache key's cost);
2. tracks the campaign in-process (workers=1), into a fresh cache;
3. tracks it on a local Dask cluster (workers=N, start-up included), into
   another fresh cache, and checks the tracks are bit-identical to 2.;
4. identifies once with tracking (the time of 2. plus the fits) and once
   more with the warm cache of 2. (hash, load, fit).

Targets (issue "Campaigns at scale"): 2 workers ≤ 60 % of 1 worker on two
cores; a warm-cache identify ≤ 10 % of the first.
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path


def _cpu_s() -> float:
    t = os.times()
    return t.user + t.system


def _load() -> str:
    try:
        return "%.2f %.2f %.2f" % os.getloadavg()
    except OSError:  # pragma: no cover
        return "?"


def _pin_process_to_one_cpu() -> int:
    """Every thread of this (worker) process onto one CPU; threads started later inherit it."""
    cpu = min(os.sched_getaffinity(0))
    for tid in os.listdir("/proc/self/task"):
        os.sched_setaffinity(int(tid), {cpu})
    return cpu


@contextmanager
def _one_worker_cluster(pinned: bool):
    """A local Dask cluster of one worker with one core's share, as ``track_campaign`` makes them.

    ``pinned``: its process is also held to one CPU. A worker given one
    decoder thread still runs that thread beside its tracking thread, so
    unpinned it uses ~1.2 cores; pinned, it is exactly one core, the unit
    N workers on N cores are measured against.
    """
    from distributed import Client

    from servoscope.campaign.parallel import start_local_cluster

    cluster = start_local_cluster(1, 1, silence_logs=50)
    try:
        if pinned:
            with Client(cluster) as client:
                client.run(_pin_process_to_one_cpu)
        yield cluster.scheduler_address
    finally:
        cluster.close()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dir", type=Path, default=Path(tempfile.gettempdir()) / "servoscope-bench",
                        help="where the paper campaign is rendered (reused when present)")
    parser.add_argument("--workers", type=int, default=2, help="workers of the parallel run")
    parser.add_argument("--preset", default="paper")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--repeat", type=int, default=1,
                        help="time each tracking run this many times, alternating, and keep the fastest "
                             "(the least disturbed by other load on the machine)")
    args = parser.parse_args(argv)

    from servoscope.campaign import identify, load_campaign, track_campaign
    from servoscope.campaign.cache import file_digest, tracks_equal
    from servoscope.campaign.parallel import default_workers
    from servoscope.simulate import simulate_campaign

    campaign_dir = args.dir / f"{args.preset}-seed{args.seed}"
    manifest = campaign_dir / "campaign.toml"
    if not manifest.exists():
        print(f"rendering the '{args.preset}' campaign into {campaign_dir} …", flush=True)
        start = time.perf_counter()
        simulate_campaign(campaign_dir, preset=args.preset, seed=args.seed)
        print(f"  rendered in {time.perf_counter() - start:.1f} s")
    campaign = load_campaign(manifest)
    videos = [t.video for t in campaign.tests]
    size_mb = sum(v.stat().st_size for v in videos) / 1e6
    print(f"campaign: {len(videos)} videos, {size_mb:.1f} MB; {default_workers()} cores available; "
          f"Python {platform.python_version()}; load average {_load()}")

    # 1. The cache key's cost: a BLAKE2b pass over every byte (files in the page cache).
    for v in videos:
        file_digest(v)  # warm the page cache so the figure is the hash, not the disk
    start = time.perf_counter()
    for v in videos:
        file_digest(v)
    hash_s = time.perf_counter() - start
    print(f"hash (BLAKE2b, whole files): {1e3 * hash_s:.0f} ms for {size_mb:.1f} MB = {size_mb / hash_s:.0f} MB/s")

    work = Path(tempfile.mkdtemp(prefix="servoscope-bench-"))
    try:
        # 2. and 3., alternating when repeated so that all see the same background load.
        seq_times, one_times, free_times, par_times, seq_cpus = [], [], [], [], []
        identical = True
        for rep in range(max(1, args.repeat)):
            tag = f"[{rep + 1}/{args.repeat}] " if args.repeat > 1 else ""
            # 2. In-process, one video after the other, into a fresh cache: `--workers 1`
            #    (FFmpeg's decoder threads on every core).
            shutil.rmtree(work / "cache-seq", ignore_errors=True)
            cpu0, start = _cpu_s(), time.perf_counter()
            seq = track_campaign(campaign, workers=1, cache_dir=work / "cache-seq")
            seq_times.append(time.perf_counter() - start)
            seq_cpus.append(_cpu_s() - cpu0)
            frames = sum(t.n_frames for t in seq.values())
            print(f"{tag}in-process (--workers 1): {seq_times[-1]:.1f} s wall ({seq_cpus[-1]:.1f} s CPU), "
                  f"{frames} frames, {1e3 * seq_times[-1] / frames:.2f} ms/frame; load average {_load()}", flush=True)

            # 3a. One Dask worker with one core's share (SERVOSCOPE_THREADS=1, as each of N
            #     workers on N cores gets), start-up included; pinned to one CPU (the unit of
            #     scaling: one core) and not.
            for pinned, times in ((True, one_times), (False, free_times)):
                shutil.rmtree(work / "cache-one", ignore_errors=True)
                start = time.perf_counter()
                with _one_worker_cluster(pinned) as address:
                    one = track_campaign(campaign, scheduler=address, cache_dir=work / "cache-one")
                times.append(time.perf_counter() - start)
                identical &= all(tracks_equal(one[k], seq[k]) for k in seq)
                what = "pinned to one CPU" if pinned else "not pinned"
                print(f"{tag}one Dask worker, one core's share, {what}: {times[-1]:.1f} s wall; "
                      f"load average {_load()}", flush=True)

            # 3b. A local Dask cluster of N workers, its start-up included (what a user waits for).
            shutil.rmtree(work / "cache-par", ignore_errors=True)
            start = time.perf_counter()
            par = track_campaign(campaign, workers=args.workers, cache_dir=work / "cache-par")
            par_times.append(time.perf_counter() - start)
            identical &= list(par) == list(seq) and all(tracks_equal(par[k], seq[k]) for k in seq)
            print(f"{tag}workers={args.workers}: {par_times[-1]:.1f} s wall; tracks bit-identical: {identical}; "
                  f"load average {_load()}", flush=True)
        seq_s, one_s, free_s, par_s = min(seq_times), min(one_times), min(free_times), min(par_times)
        print(f"fastest: workers={args.workers} {par_s:.1f} s = {100 * par_s / one_s:.0f} % of one worker on one core "
              f"({one_s:.1f} s; target ≤ 60 % with 2 workers on 2 cores), {100 * par_s / free_s:.0f} % of one "
              f"worker not pinned ({free_s:.1f} s), {100 * par_s / seq_s:.0f} % of in-process ({seq_s:.1f} s)")

        # 4. identify: first = tracking (measured above) + fits; second = warm cache + fits.
        start = time.perf_counter()
        result = identify(campaign, tracks=seq)
        fit_s = time.perf_counter() - start
        first_s = seq_s + fit_s
        start = time.perf_counter()
        cached = track_campaign(campaign, cache_dir=work / "cache-seq")
        load_s = time.perf_counter() - start
        identify(campaign, tracks=cached)
        warm_s = time.perf_counter() - start
        same = all(tracks_equal(cached[k], seq[k]) for k in seq)
        print(f"identify, first (tracking + fits): {first_s:.1f} s; again with a warm cache: {warm_s:.2f} s "
              f"(hash + load {load_s:.2f} s, fits {warm_s - load_s:.2f} s) = {100 * warm_s / first_s:.1f} % "
              f"(target ≤ 10 %); cached tracks identical: {same}")
        cache_mb = sum(p.stat().st_size for p in (work / "cache-seq").rglob("*") if p.is_file()) / 1e6
        print(f"cache size: {cache_mb:.1f} MB for {len(seq)} tracks")
        print(f"model: K = {result.model.gain:.4g}, wn = {result.model.natural_frequency_rad_s:.4g} rad/s, "
              f"zeta = {result.model.damping_ratio:.3g}")
        return 0 if identical and same else 1
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":  # the guard matters: Dask's worker processes re-import this file
    sys.exit(main())
