"""The campaign manifest (``campaign.toml``): schema and validation.

Validation happens before anything is written: a manifest that fails leaves
the output folder untouched. Unknown keys are refused (with the nearest known
key suggested), since a typo in a hand-typed manifest would otherwise be
silently ignored.
"""

from __future__ import annotations

import difflib
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from ..camera.model import CameraModel
from ..errors import ServoscopeError
from ..markers.colour import parse_colour

__all__ = ["TestSpec", "Campaign", "load_campaign"]

# [plan] is written by `servoscope plan` / `drive` (dwell lengths, rig settings): kept, not interpreted here.
_TOP_KEYS = {"camera", "markers", "input", "tests", "analysis", "plan"}
_CAMERA_KEYS = {"calibration", "exposure_s"}
_MARKER_KEYS = {"lead", "trail", "led"}
_INPUT_KEYS = {"units"}
_ANALYSIS_KEYS = {"settle_s"}
_TEST_KEYS = {"video", "kind", "frequency_hz", "amplitude", "t0_s", "label"}
_KINDS = ("sine", "step")


@dataclass(frozen=True)
class TestSpec:
    """One recording of the campaign.

    Attributes
    ----------
    video : Path
        Absolute path of the recording.
    kind : {"sine", "step"}
    amplitude : float
        Sine amplitude or step size, input units.
    frequency_hz : float or None
        Sine frequency (Hz); None for a step.
    t0_s : float or None
        Input start given by the manifest (when there is no LED).
    label : str
        Name in tables and file names (the video's file name by default).
    """

    __test__ = False  # not a pytest test class despite its name

    video: Path
    kind: str
    amplitude: float
    frequency_hz: float | None = None
    t0_s: float | None = None
    label: str = ""


@dataclass(frozen=True)
class Campaign:
    """A validated campaign: markers, camera, and the recordings.

    Attributes
    ----------
    path : Path
        The manifest file.
    lead, trail : str
        Marker colours as written ("#rrggbb", CSS name, or "auto").
    led : str or None
    camera : CameraModel or None
    exposure_s : float or None
    input_units : str
    settle_s : float
        Time skipped after the input starts before a dwell's steady state (s).
    tests : tuple of TestSpec
    """

    path: Path
    lead: str
    trail: str
    led: str | None
    camera: CameraModel | None
    exposure_s: float | None
    input_units: str
    settle_s: float
    tests: tuple[TestSpec, ...] = field(default_factory=tuple)

    @property
    def sine_tests(self) -> list[TestSpec]:
        return [t for t in self.tests if t.kind == "sine"]

    @property
    def step_tests(self) -> list[TestSpec]:
        return [t for t in self.tests if t.kind == "step"]

    @classmethod
    def load(cls, path: str | Path, *, check_videos: bool = True) -> "Campaign":
        """Read and validate a manifest; see :func:`load_campaign`."""
        return load_campaign(path, check_videos=check_videos)


def _unknown(path: Path, where: str, keys, allowed: set[str]) -> None:
    for key in keys:
        if key not in allowed:
            near = difflib.get_close_matches(key, sorted(allowed), n=1)
            hint = f" (did you mean {near[0]!r}?)" if near else f" (known: {', '.join(sorted(allowed))})"
            raise ServoscopeError(f"{path}: unknown key {key!r} in {where}{hint}")


def _number(path: Path, where: str, value, *, positive: bool = False, nonzero: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ServoscopeError(f"{path}: {where} must be a finite number, got {value!r}")
    if positive and value <= 0:
        raise ServoscopeError(f"{path}: {where} must be > 0, got {value!r}")
    if nonzero and value == 0:
        raise ServoscopeError(f"{path}: {where} must not be 0")
    return float(value)


def _table(path: Path, data: dict, name: str) -> dict:
    value = data.get(name, {})
    if not isinstance(value, dict):
        raise ServoscopeError(f"{path}: [{name}] must be a table")
    return value


def load_campaign(path: str | Path, *, check_videos: bool = True) -> Campaign:
    """Read and validate ``campaign.toml``.

    Parameters
    ----------
    path : path-like
    check_videos : bool
        Also check that every video exists and opens as a video.

    Raises
    ------
    ServoscopeError
        On the first problem, naming the file and the entry.
    """
    path = Path(path)
    try:
        text = path.read_bytes().decode("utf-8")
    except FileNotFoundError:
        raise ServoscopeError(f"{path}: campaign manifest not found") from None
    except IsADirectoryError:
        raise ServoscopeError(f"{path}: is a folder, not a campaign manifest") from None
    except UnicodeDecodeError:
        raise ServoscopeError(f"{path}: not a TOML file (not UTF-8 text)") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ServoscopeError(f"{path}: not valid TOML ({exc})") from None
    base = path.resolve().parent
    _unknown(path, "the manifest", data.keys(), _TOP_KEYS)

    camera_t = _table(path, data, "camera")
    _unknown(path, "[camera]", camera_t.keys(), _CAMERA_KEYS)
    camera = None
    if "calibration" in camera_t:
        if not isinstance(camera_t["calibration"], str):
            raise ServoscopeError(f"{path}: [camera] calibration must be a file name")
        camera = CameraModel.load(base / camera_t["calibration"])
    exposure = None
    if "exposure_s" in camera_t:
        exposure = _number(path, "[camera] exposure_s", camera_t["exposure_s"], positive=True)

    markers_t = _table(path, data, "markers")
    _unknown(path, "[markers]", markers_t.keys(), _MARKER_KEYS)
    for key in ("lead", "trail"):
        if key not in markers_t:
            raise ServoscopeError(f"{path}: [markers] needs {key} = \"#rrggbb\" (or a CSS name, or \"auto\")")
    for key in ("lead", "trail", "led"):
        if key in markers_t:
            parse_colour(markers_t[key], what=f"{path}: [markers] {key}")
    if markers_t.get("led") is not None and str(markers_t["led"]).strip().lower() == "auto":
        raise ServoscopeError(f"{path}: [markers] led must be a colour, not \"auto\"")

    input_t = _table(path, data, "input")
    _unknown(path, "[input]", input_t.keys(), _INPUT_KEYS)
    units = input_t.get("units", "normalized")
    if not isinstance(units, str):
        raise ServoscopeError(f"{path}: [input] units must be text")

    analysis_t = _table(path, data, "analysis")
    _unknown(path, "[analysis]", analysis_t.keys(), _ANALYSIS_KEYS)
    settle = _number(path, "[analysis] settle_s", analysis_t.get("settle_s", 0.5))
    if settle < 0:
        raise ServoscopeError(f"{path}: [analysis] settle_s must be ≥ 0")

    raw_tests = data.get("tests")
    if not isinstance(raw_tests, list) or not raw_tests:
        raise ServoscopeError(f"{path}: no [[tests]]: list at least one recording")
    tests = []
    labels: set[str] = set()
    for i, entry in enumerate(raw_tests, start=1):
        where = f"[[tests]] #{i}"
        if not isinstance(entry, dict):
            raise ServoscopeError(f"{path}: {where} must be a table")
        _unknown(path, where, entry.keys(), _TEST_KEYS)
        video = entry.get("video")
        if not isinstance(video, str) or not video:
            raise ServoscopeError(f"{path}: {where} needs video = \"file name\"")
        kind = entry.get("kind")
        if kind not in _KINDS:
            raise ServoscopeError(f"{path}: {where} ({video}): unknown kind {kind!r} (use \"sine\" or \"step\")")
        if "amplitude" not in entry:
            raise ServoscopeError(f"{path}: {where} ({video}): needs amplitude")
        amplitude = _number(path, f"{where} ({video}) amplitude", entry["amplitude"], nonzero=True)
        frequency = None
        if kind == "sine":
            if "frequency_hz" not in entry:
                raise ServoscopeError(f"{path}: {where} ({video}): a sine test needs frequency_hz")
            frequency = _number(path, f"{where} ({video}) frequency_hz", entry["frequency_hz"], positive=True)
            if amplitude < 0:
                raise ServoscopeError(f"{path}: {where} ({video}) amplitude of a sine must be > 0")
        elif "frequency_hz" in entry:
            raise ServoscopeError(f"{path}: {where} ({video}): a step test has no frequency_hz")
        t0 = None
        if "t0_s" in entry:
            t0 = _number(path, f"{where} ({video}) t0_s", entry["t0_s"])
        label = entry.get("label", Path(video).stem)
        if not isinstance(label, str) or not label:
            raise ServoscopeError(f"{path}: {where} label must be text")
        if label in labels:
            raise ServoscopeError(f"{path}: {where}: label {label!r} used twice")
        labels.add(label)
        video_path = (base / video).resolve()
        tests.append(TestSpec(video_path, kind, amplitude, frequency, t0, label))

    if check_videos:
        from ..video.reader import probe_video  # deferred: PyAV is slow to import

        for test in tests:
            probe_video(test.video)

    return Campaign(
        path=path.resolve(),
        lead=str(markers_t["lead"]),
        trail=str(markers_t["trail"]),
        led=None if markers_t.get("led") is None else str(markers_t["led"]),
        camera=camera,
        exposure_s=exposure,
        input_units=units,
        settle_s=settle,
        tests=tuple(tests),
    )
