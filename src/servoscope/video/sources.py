"""Opening any frame source: an image sequence or a high-speed raw file, by its path.

The path strings and the conversion live in :mod:`servoscope.video.frame_source`;
the readers in :mod:`servoscope.video.sequence` and :mod:`servoscope.video.highspeed`.
"""

from __future__ import annotations

import hashlib

import numpy as np

from pathlib import Path
from typing import Callable, Iterator

from .frame_source import FrameSource, parse_frame_source
from .highspeed import PhantomCine, PhotronMraw
from .sequence import ImageSequence

__all__ = ["open_frame_source", "iter_source", "frame_source_digest", "prefetch"]


def open_frame_source(path: str | Path) -> FrameSource:
    """Open an image sequence or a high-speed raw file named by ``path`` (see :func:`frame_source`).

    Raises
    ------
    ServoscopeError
        When the source is missing, unreadable or inconsistent; the message names the file.
    """
    spec = parse_frame_source(path)
    suffix = Path(spec.path).suffix.lower()
    if suffix in (".mraw", ".cih", ".cihx"):
        return PhotronMraw(spec)
    if suffix == ".cine":
        return PhantomCine(spec)
    return ImageSequence(spec)


def iter_source(path: str | Path, convert: Callable[[np.ndarray, int, str | None], object]
                ) -> Iterator[tuple[int, float, object]]:
    """``(index, time_s, convert(samples, bit_depth, bayer))`` for each frame, read one at a time."""
    source = open_frame_source(path)
    try:
        header = source.header
        bayer = parse_frame_source(path).bayer if header.colour.startswith("raw Bayer") else None
        for i in range(header.frame_count):
            yield i, float(header.times_s[i]), convert(source.read(i), header.bit_depth, bayer)
    finally:
        source.close()


def frame_source_digest(path: str | Path, file_digest: Callable[[str], str]) -> str:
    """A digest of a frame source's content: its options, its files' digests, and its timestamps file's."""
    spec = parse_frame_source(path)
    source = open_frame_source(path)
    try:
        files = source.header.files
    finally:
        source.close()
    h = hashlib.blake2b(digest_size=20)
    h.update(repr((spec.fps, spec.start_s, spec.bayer, spec.bits)).encode())
    for f in files + ((spec.timestamps,) if spec.timestamps else ()):
        h.update(file_digest(f).encode())
    return h.hexdigest()


_END = object()


def prefetch(items: Iterator, queue_size: int = 8) -> Iterator:
    """``items`` made on a reader thread, up to ``queue_size`` ahead of the caller.

    Reading and decompressing a frame file (tifffile, OpenCV and zlib release
    the GIL) then overlaps the caller's tracking, as the video decoder thread
    does for video; memory stays bounded by the queue. An exception in the
    reader is raised in the caller, at the item where it happened; closing
    the generator stops the reader.
    """
    import queue as _queue
    import threading

    q: _queue.Queue = _queue.Queue(maxsize=max(1, int(queue_size)))
    stop = threading.Event()

    def put(item) -> bool:
        while not stop.is_set():
            try:
                q.put(item, timeout=0.1)
                return True
            except _queue.Full:
                continue
        return False

    def run() -> None:
        try:
            for item in items:
                if not put(item):
                    return
            put(_END)
        except BaseException as exc:  # noqa: BLE001 - handed to the caller
            put(exc)
        finally:
            close = getattr(items, "close", None)
            if close is not None:
                close()

    worker = threading.Thread(target=run, name="servoscope-read-frames", daemon=True)
    worker.start()
    try:
        while True:
            item = q.get()
            if item is _END:
                return
            if isinstance(item, BaseException):
                raise item
            yield item
    finally:
        stop.set()
        while worker.is_alive():
            try:
                q.get(timeout=0.05)
            except _queue.Empty:
                pass
        worker.join()
