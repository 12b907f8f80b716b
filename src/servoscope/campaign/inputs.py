"""A campaign test's input: :class:`TestSpec` (one recording and its command), and the
``[[tests]]`` keys that say the input (kind, amplitude, frequency, a sweep's), checked.

:func:`~servoscope.campaign.sections.tests_section` reads each ``[[tests]]`` table with
:func:`check_input`; a test's command, any kind, is :meth:`TestSpec.command`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..sysid.inputs import sweep_command, sweep_problems

__all__ = ["TestSpec", "KINDS", "SWEEP_KEYS", "SWEEP_SHAPE", "check_input", "stated_fps"]

#: The kinds of test.
KINDS = ("sine", "step", "sweep")
#: A sweep test's own keys (``kind = "sweep"``): its frequencies, length and shape.
SWEEP_KEYS = ("from_hz", "to_hz", "duration_s", "shape")
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
        A sweep's start and end frequencies (Hz); None for the other kinds.
    duration_s : float or None
        A sweep's length (s); None for the other kinds.
    shape : {"log", "linear"} or None
        A sweep's frequency law ("log" when the manifest says none); None for the other kinds.
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

    @property
    def highest_frequency_hz(self) -> float | None:
        """The highest frequency the input holds: a sine's, a sweep's ``to_hz``; None for a step."""
        return self.to_hz if self.kind == "sweep" else self.frequency_hz

    def command(self, t_rel_s):
        """The test's input at ``t_rel_s`` seconds after its start (0 before), input units.

        A sine's ``amplitude·sin(2π f t)``, a step's ``amplitude``, a sweep's
        :func:`~servoscope.sysid.inputs.sweep_command` (0 after the sweep too): what the
        twin's :class:`~servoscope.simulate.InputSignal` of the same test gives at ``t0 + t``.
        """
        t = np.asarray(t_rel_s, dtype=float)
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


def check_input(problems, where: str, entry: dict, fps: float | None = None
                ) -> tuple[bool, str, float | None, float | None, dict]:
    """A test's kind, amplitude, frequency and sweep, checked: (ok, kind, amplitude, frequency, sweep fields).

    ``problems`` is the manifest's :class:`~servoscope.campaign.sections.Problems`; ``fps``, the
    frame rate the manifest states (:func:`stated_fps`), bounds a sweep's ``to_hz``.
    """
    ok = True
    kind = entry.get("kind")
    if kind not in KINDS:
        problems.add(f"{where}.kind", f"unknown kind {kind!r} (use \"sine\", \"step\" or \"sweep\")")
        ok = False
    amplitude = None
    if "amplitude" not in entry:
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
    if kind == "sweep":
        sweep_ok, sweep = _sweep_input(problems, where, entry, fps)
        ok = ok and sweep_ok
    elif kind in KINDS:
        for key in SWEEP_KEYS:
            if key in entry:
                problems.add(f"{where}.{key}", f"only a sweep test (kind = \"sweep\") has {key}")
                ok = False
    return ok, kind, amplitude, frequency, sweep
