"""A cache of tracks, keyed by what the video contains and how it was tracked.

Tracking is the expensive stage (seconds per video, minutes per campaign);
fitting is cheap. A track is therefore kept on disk under a key made of

* a content hash of the video's bytes (BLAKE2b over the whole file, read in
  1 MiB chunks: about 1 GB/s, so ~3 ms for a 3 MB dwell — see
  docs/performance.md), so a renamed or copied video still hits and a
  re-recorded one with the same name misses;
* every field of the :class:`~servoscope.markers.settings.TrackerSettings`
  (marker colours, camera matrix and distortion, exposure, …);
* :data:`CACHE_FORMAT_VERSION`, the servoscope version, a digest of the
  tracking code's own source files and the versions of the libraries whose
  output the track depends on (NumPy, OpenCV, PyAV): a track cached by other
  code is never mistaken for one this code would produce.

Each entry is two files, ``<key>.npz`` (the arrays) and ``<key>.json`` (the
scalars, lists and metadata), each written under a temporary name and
renamed into place, the JSON last: an entry whose JSON exists is whole. A
run stopped half-way (Ctrl-C, a killed worker) loses only the videos that
were being tracked; the next run finds the others.

Serialisation walks :func:`dataclasses.fields` of :class:`Track`, so fields
added to ``Track`` later round-trip without changes here: arrays go to the
``.npz``, everything else to the JSON. An entry whose field names differ from
the current ``Track``'s is treated as a miss.
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import json
import math
import zipfile
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from ..markers.settings import TrackerSettings
from ..markers.track import Track
from .._io import write_bytes_atomic

__all__ = ["CACHE_FORMAT_VERSION", "TrackCache", "file_digest", "settings_fingerprint", "tracks_equal"]

#: Bump when the on-disk layout or the meaning of a key changes.
CACHE_FORMAT_VERSION = 1

_CHUNK = 1 << 20  # 1 MiB: large enough that the hash, not the syscalls, dominates


def file_digest(path: str | Path, *, chunk_bytes: int = _CHUNK) -> str:
    """BLAKE2b digest of a file's whole content, read in chunks.

    Parameters
    ----------
    path : path-like
    chunk_bytes : int
        Read size (bytes); memory use stays at one chunk whatever the file size.

    Returns
    -------
    str
        40 hex digits (160-bit digest).
    """
    h = hashlib.blake2b(digest_size=20)
    with open(path, "rb") as f:
        # readinto a reused buffer: no allocation per chunk.
        buf = bytearray(chunk_bytes)
        view = memoryview(buf)
        while True:
            n = f.readinto(buf)
            if not n:
                break
            h.update(view[:n])
    return h.hexdigest()


def _canonical(value: Any) -> Any:
    """A JSON-able, deterministic form of settings values (dataclasses, arrays, floats)."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        # Generic over fields: a field added to TrackerSettings or CameraModel
        # enters the key without a change here.
        return {"__type__": type(value).__name__,
                **{f.name: _canonical(getattr(value, f.name)) for f in dataclasses.fields(value)}}
    if isinstance(value, np.ndarray):
        return {"__array__": [list(value.shape), str(value.dtype)], "data": [_canonical(v) for v in value.ravel().tolist()]}
    if isinstance(value, (list, tuple)):
        return [_canonical(v) for v in value]
    if isinstance(value, dict):
        return {str(k): _canonical(v) for k, v in sorted(value.items())}
    if isinstance(value, (np.floating, float)):
        # repr round-trips exactly: 0.1 and 0.1000000000000001 are different keys.
        return repr(float(value))
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (np.bool_,)):
        return bool(value)
    if isinstance(value, Path):
        return str(value)
    return value


def settings_fingerprint(settings: TrackerSettings) -> dict:
    """Everything a track depends on besides the video: settings, code and versions.

    Returns
    -------
    dict
        Plain JSON types; its canonical JSON is hashed into the cache key.
    """
    return {
        "cache_format": CACHE_FORMAT_VERSION,
        "settings": _canonical(settings),
        "code": _code_identity(),
    }


@lru_cache(maxsize=1)
def _code_identity() -> dict:
    import av
    import cv2

    from .. import __version__

    # The tracker's own sources: a changed tracker (a new release, or a
    # developer's edit under an unchanged version number) must not reuse
    # tracks made by the old one.
    root = Path(__file__).resolve().parents[1]
    files = sorted(root.joinpath("markers").glob("*.py")) + [
        root / "video" / "reader.py",
        *(root / "video" / f"{name}.py" for name in ("planes", "frame_source", "sources", "sequence", "highspeed",
                                                     "native")),
        root / "camera" / "model.py",
        root / "camera" / "plane.py",
        root / "camera" / "plane_map.py",
    ]
    h = hashlib.blake2b(digest_size=16)
    for path in files:
        if path.exists():
            h.update(path.relative_to(root).as_posix().encode())
            h.update(path.read_bytes())
    return {
        "servoscope": __version__,
        "tracker_source": h.hexdigest(),
        "numpy": np.__version__,
        "opencv": cv2.__version__,
        "av": av.__version__,
    }


def _key(video_digest: str, fingerprint: dict) -> str:
    text = json.dumps({"video": video_digest, **fingerprint}, sort_keys=True, separators=(",", ":"))
    return hashlib.blake2b(text.encode(), digest_size=16).hexdigest()


def _npz_bytes(arrays: dict[str, np.ndarray]) -> bytes:
    """An ``.npz`` (what :func:`numpy.load` reads) deflated at level 1.

    The snapshot frame dominates and shrinks 4.5× at level 1 (1.34 → 0.30 MB
    for a 720×576 frame) in 12 ms, where ``np.savez_compressed``'s level 6
    takes 41 ms for 0.23 MB: on a campaign's local cluster the calling
    process stores every track while the workers track, on the same cores.
    """
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED, compresslevel=1) as archive:
        for name, value in arrays.items():
            with archive.open(f"{name}.npy", "w", force_zip64=True) as member:
                np.lib.format.write_array(member, np.asanyarray(value), allow_pickle=False)
    return buffer.getvalue()


class TrackCache:
    """Tracks on disk under ``root``, one ``.npz`` + ``.json`` pair per key.

    Parameters
    ----------
    root : path-like
        Folder of the cache, e.g. ``<out>/.cache``; created on the first store.
        Entries go to ``root/tracks/``.

    Examples
    --------
    >>> cache = TrackCache("out/.cache")                       # doctest: +SKIP
    >>> key = cache.key("dwell_01.mp4", settings)              # doctest: +SKIP
    >>> track = cache.load(key) or track_video("dwell_01.mp4", settings)  # doctest: +SKIP
    >>> cache.store(key, track)                                # doctest: +SKIP
    """

    def __init__(self, root: str | Path):
        self.root = Path(root)
        self.folder = self.root / "tracks"

    def __repr__(self) -> str:
        return f"TrackCache({str(self.root)!r})"

    def key(self, video: str | Path, settings: TrackerSettings) -> str:
        """The cache key of tracking ``video`` with ``settings`` (32 hex digits).

        Hashes the video's whole content (see :func:`file_digest`).
        """
        from ..video.frame_source import is_frame_source
        from ..video.sources import frame_source_digest

        digest = frame_source_digest(video, file_digest) if is_frame_source(video) else file_digest(video)
        return _key(digest, settings_fingerprint(settings))

    def paths(self, key: str) -> tuple[Path, Path]:
        """The ``.npz`` and ``.json`` files of an entry."""
        return self.folder / f"{key}.npz", self.folder / f"{key}.json"

    def __contains__(self, key: str) -> bool:
        npz, meta = self.paths(key)
        return meta.exists() and npz.exists()

    def load(self, key: str) -> Track | None:
        """The cached track, or None when absent, unreadable or of another layout.

        A damaged entry is a miss, not an error: the video is simply tracked again.
        """
        npz_path, json_path = self.paths(key)
        try:
            meta = json.loads(json_path.read_text(encoding="utf-8"))
            if meta.get("cache_format") != CACHE_FORMAT_VERSION:
                return None
            with np.load(npz_path, allow_pickle=False) as data:
                arrays = {name: data[name] for name in data.files}
        except Exception:  # noqa: BLE001 - truncated zip, bad zlib stream, bad JSON…: all just a miss
            return None
        values = meta.get("values", {})
        names = {f.name for f in dataclasses.fields(Track)}
        if set(arrays) | set(values) != names or set(arrays) & set(values):
            # Written by a Track with other fields: not what this code would produce.
            return None
        kwargs = {**values, **arrays}
        try:
            return Track(**kwargs)
        except (TypeError, ValueError):
            return None

    def store(self, key: str, track: Track, *, video: str | Path | None = None, extra: dict | None = None) -> None:
        """Write a track under ``key``, atomically (temporary names, then rename).

        Parameters
        ----------
        key : str
        track : Track
        video : path-like, optional
            Recorded in the metadata, for people looking in the folder.
        extra : dict, optional
            More metadata (plain JSON types), e.g. the tracking time.
        """
        arrays: dict[str, np.ndarray] = {}
        values: dict[str, Any] = {}
        for f in dataclasses.fields(track):
            value = getattr(track, f.name)
            if isinstance(value, np.ndarray) and value.dtype != object:
                arrays[f.name] = value
            else:
                values[f.name] = _plain(value)
        meta = {
            "cache_format": CACHE_FORMAT_VERSION,
            "video": None if video is None else str(video),
            "arrays": sorted(arrays),
            "values": values,
            **(extra or {}),
        }
        self.folder.mkdir(parents=True, exist_ok=True)
        npz_path, json_path = self.paths(key)
        write_bytes_atomic(npz_path, _npz_bytes(arrays))
        # JSON last: its presence marks the entry complete. NaN is allowed
        # (Python's json reads it back) so float fields round-trip exactly.
        write_bytes_atomic(json_path, json.dumps(meta, indent=1, allow_nan=True).encode("utf-8"))

    def clear(self) -> int:
        """Remove every entry; returns how many files were removed."""
        removed = 0
        if self.folder.exists():
            for path in self.folder.iterdir():
                if path.is_file():
                    path.unlink()
                    removed += 1
        return removed


def _plain(value: Any) -> Any:
    """A scalar/list field value as JSON types, exactly (NaN kept as NaN)."""
    if isinstance(value, np.ndarray):  # object arrays only: no .npz without pickle
        return [_plain(v) for v in value.tolist()]
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    return value


def tracks_equal(a: Track, b: Track) -> bool:
    """Whether two tracks are identical, field by field: arrays bit for bit (dtype, shape, bytes), NaN equal to NaN.

    Parameters
    ----------
    a, b : Track

    Returns
    -------
    bool
    """
    if type(a) is not type(b):
        return False
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
            if not (isinstance(x, np.ndarray) and isinstance(y, np.ndarray)):
                return False
            # Bytes, not values: bit-identical (−0.0 ≠ 0.0, NaN payloads alike).
            if x.dtype != y.dtype or x.shape != y.shape:
                return False
            if np.ascontiguousarray(x).tobytes() != np.ascontiguousarray(y).tobytes():
                return False
        elif isinstance(x, float) and isinstance(y, float):
            if not (x == y or (math.isnan(x) and math.isnan(y))):
                return False
        elif x != y:
            return False
    return True
