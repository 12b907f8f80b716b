"""The campaign manifest (``campaign.toml``): schema and validation.

Validation happens before anything is written: a manifest that fails leaves
the output folder untouched. Every problem in the file is reported at once,
each with its location (``campaign.toml: tests[3].frequency_hz: must be > 0``),
so that a hand-typed manifest is fixed in one pass. Unknown keys are refused
with the nearest known key suggested, since a typo would otherwise be
silently ignored.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path

from ..camera.model import CameraModel
from ..camera.plane import Plane
from ..defaults import TIMESTAMP
from ..errors import ServoscopeError
from .sections import (Problems, RotorSpec, TestSpec, analysis_section, camera_section, input_section,
                       markers_section, plan_section, rotor_section, tests_section)
from .toml_io import campaign_to_toml, save_campaign

__all__ = ["TestSpec", "Campaign", "RotorSpec", "load_campaign"]

# [plan] is written by `servoscope plan` / `drive` (dwell lengths, rig settings): kept, checked only in a plan.
_TOP_KEYS = {"camera", "markers", "input", "tests", "analysis", "plan", "model", "rotor"}
_MODEL_KEYS = {"fix", "bound", "tie"}
_Problems = Problems  # the collector of a manifest's problems (sections.Problems)


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
    camera_file, plane_file : Path or None
        The files ``camera`` and ``plane`` were read from (what :meth:`save` writes).
    settle_stated : bool
        The manifest states ``[analysis] settle_s`` (written again even at the default).
    plan : dict
        The ``[plan]`` table (``servoscope plan`` / ``drive``), as written.
    rotor : RotorSpec or None
        A turning rotor filmed at each blade's pass (``[rotor]``: each blade's sticker colours, its speed,
        the camera's distance, the tip radius); None: a static campaign.

    Two campaigns are equal when their files would say the same: the manifest's own path,
    and the camera and plane read from files (compared by their files), are left out.
    """

    path: Path = field(compare=False)
    lead: str
    trail: str
    led: str | None
    camera: CameraModel | None = field(compare=False)
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
    plane: Plane | None = field(default=None, compare=False)
    camera_file: Path | None = None
    plane_file: Path | None = None
    settle_stated: bool = field(default=False, compare=False)
    plan: dict = field(default_factory=dict)
    rotor: RotorSpec | None = None

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

    @property
    def sweep_tests(self) -> list[TestSpec]:
        return [t for t in self.tests if t.kind == "sweep"]

    @classmethod
    def load(cls, path: str | Path, *, check_videos: bool = True, keep_going: bool = False,
             planned: bool = False) -> "Campaign":
        """Read and validate a manifest; see :func:`load_campaign`."""
        return load_campaign(path, check_videos=check_videos, keep_going=keep_going, planned=planned)

    def to_toml(self, header: str = "") -> str:
        """The manifest's text: what :meth:`load` reads back to an equal campaign.

        Paths are written relative to :attr:`path`'s folder; ``header`` (comment lines,
        each ending in a newline) goes first. See :mod:`servoscope.campaign.toml_io`.
        """
        return campaign_to_toml(self, header)

    def save(self, path: str | Path | None = None, *, header: str = "") -> Path:
        """Write :meth:`to_toml` to ``path`` (default: :attr:`path`) atomically; returns the path.

        Paths in the file are relative to ``path``'s folder (they name the same files).
        """
        return save_campaign(self, self.path if path is None else path, header)

    def without(self, reasons: dict[str, str]) -> "Campaign":
        """The same campaign less some tests, each with the reason it was left out."""
        return replace(self, tests=tuple(t for t in self.tests if t.label not in reasons),
                       skipped=self.skipped + tuple(reasons.items()))


def _read_manifest(path: Path) -> dict:
    """The manifest's TOML document; a ServoscopeError when it cannot be read or is not TOML."""
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
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ServoscopeError(f"{path}: not valid TOML ({exc})") from None


def _model_section(data: dict, problems: _Problems
                   ) -> tuple[dict[str, float], dict[str, tuple[float, float]], dict[str, str]]:
    """``[model]``: the parameters held (fix, bound) and tied: (model_fix, model_bounds, model_ties)."""
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
    return model_fix, model_bounds, model_ties


def load_campaign(path: str | Path, *, check_videos: bool = True, keep_going: bool = False,
                  planned: bool = False) -> Campaign:
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
    planned : bool
        A plan (``servoscope plan``): its tests may have no video yet, its
        ``[plan]`` table must be there and is checked, and its camera's files
        are named, not read.

    Raises
    ------
    ServoscopeError
        Listing every problem found, each with its location.
    """
    path = Path(path)
    return campaign_from_data(_read_manifest(path), path, check_videos=check_videos, keep_going=keep_going,
                              planned=planned, read_files=not planned)


def campaign_from_data(data: dict, path: Path, *, check_videos: bool = True, keep_going: bool = False,
                       planned: bool = False, read_files: bool = True) -> Campaign:
    """The campaign a manifest's TOML document describes, each section checked in turn (see :func:`load_campaign`).

    ``path`` is where the document is (or would be): relative paths are in its folder.
    ``read_files=False`` records the camera's and plane's files without reading them.
    """
    base = path.resolve().parent
    problems = _Problems(path)
    problems.unknown("", data.keys(), _TOP_KEYS)
    camera = camera_section(data, base, problems, read_files=read_files)
    markers = markers_section(data, problems)
    units = input_section(data, problems)
    model_fix, model_bounds, model_ties = _model_section(data, problems)
    settle, settle_stated = analysis_section(data, problems)
    tests, skipped = tests_section(data, base, problems, camera, check_videos=check_videos, keep_going=keep_going,
                                   planned=planned)
    plan = plan_section(data, problems, planned=planned)
    rotor = rotor_section(data, problems)
    problems.raise_if_any()
    return Campaign(
        path=path.resolve(), **markers, **camera, input_units=units, settle_s=settle, settle_stated=settle_stated,
        tests=tuple(tests), skipped=tuple(skipped), model_fix=model_fix, model_bounds=model_bounds,
        model_ties=model_ties, plan=plan, rotor=rotor,
    )
