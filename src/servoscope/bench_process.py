"""A whole process timed from outside: what the benchmarks' whole-command rows are made of."""

from __future__ import annotations

import subprocess
import time

__all__ = ["run_process"]


def run_process(argv: list[str]) -> float:
    """Wall-clock seconds of one process, start-up included.

    Raises
    ------
    RuntimeError
        When the process fails (its command line and the end of its stderr).
    """
    start = time.perf_counter()
    done = subprocess.run(argv, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(argv)} failed:\n{done.stderr[-2000:]}")
    return seconds
