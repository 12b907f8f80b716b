"""The campaign manifest's sections, each read and checked by one function.

Every function takes the parsed TOML document and the :class:`Problems`
collector, adds each problem it finds with its location, and returns what the
section says (defaults where it says nothing); :func:`~servoscope.campaign.manifest.load_campaign`
calls them in the file's order and raises once, listing every problem.
The ``[model]`` section stays with the manifest (its held parameters).
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass
from pathlib import Path

from ..camera.model import CameraModel
from ..camera.plane import Plane
from ..defaults import SETTLE_AUTO, SETTLE_S, TIMESTAMP, TIMESTAMPS
from ..errors import ServoscopeError
from ..markers.colour import parse_colour
from ..markers.selection import check_near
from ..markers.settings import extra_marker_problems
from ..video.frame_source import MANIFEST_KEYS, SOURCE_SEPARATOR, manifest_frame_source, source_name
from .inputs import SWEEP_KEYS, TestSpec, check_input, stated_fps

__all__ = ["TestSpec", "Problems", "camera_section", "markers_section", "input_section", "analysis_section", "tests_section",
           "plan_section", "default_labels", "RotorSpec", "rotor_section"]

_CAMERA_KEYS = {"calibration", "exposure_s", "readout_s", "timestamp", "plane"}
_MARKER_KEYS = {"lead", "trail", "led", "reference", "extra"}
_INPUT_KEYS = {"units"}
_ANALYSIS_KEYS = {"settle_s"}
_TEST_KEYS = {"video", "kind", "frequency_hz", "amplitude", "t0_s", "label", *SWEEP_KEYS}
#: A plan's ``[plan]`` table (``servoscope plan`` / ``drive``) and its ``[[plan.dwells]]``; its tests' keys.
_PLAN_KEYS = {"fps", "update_hz", "settle_s", "periods", "min_seconds", "lead_in_s", "tail_s", "rest_s", "dwells",
              "drive"}
_PLAN_POSITIVE = ("fps", "update_hz", "periods")  # > 0; the other numbers ≥ 0
_DWELL_KEYS = {"duration_s", "warnings", "max_late_ms"}
_PLAN_TEST_KEYS = {"video", "kind", "frequency_hz", "amplitude", "label", *SWEEP_KEYS} - {"input"}


class Problems:
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


# ---------------------------------------------------------------------------
# [camera]


def _camera_file(problems: Problems, camera_t: dict, base: Path, key: str, load, hint: str):
    """``[camera] key = "file"``: (its path, read with ``load``; None unless ``load``), or (None, None) when absent or bad."""
    if key not in camera_t:
        return None, None
    if not isinstance(camera_t[key], str):
        problems.add(f"camera.{key}", f"must be a file name{hint}")
        return None, None
    if load is None:
        return (base / camera_t[key]).resolve(), None
    try:
        return (base / camera_t[key]).resolve(), load(base / camera_t[key])
    except ServoscopeError as exc:
        problems.add(f"camera.{key}", str(exc))
        return None, None


def camera_section(data: dict, base: Path, problems: Problems, *, read_files: bool = True) -> dict:
    """``[camera]``: the Campaign's camera fields (camera, camera_file, plane, plane_file, exposure_s, timestamp, readout_s).

    ``read_files=False`` records the calibration's and plane's paths without reading them.
    """
    camera_t = problems.table(data, "camera")
    problems.unknown("camera", camera_t.keys(), _CAMERA_KEYS)
    out: dict = {}
    out["camera_file"], out["camera"] = _camera_file(problems, camera_t, base, "calibration",
                                                     CameraModel.load if read_files else None, "")
    # The blade's plane from a board photo (servoscope plane): angles measured in it.
    out["plane_file"], out["plane"] = _camera_file(problems, camera_t, base, "plane", Plane.load if read_files else None,
                                                   " (plane.json, from `servoscope plane`)")
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
    out.update(exposure_s=exposure, timestamp=str(timestamp), readout_s=float(readout or 0.0))
    return out


# ---------------------------------------------------------------------------
# [markers]


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


def _pinned_markers(markers_t: dict, problems: Problems) -> tuple[dict, dict]:
    """The lead's, trail's and LED's colours (or brightness), and where each is pinned: (colours, near)."""
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
    return colours, near


def _reference_markers(markers_t: dict, colours: dict, problems: Problems) -> tuple[str, str] | None:
    """``[markers] reference``: two stickers on the airframe; the blade's angle against the line joining them."""
    if "reference" not in markers_t:
        return None
    ref = markers_t["reference"]
    if not (isinstance(ref, list) and len(ref) == 2 and all(isinstance(c, str) for c in ref)):
        problems.add("markers.reference", "two colours of stickers on the airframe: reference = [\"#rrggbb\", "
                     "\"#rrggbb\"]")
        return None
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
    return (str(ref[0]), str(ref[1]))


def markers_section(data: dict, problems: Problems) -> dict:
    """``[markers]``: the Campaign's marker fields (lead, trail, led, their near, reference, extra)."""
    markers_t = problems.table(data, "markers")
    problems.unknown("markers", markers_t.keys(), _MARKER_KEYS)
    colours, near = _pinned_markers(markers_t, problems)
    reference = _reference_markers(markers_t, colours, problems)
    extra = _extra_markers(markers_t, colours, reference, problems)
    return dict(lead=str(colours.get("lead")), trail=str(colours.get("trail")),  # (a missing one is a problem said)
                led=None if colours.get("led") is None else str(colours["led"]),
                lead_near=near["lead"], trail_near=near["trail"], led_near=near["led"],
                reference=reference, extra=extra)


# ---------------------------------------------------------------------------
# [input], [analysis]


def input_section(data: dict, problems: Problems) -> str:
    """``[input] units`` ("normalized" by default)."""
    input_t = problems.table(data, "input")
    problems.unknown("input", input_t.keys(), _INPUT_KEYS)
    units = input_t.get("units", "normalized")
    if not isinstance(units, str):
        problems.add("input.units", "must be text")
        units = "normalized"
    return units


def analysis_section(data: dict, problems: Problems) -> tuple[float | str, bool]:
    """``[analysis] settle_s`` (seconds, or "auto"), and whether the file states it."""
    analysis_t = problems.table(data, "analysis")
    problems.unknown("analysis", analysis_t.keys(), _ANALYSIS_KEYS)
    settle = analysis_t.get("settle_s", SETTLE_S)
    if settle != SETTLE_AUTO:
        # A number of seconds, or "auto": each dwell's own, where its transient ends (fit_sine).
        if isinstance(settle, str):
            problems.add("analysis.settle_s", f"must be a number of seconds ≥ 0 or \"{SETTLE_AUTO}\", got {settle!r}")
            settle = None
        else:
            settle = problems.number("analysis.settle_s", settle, nonnegative=True)
    return (settle if settle == SETTLE_AUTO else float(settle or 0.0)), "settle_s" in analysis_t


# ---------------------------------------------------------------------------
# [[tests]]


def _raw_stem(entry: dict) -> str:
    return Path(str(entry["frames"]).split(SOURCE_SEPARATOR)[0]).stem


def _frames_label(entry: dict, video: str, stems: list[str]) -> str:
    """A frame source's default label: its name, or its folder's where raw files' stems repeat."""
    label = source_name(video)
    raw = Path(str(entry["frames"]).split(SOURCE_SEPARATOR)[0])
    if stems.count(raw.stem) > 1 and raw.stem == label and raw.parent.name:
        label = raw.parent.name
    return label


def default_labels(entries: list[dict], base: Path) -> list[str]:
    """The label each ``[[tests]]`` table gets when it gives none (as :func:`tests_section` reads it)."""
    stems = [_raw_stem(e) for e in entries if "frames" in e]
    labels = []
    for i, entry in enumerate(entries, start=1):
        video = entry.get("video")
        if "frames" in entry:
            labels.append(_frames_label(entry, manifest_frame_source(entry, base), stems))
        else:
            labels.append(Path(video).stem if isinstance(video, str) and video else f"test{i}")
    return labels


def _check_recording(problems: Problems, where: str, video: str, video_path: Path, frequency, camera: dict,
                     label: str, skipped: list, keep_going: bool, frequency_key: str = "frequency_hz") -> bool:
    """Whether the recording opens, and its frame rate resolves the test's frequency and the camera's times."""
    from ..video.reader import probe_video  # deferred: PyAV is slow to import

    exposure, readout = camera.get("exposure_s"), camera.get("readout_s")
    try:
        info = probe_video(video_path)
    except ServoscopeError as exc:
        if keep_going:
            skipped.append((label, str(exc)))
        else:
            problems.add(f"{where}.video", str(exc))
        return False
    ok = True
    if frequency is not None and info.frame_rate_hz and frequency >= 0.5 * info.frame_rate_hz:
        problems.add(
            f"{where}.{frequency_key}",
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
    return ok


def _test_source(problems: Problems, where: str, i: int, entry: dict, base: Path, stems: list[str],
                 planned: bool) -> tuple[bool, str | None, str]:
    """A test's recording: (ok, the video or frame source's path string, its default label)."""
    video = entry.get("video")
    default_label = f"test{i}"
    for key in ("video", "frames"):
        # No file can have such a name; the operating system refuses it (ValueError) rather than not finding it.
        if isinstance(entry.get(key), str) and "\x00" in entry[key]:
            problems.add(f"{where}.{key}", f"{entry[key]!r} holds a NUL character: give the recording's file name")
            return False, None, default_label
    if "frames" in entry:  # an image sequence or a high-speed raw file (issue 16)
        try:
            video = manifest_frame_source(entry, base)
            default_label = _frames_label(entry, video, stems)
        except ServoscopeError as exc:
            problems.add(f"{where}.frames", str(exc))
            return False, None, default_label
    elif any(key in entry for key in MANIFEST_KEYS):
        problems.add(where, f"{', '.join(k for k in MANIFEST_KEYS if k in entry)}: for frames = …, not a video")
    if video is None and planned:
        return True, None, default_label  # a plan's test, before the rig has recorded it
    if not isinstance(video, str) or not video:
        problems.add(f"{where}.video", "missing: give the recording's file name")
        return False, video, default_label
    if "frames" not in entry:
        default_label = Path(video).stem
    return True, video, default_label


def tests_section(data: dict, base: Path, problems: Problems, camera: dict, *, check_videos: bool = True,
                  keep_going: bool = False, planned: bool = False) -> tuple[list[TestSpec], list[tuple[str, str]]]:
    """``[[tests]]``: the recordings, and those left out (``keep_going``) with the reason: (tests, skipped).

    ``planned``: a plan's tests, which may have no video yet.
    """
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
    stems = [_raw_stem(e) for e in raw_tests if isinstance(e, dict) and "frames" in e]
    for i, entry in enumerate(raw_tests, start=1):
        where = f"tests[{i}]"
        if not isinstance(entry, dict):
            problems.add(where, "must be a table")
            continue
        problems.unknown(where, entry.keys(), _TEST_KEYS | set(MANIFEST_KEYS))
        ok, video, default_label = _test_source(problems, where, i, entry, base, stems, planned)
        input_ok, kind, amplitude, frequency, sweep = check_input(problems, where, entry, stated_fps(data, entry),
                                                                  base)
        ok = ok and input_ok
        t0 = None
        if "t0_s" in entry:
            t0 = problems.number(f"{where}.t0_s", entry["t0_s"])
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
        video_path = None
        if isinstance(video, str) and video:
            video_path = (base / video).resolve()
            if video_path in videos:
                problems.add(f"{where}.video", f"{video!r} is also the video of tests[{videos[video_path]}]")
                ok = False
            videos.setdefault(video_path, i)
            if check_videos and ok:
                ok = _check_recording(problems, where, video, video_path, sweep.get("to_hz", frequency), camera, label,
                                      skipped, keep_going, "to_hz" if sweep else "frequency_hz")
        if ok and (video_path is not None or planned):
            tests.append(TestSpec(video_path, kind, float(amplitude), frequency, t0, label, "frames" in entry, **sweep))
    return tests, skipped


# ---------------------------------------------------------------------------
# [plan]


def _plan_dwells(plan_t: dict, n_tests: int, problems: Problems) -> None:
    """``[[plan.dwells]]``: one per test, each with its duration, warnings and lateness."""
    dwells = plan_t.get("dwells")
    if not isinstance(dwells, list) or len(dwells) != n_tests:
        problems.add("plan.dwells", f"[[plan.dwells]] must have one entry per [[tests]] ({n_tests})")
        return
    for i, dwell in enumerate(dwells, start=1):
        where = f"plan.dwells[{i}]"
        if not isinstance(dwell, dict):
            problems.add(where, "must be a table")
            continue
        problems.unknown(where, dwell.keys(), _DWELL_KEYS)
        if "duration_s" not in dwell:
            problems.add(f"{where}.duration_s", "missing")
        else:
            problems.number(f"{where}.duration_s", dwell["duration_s"], positive=True)
        warnings = dwell.get("warnings", [])
        if not isinstance(warnings, list) or not all(isinstance(w, str) for w in warnings):
            problems.add(f"{where}.warnings", "must be a list of text")
        if "max_late_ms" in dwell:
            problems.number(f"{where}.max_late_ms", dwell["max_late_ms"])


def plan_section(data: dict, problems: Problems, *, planned: bool = False) -> dict:
    """``[plan]``: what the rig needs (``servoscope plan`` / ``drive``), kept as written.

    Only a plan (``planned``) must have it, and only then is it checked: the analysis ignores it.
    """
    plan_t = data.get("plan", {})
    if not planned:
        return dict(plan_t) if isinstance(plan_t, dict) else {}
    if "plan" not in data or not isinstance(plan_t, dict):
        problems.add("", "no [plan] table (make a plan with `servoscope plan`)")
        return {}
    problems.unknown("plan", plan_t.keys(), _PLAN_KEYS)
    if "fps" not in plan_t:
        problems.add("plan.fps", "missing: the camera's frame rate")
    for key in _PLAN_KEYS - {"dwells", "drive"}:
        if key in plan_t:
            positive = key in _PLAN_POSITIVE
            problems.number(f"plan.{key}", plan_t[key], positive=positive, nonnegative=not positive)
    if not isinstance(plan_t.get("drive", {}), dict):
        problems.add("plan.drive", "must be a table")
    tests = data.get("tests")
    for i, entry in enumerate(tests if isinstance(tests, list) else (), start=1):
        if isinstance(entry, dict):
            if "input" in entry:  # the rig generates its inputs; a pilot's recording it cannot replay
                problems.add(f"tests[{i}].input", "servoscope drive plays sines, steps and chirps, not a recorded "
                             "input: fly it yourself with the LED switching at its start, and list the video with "
                             "input = … in a campaign.toml (not a plan)")
            for key in entry.keys() - _PLAN_TEST_KEYS - {"input"}:
                problems.add(f"tests[{i}].{key}", f"not in a plan (a plan's tests take {', '.join(sorted(_PLAN_TEST_KEYS))})")
    _plan_dwells(plan_t, len(tests) if isinstance(tests, list) else 0, problems)
    return dict(plan_t)


# ---------------------------------------------------------------------------
# [rotor] (issue 33: the rotor turning, filmed edge-on at each blade's pass)

_ROTOR_KEYS = {"blades", "rev_per_s", "camera_distance_m", "tip_radius_m"}
_BLADE_KEYS = ("lead", "trail")


@dataclass(frozen=True)
class RotorSpec:
    """``[rotor]``: a turning rotor's blades and what the engineer knows of it.

    Attributes
    ----------
    blades : tuple of (str, str)
        Each blade's (lead, trail) sticker colours as written, blade 0 first.
    rev_per_s : float or None
        The rotor speed (rev/s); None: measured from the passes.
    camera_distance_m : float or None
        The camera's pinhole to the rotor axis (m).
    tip_radius_m : float or None
        The blade tip's radius (m).
    """

    blades: tuple[tuple[str, str], ...]
    rev_per_s: float | None = None
    camera_distance_m: float | None = None
    tip_radius_m: float | None = None

    def plan_rotor(self) -> dict:
        """The rig plan's ``rotor`` (:class:`~servoscope.rig.plan.SweepPlan`) from this section: empty without a
        speed; else the speed, the blades (their colours) and the passes' rate and Nyquist frequency."""
        if self.rev_per_s is None:
            return {}
        n, rev = len(self.blades), float(self.rev_per_s)
        return {"rev_per_s": rev, "n_blades": n, "pass_rate_hz": n * rev, "pass_nyquist_hz": 0.5 * n * rev,
                "blades": [list(b) for b in self.blades]}


def _rotor_blade(problems: Problems, i: int, entry) -> tuple[str, str] | None:
    """``[rotor] blades[i]``: ``{lead = "#…", trail = "#…"}``, each a colour (or a brightness); None when bad."""
    where = f"rotor.blades[{i}]"
    if not isinstance(entry, dict):
        problems.add(where, f"must be {{lead = \"#rrggbb\", trail = \"#rrggbb\"}}, got {entry!r}")
        return None
    problems.unknown(where, entry.keys(), set(_BLADE_KEYS))
    colours = []
    for key in _BLADE_KEYS:
        if key not in entry:
            problems.add(f"{where}.{key}",
                         f"missing: give blade {i}'s {key} sticker's colour, e.g. {key} = \"#rrggbb\"")
            continue
        try:
            spec = parse_colour(entry[key], what="colour")
        except ServoscopeError as exc:
            problems.add(f"{where}.{key}", str(exc).removeprefix("colour: "))
            continue
        if spec == "auto":
            problems.add(f"{where}.{key}", "must be a colour (or \"bright\"/\"dark\"), not \"auto\": the colours tell "
                         "the blades apart")
            continue
        colours.append(str(entry[key]))
    return (colours[0], colours[1]) if len(colours) == 2 else None


def rotor_section(data: dict, problems: Problems) -> RotorSpec | None:
    """``[rotor]``: the turning rotor's blades (their sticker colours) and its optional speed, camera distance and
    tip radius; None when the manifest has no ``[rotor]`` (a static campaign)."""
    if "rotor" not in data:
        return None
    rotor_t = problems.table(data, "rotor")
    problems.unknown("rotor", rotor_t.keys(), _ROTOR_KEYS)
    blades_t = rotor_t.get("blades")
    if not isinstance(blades_t, list) or not blades_t:
        problems.add("rotor.blades", "missing: one {lead = \"#rrggbb\", trail = \"#rrggbb\"} a blade, blade 0 first")
        return None
    blades = [_rotor_blade(problems, i, entry) for i, entry in enumerate(blades_t)]
    seen: dict[str, str] = {}
    for i, blade in enumerate(blades):
        for key, colour in zip(_BLADE_KEYS, blade or ()):
            name = colour.strip().lower()
            if name in ("bright", "dark"):
                continue  # a monochrome camera's stickers: told apart by where and when, not by colour
            if name in seen:
                problems.add(f"rotor.blades[{i}].{key}", f"{colour} is also {seen[name]}'s colour: give each "
                             "sticker a colour of its own")
            seen[name] = f"blades[{i}].{key}"
    numbers = {key: problems.number(f"rotor.{key}", rotor_t[key], positive=True) if key in rotor_t else None
               for key in ("rev_per_s", "camera_distance_m", "tip_radius_m")}
    if (numbers["camera_distance_m"] is not None and numbers["tip_radius_m"] is not None
            and numbers["tip_radius_m"] >= numbers["camera_distance_m"]):
        problems.add("rotor.tip_radius_m", "must be less than camera_distance_m: the camera stands outside the disc")
    if any(b is None for b in blades):
        return None
    return RotorSpec(blades=tuple(blades), **numbers)
