"""The campaign manifest (``campaign.toml``): schema and validation.

Validation happens before anything is written: a manifest that fails leaves
the output folder untouched. Every problem in the file is reported at once,
each with its location (``campaign.toml: tests[3].frequency_hz: must be > 0``),
so that a hand-typed manifest is fixed in one pass. Unknown keys are refused
with the nearest known key suggested, since a typo would otherwise be
silently ignored.
"""

from __future__ import annotations

import difflib
import math
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path

from ..camera.model import CameraModel
from ..camera.plane import Plane
from ..defaults import SETTLE_AUTO, SETTLE_S, TIMESTAMP, TIMESTAMPS
from ..errors import ServoscopeError
from ..markers.colour import parse_colour
from ..markers.selection import check_near
from ..markers.settings import extra_marker_problems
from ..video.frame_source import MANIFEST_KEYS, SOURCE_SEPARATOR, manifest_frame_source, source_name

__all__ = ["TestSpec", "Campaign", "load_campaign"]

# [plan] is written by `servoscope plan` / `drive` (dwell lengths, rig settings): kept, not interpreted here.
_TOP_KEYS = {"camera", "markers", "input", "tests", "analysis", "plan", "model"}
_MODEL_KEYS = {"fix", "bound", "tie"}
_CAMERA_KEYS = {"calibration", "exposure_s", "readout_s", "timestamp", "plane"}
_MARKER_KEYS = {"lead", "trail", "led", "reference", "extra"}
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
    settle_s : float or "auto"
        Time skipped after the input starts before a dwell's steady state (s;
        :data:`~servoscope.defaults.SETTLE_S` when the manifest says none), or
        ``"auto"``: each dwell's own, where its transient ends (see
        :func:`servoscope.sysid.fit_sine`).
    tests : tuple of TestSpec
    skipped : tuple of (label, reason)
        Tests left out because their video could not be read (``keep_going``).
    readout_s : float
        Rolling-shutter readout time (s); 0 for a global shutter.
    timestamp : {"middle", "start", "end"}
        Which point of its exposure a frame's timestamp marks (``[camera]
        timestamp``; "middle" by default: :data:`~servoscope.defaults.TIMESTAMPS`).
    lead_near, trail_near : (float, float) or None
        A marker pinned by position (px, first frame), from
        ``lead = {colour = "#…", near = [x, y]}``; None when not pinned.
    led_near : (float, float) or None
        The LED pinned by position (px, first frame; fixed on the stand or on the
        blade), from ``led = {colour = "#…", near = [x, y]}`` or ``{brightness =
        "bright", near = [x, y]}``; None: found by its switch.
    reference : (str, str) or None
        Two stickers on the airframe (``[markers] reference = ["#…", "#…"]``):
        the blade's angle is measured against the line joining them.
    extra : tuple of str
        More stickers along the blade (``[markers] extra = ["#…", …]``), each its
        own colour: each marker's bending across the lead–trail line.
    model_fix, model_bounds : dict
        Model parameters held at a value or within limits (``[model] fix =
        {damping_ratio = 0.8}``, ``bound = {natural_frequency_rad_s = [20, 80]}``).
    model_ties : dict of name → expression
        Parameters computed from others in the time-domain fits (``[model] tie =
        {rate_limit_rad_s = "4*gain"}``).
    plane : Plane or None
        The blade's plane (``[camera] plane = "plane.json"``, from ``servoscope plane``):
        angles are measured in it; None: in the image.
    """

    path: Path
    lead: str
    trail: str
    led: str | None
    camera: CameraModel | None
    exposure_s: float | None
    input_units: str
    settle_s: float | str
    tests: tuple[TestSpec, ...] = field(default_factory=tuple)
    skipped: tuple[tuple[str, str], ...] = field(default_factory=tuple)
    readout_s: float = 0.0
    lead_near: tuple[float, float] | None = None
    trail_near: tuple[float, float] | None = None
    led_near: tuple[float, float] | None = None
    timestamp: str = TIMESTAMP
    reference: tuple[str, str] | None = None
    extra: tuple[str, ...] = ()
    model_fix: dict[str, float] = field(default_factory=dict)
    model_bounds: dict[str, tuple[float, float]] = field(default_factory=dict)
    model_ties: dict[str, str] = field(default_factory=dict)
    plane: Plane | None = None

    def held_parameters(self, fix: dict[str, float] | None = None,
                        bounds: dict[str, tuple[float, float]] | None = None
                        ) -> tuple[dict[str, float], dict[str, tuple[float, float]]]:
        """The model parameters held: the manifest's ``[model]``, with ``fix``/``bounds`` added and winning.

        A parameter fixed by the caller is no longer bounded by the manifest.
        """
        fixed = {**self.model_fix, **(fix or {})}
        bounded = {k: v for k, v in {**self.model_bounds, **(bounds or {})}.items() if k not in (fix or {})}
        return fixed, bounded

    @property
    def sine_tests(self) -> list[TestSpec]:
        return [t for t in self.tests if t.kind == "sine"]

    @property
    def step_tests(self) -> list[TestSpec]:
        return [t for t in self.tests if t.kind == "step"]

    @classmethod
    def load(cls, path: str | Path, *, check_videos: bool = True, keep_going: bool = False) -> "Campaign":
        """Read and validate a manifest; see :func:`load_campaign`."""
        return load_campaign(path, check_videos=check_videos, keep_going=keep_going)

    def without(self, reasons: dict[str, str]) -> "Campaign":
        """The same campaign less some tests, each with the reason it was left out."""
        return replace(self, tests=tuple(t for t in self.tests if t.label not in reasons),
                       skipped=self.skipped + tuple(reasons.items()))


class _Problems:
    """Collects every problem of a manifest, each with its location."""

    def __init__(self, path: Path):
        self.path = path
        self.items: list[str] = []

    def add(self, where: str, message: str) -> None:
        self.items.append(f"{where}: {message}" if where else message)

    def raise_if_any(self) -> None:
        if not self.items:
            return
        if len(self.items) == 1:
            raise ServoscopeError(f"{self.path}: {self.items[0]}")
        raise ServoscopeError(f"{self.path}: {len(self.items)} problems: " + "; ".join(self.items))

    def unknown(self, where: str, keys, allowed: set[str]) -> None:
        for key in keys:
            if key not in allowed:
                near = difflib.get_close_matches(key, sorted(allowed), n=1)
                hint = f" (did you mean {near[0]!r}?)" if near else f" (known: {', '.join(sorted(allowed))})"
                self.add(f"{where}.{key}" if where else key, f"unknown key{hint}")

    def number(self, where: str, value, *, positive: bool = False, nonzero: bool = False, nonnegative: bool = False) -> float | None:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            self.add(where, f"must be a finite number, got {value!r}")
            return None
        if positive and value <= 0:
            self.add(where, f"must be > 0, got {value!r}")
            return None
        if nonnegative and value < 0:
            self.add(where, f"must be ≥ 0, got {value!r}")
            return None
        if nonzero and value == 0:
            self.add(where, "must not be 0")
            return None
        return float(value)

    def table(self, data: dict, name: str) -> dict:
        value = data.get(name, {})
        if not isinstance(value, dict):
            self.add(name, "must be a table")
            return {}
        return value


def _extra_markers(markers_t: dict, colours: dict, reference, problems) -> tuple[str, ...]:
    """``[markers] extra``: colours of more stickers on the blade, each its own and none another marker's."""
    if "extra" not in markers_t:
        return ()
    extra = markers_t["extra"]
    if not (isinstance(extra, list) and extra and all(isinstance(c, str) for c in extra)):
        problems.add("markers.extra", "the colours of more stickers on the blade: extra = [\"#rrggbb\", ...]")
        return ()
    others = {f"the {k}": colours.get(k) for k in ("lead", "trail", "led")}
    others.update({f"reference[{i}]": c for i, c in enumerate(reference or ())})
    for i, why in extra_marker_problems(extra, others):
        problems.add(f"markers.extra[{i}]", why)
    return tuple(str(c) for c in extra)


def _camera_file(problems: "_Problems", camera_t: dict, base: Path, key: str, load, hint: str):
    """``[camera] key = "file"`` read with ``load``; None (and a problem said) when absent or bad."""
    if key not in camera_t:
        return None
    if not isinstance(camera_t[key], str):
        problems.add(f"camera.{key}", f"must be a file name{hint}")
        return None
    try:
        return load(base / camera_t[key])
    except ServoscopeError as exc:
        problems.add(f"camera.{key}", str(exc))
        return None


def load_campaign(path: str | Path, *, check_videos: bool = True, keep_going: bool = False) -> Campaign:
    """Read and validate ``campaign.toml``.

    Parameters
    ----------
    path : path-like
    check_videos : bool
        Also check that every video exists and opens as a video, and that
        no sine frequency reaches half the video's frame rate.
    keep_going : bool
        A video that cannot be read leaves its test out (listed in
        ``Campaign.skipped``) instead of failing the manifest.

    Raises
    ------
    ServoscopeError
        Listing every problem found, each with its location.

    Long because it checks every field of the manifest in one pass and collects every
    problem, so that a user sees them all at once; each check is a few lines.
    """
    path = Path(path)
    try:
        text = path.read_bytes().decode("utf-8")
    except FileNotFoundError:
        raise ServoscopeError(f"{path}: campaign manifest not found") from None
    except IsADirectoryError:
        raise ServoscopeError(f"{path}: is a folder, not a campaign manifest") from None
    except PermissionError:
        raise ServoscopeError(f"{path}: cannot read the manifest (permission denied)") from None
    except UnicodeDecodeError:
        raise ServoscopeError(f"{path}: not a TOML file (not UTF-8 text)") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ServoscopeError(f"{path}: not valid TOML ({exc})") from None
    base = path.resolve().parent
    problems = _Problems(path)
    problems.unknown("", data.keys(), _TOP_KEYS)

    camera_t = problems.table(data, "camera")
    problems.unknown("camera", camera_t.keys(), _CAMERA_KEYS)
    camera = _camera_file(problems, camera_t, base, "calibration", CameraModel.load, "")
    # The blade's plane from a board photo (servoscope plane): angles measured in it.
    plane = _camera_file(problems, camera_t, base, "plane", Plane.load, " (plane.json, from `servoscope plane`)")
    exposure = None
    if "exposure_s" in camera_t:
        exposure = problems.number("camera.exposure_s", camera_t["exposure_s"], positive=True)
    timestamp = camera_t.get("timestamp", TIMESTAMP)
    if timestamp not in TIMESTAMPS:
        problems.add("camera.timestamp", f"{timestamp!r}: which point of its exposure a frame's time marks, one of "
                     + ", ".join(f'"{t}"' + (" (the default)" if t == TIMESTAMP else "") for t in TIMESTAMPS))
        timestamp = TIMESTAMP
    readout = 0.0
    if "readout_s" in camera_t:
        # A rolling shutter's row-to-row delay over the frame (0: global shutter).
        readout = problems.number("camera.readout_s", camera_t["readout_s"], nonnegative=True)

    markers_t = problems.table(data, "markers")
    problems.unknown("markers", markers_t.keys(), _MARKER_KEYS)
    for key in ("lead", "trail"):
        if key not in markers_t:
            problems.add(f"markers.{key}", "missing: give \"#rrggbb\", a CSS colour name, or \"auto\"")
    near: dict[str, tuple[float, float] | None] = {"lead": None, "trail": None, "led": None}
    colours: dict[str, object] = dict(markers_t)
    for key in ("lead", "trail", "led"):
        # A marker (or the LED) pinned by position, as a user clicks a point: {colour = "#…", near = [x, y]}.
        entry = markers_t.get(key)
        if isinstance(entry, dict):
            # A marker told by brightness (monochrome footage) names it instead of a colour.
            unknown = set(entry) - {"colour", "brightness", "near"}
            kind = [k for k in ("colour", "brightness") if k in entry]
            if unknown or len(kind) != 1 or ("near" not in entry and kind != ["brightness"]):
                problems.add(f"markers.{key}", "a pinned marker is {colour = \"#rrggbb\", near = [x, y]} (or "
                             "{brightness = \"bright\", near = [x, y]} on monochrome footage), "
                             f"got keys {sorted(entry)}")
                colours[key] = None
                continue
            colours[key] = entry[kind[0]]
            if kind == ["brightness"] and str(entry["brightness"]).lower() not in ("bright", "dark"):
                problems.add(f"markers.{key}.brightness", f"{entry['brightness']!r}: \"bright\" or \"dark\"")
                colours[key] = None
                continue
            if "near" not in entry:
                continue
            try:
                near[key] = check_near(entry["near"], what="near")
            except ServoscopeError as exc:
                problems.add(f"markers.{key}.near", str(exc).removeprefix("near: "))
    for key in ("lead", "trail", "led"):
        if key in markers_t and colours[key] is not None:
            try:
                spec = parse_colour(colours[key], what="colour")
            except ServoscopeError as exc:
                problems.add(f"markers.{key}", str(exc).removeprefix("colour: "))
            else:
                if key == "led" and spec == "auto":
                    problems.add("markers.led", "must be a colour, not \"auto\"")

    reference = None
    if "reference" in markers_t:
        # Two stickers on the airframe: the blade's angle against the line joining them.
        ref = markers_t["reference"]
        if not (isinstance(ref, list) and len(ref) == 2 and all(isinstance(c, str) for c in ref)):
            problems.add("markers.reference", "two colours of stickers on the airframe: reference = [\"#rrggbb\", "
                         "\"#rrggbb\"]")
        else:
            specs = []
            for i, colour in enumerate(ref):
                try:
                    spec = parse_colour(colour, what="colour")
                except ServoscopeError as exc:
                    problems.add(f"markers.reference[{i}]", str(exc).removeprefix("colour: "))
                    continue
                if spec == "auto":
                    problems.add(f"markers.reference[{i}]", "must be a colour, not \"auto\"")
                specs.append(spec)
            taken = {k: colours.get(k) for k in ("lead", "trail", "led")}
            if len(specs) == 2 and specs[0] == specs[1]:
                problems.add("markers.reference", "the two reference stickers need two colours (the line joining "
                             "them is told apart by them)")
            for i, colour in enumerate(ref):
                same = [k for k, c in taken.items() if isinstance(c, str) and c.lower() == colour.lower()]
                if same:
                    problems.add(f"markers.reference[{i}]", f"{colour} is also the {same[0]}'s colour: give the "
                                 "airframe's stickers colours of their own")
            reference = (str(ref[0]), str(ref[1]))

    extra = _extra_markers(markers_t, colours, reference, problems)

    input_t = problems.table(data, "input")
    problems.unknown("input", input_t.keys(), _INPUT_KEYS)
    units = input_t.get("units", "normalized")
    if not isinstance(units, str):
        problems.add("input.units", "must be text")
        units = "normalized"

    model_t = problems.table(data, "model")
    problems.unknown("model", model_t.keys(), _MODEL_KEYS)
    model_fix: dict[str, float] = {}
    model_bounds: dict[str, tuple[float, float]] = {}
    # Parameters held, as lmfit's vary=False / min, max: [model] fix = {damping_ratio = 0.8},
    # bound = {natural_frequency_rad_s = [20, 80]}; their names are checked when the model's order is known.
    for name, value in (model_t.get("fix") or {}).items() if isinstance(model_t.get("fix", {}), dict) else ():
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            model_fix[name] = float(value)
        else:
            problems.add(f"model.fix.{name}", f"must be a number, got {value!r}")
    for name, value in (model_t.get("bound") or {}).items() if isinstance(model_t.get("bound", {}), dict) else ():
        if (isinstance(value, list) and len(value) == 2
                and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value) and value[0] < value[1]):
            model_bounds[name] = (float(value[0]), float(value[1]))
        else:
            problems.add(f"model.bound.{name}", f"must be [low, high] with low < high, got {value!r}")
    model_ties: dict[str, str] = {}
    for name, value in (model_t.get("tie") or {}).items() if isinstance(model_t.get("tie", {}), dict) else ():
        if isinstance(value, str) and value.strip():
            model_ties[name] = value
        else:
            problems.add(f"model.tie.{name}", f"must be an expression in quotes, e.g. \"4*gain\", got {value!r}")
    for key in ("fix", "bound", "tie"):
        if key in model_t and not isinstance(model_t[key], dict):
            problems.add(f"model.{key}", "must be a table: {name = value, …}")

    analysis_t = problems.table(data, "analysis")
    problems.unknown("analysis", analysis_t.keys(), _ANALYSIS_KEYS)
    settle = analysis_t.get("settle_s", SETTLE_S)
    if settle != SETTLE_AUTO:
        # A number of seconds, or "auto": each dwell's own, where its transient ends (fit_sine).
        if isinstance(settle, str):
            problems.add("analysis.settle_s", f"must be a number of seconds ≥ 0 or \"{SETTLE_AUTO}\", got {settle!r}")
        else:
            settle = problems.number("analysis.settle_s", settle, nonnegative=True)

    raw_tests = data.get("tests")
    tests: list[TestSpec] = []
    if not isinstance(raw_tests, list) or not raw_tests:
        problems.add("tests", "no [[tests]]: list at least one recording")
        raw_tests = []
    labels: dict[str, int] = {}
    videos: dict[Path, int] = {}
    skipped: list[tuple[str, str]] = []
    # A camera's program names every recording's file alike (Photron's C001H001S0001.cihx, one folder
    # per recording; the twin's frames.cih): where raw files' stems repeat, their folders name them.
    stems = [Path(str(e["frames"]).split(SOURCE_SEPARATOR)[0]).stem for e in raw_tests
             if isinstance(e, dict) and "frames" in e]
    for i, entry in enumerate(raw_tests, start=1):
        where = f"tests[{i}]"
        if not isinstance(entry, dict):
            problems.add(where, "must be a table")
            continue
        problems.unknown(where, entry.keys(), _TEST_KEYS | set(MANIFEST_KEYS))
        ok = True
        video = entry.get("video")
        if "frames" in entry:  # an image sequence or a high-speed raw file (issue 16)
            try:
                video = manifest_frame_source(entry, base)
                default_label = source_name(video)
                raw = Path(str(entry["frames"]).split(SOURCE_SEPARATOR)[0])
                if stems.count(raw.stem) > 1 and raw.stem == default_label and raw.parent.name:
                    default_label = raw.parent.name
            except ServoscopeError as exc:
                problems.add(f"{where}.frames", str(exc))
                video, default_label = None, f"test{i}"
        elif any(key in entry for key in MANIFEST_KEYS):
            problems.add(where, f"{', '.join(k for k in MANIFEST_KEYS if k in entry)}: for frames = …, not a video")
        if video is None and "frames" in entry:
            ok = False
        elif not isinstance(video, str) or not video:
            problems.add(f"{where}.video", "missing: give the recording's file name")
            ok = False
        kind = entry.get("kind")
        if kind not in _KINDS:
            problems.add(f"{where}.kind", f"unknown kind {kind!r} (use \"sine\" or \"step\")")
            ok = False
        amplitude = None
        if "amplitude" not in entry:
            problems.add(f"{where}.amplitude", "missing")
            ok = False
        else:
            amplitude = problems.number(f"{where}.amplitude", entry["amplitude"], nonzero=True)
            if amplitude is None:
                ok = False
            elif kind == "sine" and amplitude < 0:
                problems.add(f"{where}.amplitude", f"must be > 0 for a sine, got {amplitude!r}")
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
        t0 = None
        if "t0_s" in entry:
            t0 = problems.number(f"{where}.t0_s", entry["t0_s"])
        if "frames" not in entry:
            default_label = Path(video).stem if isinstance(video, str) and video else f"test{i}"
        label = entry.get("label", default_label)
        if not isinstance(label, str) or not label or "/" in label or "\\" in label:
            problems.add(f"{where}.label", "must be non-empty text without slashes")
            ok = False
        elif label in labels:
            problems.add(f"{where}.label", f"{label!r} is also the label of tests[{labels[label]}]: give each test "
                         "its own label = \"…\"")
            ok = False
        else:
            labels[label] = i
        if isinstance(video, str) and video:
            video_path = (base / video).resolve()
            if video_path in videos:
                problems.add(f"{where}.video", f"{video!r} is also the video of tests[{videos[video_path]}]")
                ok = False
            videos.setdefault(video_path, i)
            if check_videos and ok:
                try:
                    from ..video.reader import probe_video  # deferred: PyAV is slow to import

                    info = probe_video(video_path)
                except ServoscopeError as exc:
                    if keep_going:
                        skipped.append((label, str(exc)))
                    else:
                        problems.add(f"{where}.video", str(exc))
                    ok = False
                else:
                    if frequency is not None and info.frame_rate_hz and frequency >= 0.5 * info.frame_rate_hz:
                        problems.add(
                            f"{where}.frequency_hz",
                            f"{frequency:g} Hz is at or above half the video's frame rate "
                            f"({info.frame_rate_hz:g} frames/s): the camera cannot resolve it",
                        )
                        ok = False
                    if (exposure and info.frame_rate_hz and exposure > 1.001 / info.frame_rate_hz
                            and not any(p.startswith("camera.exposure_s") for p in problems.items)):
                        problems.add(
                            "camera.exposure_s",
                            f"{exposure:g} s is longer than the frame interval of {video!r} "
                            f"({1e3 / info.frame_rate_hz:.4g} ms): a frame cannot expose longer than it lasts "
                            "(give the shutter time, e.g. 0.001 for 1/1000 s, or leave it out when not known)",
                        )
                    if (readout and info.frame_rate_hz and readout >= 1.0 / info.frame_rate_hz
                            and not any(p.startswith("camera.readout_s") for p in problems.items)):
                        problems.add(
                            "camera.readout_s",
                            f"{readout:g} s is not shorter than the frame interval of {video!r} "
                            f"({1e3 / info.frame_rate_hz:.4g} ms): a sensor reads one frame's rows before the next's",
                        )
            if ok:
                tests.append(TestSpec(video_path, kind, float(amplitude), frequency, t0, label))

    problems.raise_if_any()
    return Campaign(
        path=path.resolve(),
        lead=str(colours["lead"]),
        trail=str(colours["trail"]),
        led=None if colours.get("led") is None else str(colours["led"]),
        camera=camera,
        exposure_s=exposure,
        input_units=units,
        settle_s=settle if settle == SETTLE_AUTO else float(settle),
        tests=tuple(tests),
        skipped=tuple(skipped),
        readout_s=float(readout or 0.0),
        lead_near=near["lead"],
        trail_near=near["trail"],
        led_near=near["led"],
        timestamp=str(timestamp),
        reference=reference,
        extra=extra,
        model_fix=model_fix,
        model_bounds=model_bounds,
        model_ties=model_ties,
        plane=plane,
    )
