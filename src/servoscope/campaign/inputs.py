"""A campaign test's input: :class:`TestSpec` (one recording and its command), and the
``[[tests]]`` keys that say the input (kind, amplitude, frequency, a sweep's chirp or its recorded
input ``input = "u.csv"``, :mod:`~servoscope.campaign.recorded_input`), checked.

:func:`~servoscope.campaign.sections.tests_section` reads each ``[[tests]]`` table with
:func:`check_input`; a test's command, any kind, is :meth:`TestSpec.command`.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import ServoscopeError
from ..sysid.inputs import recorded_command, sweep_command, sweep_problems
from .recorded_input import input_band_hz, peak_command, read_input_file

__all__ = ["TestSpec", "KINDS", "SWEEP_KEYS", "SWEEP_SHAPE", "check_input", "stated_fps"]

#: The kinds of test.
KINDS = ("sine", "step", "sweep")
#: A sweep test's own keys (``kind = "sweep"``): its frequencies, length and shape, or a recorded
#: input (``input = "u.csv"``, :mod:`servoscope.campaign.recorded_input`) with an optional band.
SWEEP_KEYS = ("from_hz", "to_hz", "duration_s", "shape", "input")
#: A sweep's shape when the manifest names none.
SWEEP_SHAPE = "log"


@dataclass(frozen=True)
class TestSpec:
    """One recording of the campaign.

    Attributes
    ----------
    video : Path
        Absolute path of the recording (a frame source's path string with its
        options, ``…/dwell_01/*.tif#fps=2000``, for ``frames = …``); None in a
        plan, before the rig has recorded it.
    kind : {"sine", "step", "sweep"}
    amplitude : float
        Sine or sweep amplitude, or step size, input units.
    frequency_hz : float or None
        Sine frequency (Hz); None for a step or a sweep.
    t0_s : float or None
        Input start given by the manifest (when there is no LED).
    label : str
        Name in tables and file names (the video's file name by default).
    frames : bool
        Given as ``frames = …`` (an image sequence or a high-speed raw file), not ``video = …``.
    from_hz, to_hz : float or None
        A sweep's start and end frequencies (Hz); None for the other kinds. For a recorded
        input, the band the manifest gives, or None (the input's own: :attr:`sweep_band_hz`).
    duration_s : float or None
        A sweep's length (s); None for the other kinds and a recorded input.
    shape : {"log", "linear"} or None
        A sweep's frequency law ("log" when the manifest says none); None for the other kinds
        and a recorded input.
    input_file : Path or None
        A recorded input's CSV (absolute), ``input = "u.csv"``; None for a chirp and the other kinds.
    input_time_s, input_command : ndarray or None
        The recorded input's samples (seconds after the input's start, input units), read
        when the manifest was; None without a recorded input.
    """

    __test__ = False  # not a pytest test class despite its name

    video: Path
    kind: str
    amplitude: float
    frequency_hz: float | None = None
    t0_s: float | None = None
    label: str = ""
    frames: bool = False
    from_hz: float | None = None
    to_hz: float | None = None
    duration_s: float | None = None
    shape: str | None = None
    input_file: Path | None = None
    input_time_s: np.ndarray | None = field(default=None, compare=False, repr=False)
    input_command: np.ndarray | None = field(default=None, compare=False, repr=False)

    @property
    def recorded(self) -> bool:
        """Whether the input is a recorded one (``input = "u.csv"``), not a chirp."""
        return self.input_time_s is not None

    @functools.cached_property
    def sweep_band_hz(self) -> tuple[float, float] | None:
        """A sweep's band: its ``(from_hz, to_hz)``; a recorded input's as given, else its own.

        A recorded input's own band (:func:`~servoscope.campaign.recorded_input.input_band_hz`) is
        where its Welch autospectrum is within 20 dB of its peak; a bound the manifest gives
        replaces that end. None for a sine or a step.
        """
        if self.kind != "sweep":
            return None
        if not self.recorded or (self.from_hz is not None and self.to_hz is not None):
            return float(self.from_hz), float(self.to_hz)
        lo, hi = input_band_hz(self.input_time_s, self.input_command)
        return (lo if self.from_hz is None else float(self.from_hz)), (hi if self.to_hz is None else float(self.to_hz))

    @property
    def input_duration_s(self) -> float | None:
        """How long the input is driven: a chirp's ``duration_s``, a recorded input's last time; None otherwise."""
        if self.recorded:
            return float(self.input_time_s[-1])
        return self.duration_s

    @property
    def highest_frequency_hz(self) -> float | None:
        """The highest frequency the input holds: a sine's, a sweep's ``to_hz`` (a recorded input's band's top);
        None for a step."""
        return self.sweep_band_hz[1] if self.kind == "sweep" else self.frequency_hz

    def command(self, t_rel_s):
        """The test's input at ``t_rel_s`` seconds after its start (0 before), input units.

        A sine's ``amplitude·sin(2π f t)``, a step's ``amplitude``, a sweep's
        :func:`~servoscope.sysid.inputs.sweep_command` (0 after the sweep too), a recorded
        input's samples joined by straight lines
        (:func:`~servoscope.sysid.inputs.recorded_command`: the first value from the start to
        the first sample, the last after the last): what the twin's
        :class:`~servoscope.simulate.InputSignal` of the same test gives at ``t0 + t``.
        """
        t = np.asarray(t_rel_s, dtype=float)
        if self.recorded:
            return recorded_command(t, self.input_time_s, self.input_command)
        if self.kind == "sweep":
            return sweep_command(t, self.amplitude, self.from_hz, self.to_hz, self.duration_s, self.shape)
        if self.kind == "sine":
            v = self.amplitude * np.sin(2.0 * math.pi * float(self.frequency_hz) * t)
        else:
            v = np.full_like(t, self.amplitude)
        return np.where(t >= 0.0, v, 0.0)


def stated_fps(data: dict, entry: dict) -> float | None:
    """The frame rate the manifest states for a test: its frame source's ``fps``, else ``[plan] fps``; None."""
    for value in (entry.get("fps"), data.get("plan", {}).get("fps") if isinstance(data.get("plan"), dict) else None):
        if isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value > 0:
            return float(value)
    return None


def _sweep_input(problems, where: str, entry: dict, fps: float | None) -> tuple[bool, dict]:
    """A sweep test's ``from_hz``, ``to_hz``, ``duration_s`` and ``shape``, checked: (ok, the TestSpec fields).

    ``fps``: the frame rate where the manifest says it (a frame source's ``fps``, a plan's
    ``[plan] fps``): ``to_hz`` must stay below half of it.
    """
    if "frequency_hz" in entry:
        problems.add(f"{where}.frequency_hz", "a sweep test has from_hz and to_hz, not frequency_hz")
    shape = entry.get("shape", SWEEP_SHAPE)
    found = sweep_problems(entry.get("from_hz"), entry.get("to_hz"), entry.get("duration_s"), shape)
    for key, message in found:
        problems.add(f"{where}.{key}", message)
    ok = not found and "frequency_hz" not in entry
    if ok and fps and entry["to_hz"] >= 0.5 * fps:
        problems.add(f"{where}.to_hz", f"{entry['to_hz']:g} Hz is at or above half the frame rate ({fps:g} frames/s): "
                     "the camera cannot resolve it")
        ok = False
    if not ok:
        return False, {}
    return True, {"from_hz": float(entry["from_hz"]), "to_hz": float(entry["to_hz"]),
                  "duration_s": float(entry["duration_s"]), "shape": shape}


def _band(problems, where: str, entry: dict, fps: float | None) -> bool:
    """A recorded input's optional ``from_hz`` and ``to_hz``, checked (each > 0, ``to_hz`` > ``from_hz``)."""
    ok = True
    for key in ("from_hz", "to_hz"):
        if key in entry:
            ok = problems.number(f"{where}.{key}", entry[key], positive=True) is not None and ok
    if ok and "from_hz" in entry and "to_hz" in entry and not entry["to_hz"] > entry["from_hz"]:
        problems.add(f"{where}.to_hz", f"must be > from_hz ({entry['from_hz']:g} Hz), got {entry['to_hz']:g}")
        ok = False
    if ok and fps and "to_hz" in entry and entry["to_hz"] >= 0.5 * fps:
        problems.add(f"{where}.to_hz", f"{entry['to_hz']:g} Hz is at or above half the frame rate ({fps:g} "
                     "frames/s): the camera cannot resolve it")
        ok = False
    return ok


def _recorded_input(problems, where: str, entry: dict, fps: float | None, base: Path | None) -> tuple[bool, dict]:
    """A sweep test's ``input = "u.csv"`` (and its optional band), checked and read: (ok, the TestSpec fields).

    Every problem is one line naming the test and the file (:func:`~servoscope.campaign.recorded_input.
    read_input_file`'s); a chirp's ``duration_s`` or ``shape`` beside it is refused (the file has both).
    """
    name = entry["input"]
    if not isinstance(name, str) or not name or "\x00" in name:
        problems.add(f"{where}.input", f"must be the recorded input's CSV file name (time_s, command), got {name!r}")
        return False, {}
    ok = True
    for key in ("duration_s", "shape"):
        if key in entry:
            problems.add(f"{where}.{key}", f"a recorded input ({name}) has its own length and shape: leave out {key}")
            ok = False
    if "frequency_hz" in entry:
        problems.add(f"{where}.frequency_hz", "a sweep test has from_hz and to_hz (optional with input), not "
                     "frequency_hz")
        ok = False
    ok = _band(problems, where, entry, fps) and ok
    path = ((base or Path.cwd()) / name).resolve()
    try:
        t, u = read_input_file(path)
    except ServoscopeError as exc:
        problems.add(f"{where}.input", str(exc))
        return False, {}
    if not ok:
        return False, {}
    fields = {"input_file": path, "input_time_s": t, "input_command": u,
              **{k: float(entry[k]) for k in ("from_hz", "to_hz") if k in entry}}
    try:
        TestSpec(None, "sweep", 1.0, **fields).sweep_band_hz  # noqa: B018 (a constant input has no band)
    except ServoscopeError as exc:
        problems.add(f"{where}.input", f"{path}: {exc}")
        return False, {}
    return True, fields


def check_input(problems, where: str, entry: dict, fps: float | None = None, base: Path | None = None
                ) -> tuple[bool, str, float | None, float | None, dict]:
    """A test's kind, amplitude, frequency and sweep, checked: (ok, kind, amplitude, frequency, sweep fields).

    ``problems`` is the manifest's :class:`~servoscope.campaign.sections.Problems`; ``fps``, the
    frame rate the manifest states (:func:`stated_fps`), bounds a sweep's ``to_hz``; ``base``, the
    manifest's folder, is where a recorded input's file (``input = "u.csv"``) is looked for. Such a
    test's amplitude is optional: the file's largest ``|command|`` when the manifest gives none.
    """
    ok = True
    kind = entry.get("kind")
    if kind not in KINDS:
        problems.add(f"{where}.kind", f"unknown kind {kind!r} (use \"sine\", \"step\" or \"sweep\")")
        ok = False
    amplitude = None
    recorded = kind == "sweep" and "input" in entry
    if "amplitude" not in entry and recorded:
        pass  # the file's peak, once it is read
    elif "amplitude" not in entry:
        problems.add(f"{where}.amplitude", "missing")
        ok = False
    else:
        amplitude = problems.number(f"{where}.amplitude", entry["amplitude"], nonzero=True)
        if amplitude is None:
            ok = False
        elif kind in ("sine", "sweep") and amplitude < 0:
            problems.add(f"{where}.amplitude", f"must be > 0 for a {kind}, got {amplitude!r}")
            ok = False
    frequency = None
    if kind == "sine":
        if "frequency_hz" not in entry:
            problems.add(f"{where}.frequency_hz", "missing: a sine test needs its frequency")
            ok = False
        else:
            frequency = problems.number(f"{where}.frequency_hz", entry["frequency_hz"], positive=True)
            ok = ok and frequency is not None
    elif kind == "step" and "frequency_hz" in entry:
        problems.add(f"{where}.frequency_hz", "a step test has no frequency")
    sweep: dict = {}
    if recorded:
        sweep_ok, sweep = _recorded_input(problems, where, entry, fps, base)
        ok = ok and sweep_ok
        if sweep_ok and amplitude is None and "amplitude" not in entry:
            amplitude = peak_command(sweep["input_command"])  # > 0: a constant input was refused (no band)
    elif kind == "sweep":
        sweep_ok, sweep = _sweep_input(problems, where, entry, fps)
        ok = ok and sweep_ok
    elif kind in KINDS:
        for key in SWEEP_KEYS:
            if key in entry:
                problems.add(f"{where}.{key}", f"only a sweep test (kind = \"sweep\") has {key}")
                ok = False
    return ok, kind, amplitude, frequency, sweep
