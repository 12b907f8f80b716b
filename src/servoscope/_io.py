"""Writing output files whole or not at all: servoscope's one atomic writer.

Every file servoscope writes (result.json, report.html, figures, CSV tables,
cached tracks, overlay videos) is written under a temporary name beside its
destination and renamed into place when whole. A reader, or a user after a
crash or Ctrl-C, sees the old file or the new one, never half of one; a
failed write leaves no temporary file behind.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from .results import jsonable

__all__ = ["atomic_path", "write_bytes_atomic", "write_json_atomic", "write_text_atomic"]


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary path beside ``path``, renamed onto it when the block ends without an error.

    For writers that want a path of their own (a codec, ``numpy.savez``,
    ``Figure.savefig``): the temporary name keeps the destination's suffix,
    so that writers choosing a format by it choose the same one.

    Parameters
    ----------
    path : str or path-like
        The destination; its folder must exist.

    Yields
    ------
    Path
        Where to write; on an error it is deleted and the error raised.
    """
    path = Path(path)
    # The process id keeps two processes writing the same file (two workers
    # caching one video) from writing into each other's temporary file.
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp{path.suffix}")
    try:
        yield tmp
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)


def write_bytes_atomic(path: str | Path, data: bytes) -> None:
    """Write bytes to ``path`` whole or not at all (see :func:`atomic_path`)."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def write_text_atomic(path: str | Path, text: str) -> None:
    """Write UTF-8 text to ``path`` whole or not at all (see :func:`atomic_path`)."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def write_json_atomic(path: str | Path, data: Any) -> None:
    """Write ``data`` as indented JSON (NaN refused; numpy types made plain by :func:`servoscope.results.jsonable`)."""
    write_text_atomic(path, json.dumps(jsonable(data), indent=2, allow_nan=False) + "\n")
