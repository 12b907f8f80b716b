"""A recorded input (issue 31): a sweep test's ``input = "u.csv"``, a pilot's or any arbitrary command.

The file is a CSV with a header line naming a ``time_s`` and a ``command`` column (other
columns are ignored): time in seconds after the input's start, which the LED's switch (or the
test's ``t0_s``) dates like every test's, and the command in input units. :func:`read_input_file`
reads and checks it; :func:`input_band_hz` is the band a test analyses when the manifest gives
none; :func:`write_input_file` writes one (the twin's piloted sweep).

A result (``result.json``) keeps each recorded input's file path (``input``, absolute, where it
was read), its band (``input_band_hz``: the manifest's, else its spectrum's) and the samples
themselves (``input_samples``):
:func:`recorded_input_fields` loads the test back from the samples, so a result still loads, and
its report still draws the input, when the CSV has moved or gone.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import scipy.signal

from .._io import write_text_atomic
from ..errors import ServoscopeError

__all__ = ["INPUT_COLUMNS", "BAND_DB", "input_band_hz", "peak_command", "read_input_file", "recorded_input_entry",
           "recorded_input_fields", "write_input_file"]

#: The columns a recorded input must have: time since the input's start (s) and the command (input units).
INPUT_COLUMNS = ("time_s", "command")
#: How far below its peak the input's autospectrum may fall inside the band analysed by default, dB.
BAND_DB = 20.0


def read_input_file(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """A recorded input's samples: ``(time_s, command)``, checked.

    Parameters
    ----------
    path : path-like
        A comma-separated file whose header names ``time_s`` and ``command``.

    Returns
    -------
    time_s, command : ndarray
        Float arrays of the same length (≥ 2); ``time_s`` strictly increasing and ≥ 0.

    Raises
    ------
    ServoscopeError
        One line naming the file and what to do: missing or unreadable, no ``time_s`` or
        ``command`` column, a value that is not a number, fewer than 2 rows, a time that does
        not increase or is before the start, a value that is not finite.
    """
    path = Path(path)
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:  # utf-8-sig: a spreadsheet's byte-order mark
            rows = [r for r in csv.reader(f) if r and any(c.strip() for c in r)]
    except FileNotFoundError:
        raise ServoscopeError(f"{path}: no such file (give the recorded input's CSV, relative to campaign.toml)"
                              ) from None
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise ServoscopeError(f"{path}: cannot read it ({getattr(exc, 'strerror', None) or exc}): give a text CSV "
                              "with columns time_s and command") from None
    header = [c.strip() for c in rows[0]] if rows else []
    missing = [c for c in INPUT_COLUMNS if c not in header]
    if missing:
        raise ServoscopeError(f"{path}: no {' or '.join(missing)} column (its header line must name time_s and "
                              f"command, comma-separated; found {', '.join(header) or 'nothing'})")
    cols = [header.index(c) for c in INPUT_COLUMNS]
    values = []
    for line, row in enumerate(rows[1:], start=2):
        try:
            values.append([float(row[i]) for i in cols])
        except (IndexError, ValueError):
            raise ServoscopeError(f"{path}: row {line} has no number in time_s or command ({','.join(row)!r}): "
                                  "every row gives both as numbers") from None
    if len(values) < 2:
        raise ServoscopeError(f"{path}: {len(values)} row(s) of samples: a recorded input needs at least 2")
    data = np.asarray(values, dtype=float)
    bad = ~np.isfinite(data).all(axis=1)
    if bad.any():
        raise ServoscopeError(f"{path}: row {int(np.argmax(bad)) + 2} holds a value that is not finite (nan or inf): "
                              "give every time and command as a finite number")
    t, u = data[:, 0], data[:, 1]
    if t[0] < 0:
        raise ServoscopeError(f"{path}: time_s starts at {t[0]:g} s: times are seconds after the input's start "
                              "(the LED's switch), ≥ 0")
    back = np.diff(t) <= 0
    if back.any():
        k = int(np.argmax(back))
        raise ServoscopeError(f"{path}: time_s is not strictly increasing (row {k + 3}: {t[k + 1]:g} s after "
                              f"{t[k]:g} s): sort the rows by time and drop repeated times")
    return t, u


def input_band_hz(time_s, command) -> tuple[float, float]:
    """The band a recorded input excites: where its Welch autospectrum is within :data:`BAND_DB` of its peak.

    The samples are resampled on a uniform grid at their mean rate from the input's start
    (``t = 0``) to the last sample (:func:`~servoscope.sysid.inputs.recorded_command`), and
    their autospectrum estimated with Hann windows half the record long (75 % overlap, the mean
    removed, half a window of rest padded at each end so that the record's first and last
    instants weigh as much as its middle), so that the lowest frequency told from DC is ``2/T``.
    The band runs from the lowest to the highest frequency (DC left out) whose power is at least
    the peak's less 20 dB (1/100).

    Parameters
    ----------
    time_s, command : array_like
        The recording's samples (as :func:`read_input_file` returns them).

    Returns
    -------
    (float, float)
        ``(from_hz, to_hz)``, ``0 < from_hz < to_hz``.

    Raises
    ------
    ServoscopeError
        An input too short to have a band (fewer than 8 samples) or with no variation.
    """
    from ..sysid.inputs import recorded_command

    t = np.asarray(time_s, dtype=float)
    span = float(t[-1])
    rate = (t.size - 1) / (span - float(t[0])) if t.size > 1 and span > t[0] else 0.0
    n = int(round(rate * span)) + 1
    if n < 8 or t.size < 8:
        raise ServoscopeError(f"a recorded input of {t.size} samples over {span:g} s has no band: give from_hz "
                              "and to_hz")
    fs = (n - 1) / span
    u = recorded_command(np.linspace(0.0, span, n), t, command)
    # Half a window of the input's rest before the start (0) and after the end (its last value):
    # a Hann window's centre then passes over the first and last instants, which a chirp's ends
    # (its lowest and highest frequencies) would otherwise barely weigh.
    seg = max(n // 2, 4)
    u = np.concatenate([np.zeros(seg // 2), u, np.full(seg // 2, u[-1])])
    f, pxx = scipy.signal.welch(u, fs=fs, nperseg=seg, noverlap=3 * seg // 4, detrend="constant")
    f, pxx = f[1:], pxx[1:]
    if not np.any(pxx > 0):
        raise ServoscopeError("a recorded input that does not vary has no band: its command is constant")
    inside = np.nonzero(pxx >= pxx.max() * 10.0 ** (-BAND_DB / 10.0))[0]
    lo, hi = float(f[inside[0]]), float(f[inside[-1]])
    if not hi > lo:  # one bin: the band is that bin's width about it
        step = float(f[1] - f[0]) if f.size > 1 else lo
        lo, hi = max(lo - 0.5 * step, 0.5 * lo), hi + 0.5 * step
    return lo, hi


def write_input_file(path: str | Path, time_s, command) -> Path:
    """Write a recorded input as :func:`read_input_file` reads it (``time_s,command``, full precision)."""
    path = Path(path)
    t, u = np.asarray(time_s, dtype=float), np.asarray(command, dtype=float)
    if t.shape != u.shape or t.ndim != 1 or not (np.isfinite(t).all() and np.isfinite(u).all()):
        raise ServoscopeError(f"{path}: time and command must be finite, one-dimensional and of one length")
    lines = [",".join(INPUT_COLUMNS)] + [f"{a!r},{b!r}" for a, b in zip(t.tolist(), u.tolist())]
    try:
        write_text_atomic(path, "\n".join(lines) + "\n")
    except OSError as exc:
        raise ServoscopeError(f"{path}: cannot write ({exc.strerror or exc})") from None
    return path


def peak_command(command) -> float:
    """The recording's largest ``|command|`` (a test's amplitude when the manifest gives none)."""
    peak = float(np.max(np.abs(np.asarray(command, dtype=float))))
    return peak if math.isfinite(peak) else math.nan


def recorded_input_entry(test) -> dict:
    """A recorded input's part of its test's ``result.json`` entry: the file, its band, the samples."""
    return {"input": str(test.input_file), "input_band_hz": [float(v) for v in test.sweep_band_hz],
            "input_samples": {"time_s": np.asarray(test.input_time_s, float).tolist(),
                              "command": np.asarray(test.input_command, float).tolist()}}


def recorded_input_fields(entry: dict, result_path: Path) -> dict:
    """The TestSpec fields of a ``result.json`` test entry's recorded input; empty without one.

    The samples come from the entry (:func:`recorded_input_entry`); a result without them is read
    from the file where it was, else beside the result.
    """
    if not entry.get("input"):
        return {}
    path = Path(entry["input"])
    samples = entry.get("input_samples")
    if isinstance(samples, dict) and "time_s" in samples and "command" in samples:
        t, u = np.asarray(samples["time_s"], dtype=float), np.asarray(samples["command"], dtype=float)
    else:
        where = path if path.is_file() else Path(result_path).parent / path.name
        t, u = read_input_file(where)
    return {"input_file": path, "input_time_s": t, "input_command": u}
