"""How to track one video: :class:`TrackerSettings`, and the engine it resolves to."""

from __future__ import annotations

import warnings
from dataclasses import dataclass

from ..defaults import LEAD_COLOUR, LED_COLOUR, TIMESTAMP, TRAIL_COLOUR
from ..errors import ServoscopeError
from .colour import BRIGHTNESS, parse_colour

__all__ = ["BACKENDS", "ENGINES", "TrackerSettings", "extra_marker_problems", "resolve_engine"]


@dataclass(frozen=True)
class TrackerSettings:
    """How to track one video.

    Attributes
    ----------
    lead, trail : str
        Marker colours: ``"#rrggbb"``, a CSS name, or ``"auto"``; or, for
        monochrome footage, ``"bright"`` (white dots on a dark blade) or
        ``"dark"``: told apart by position (``lead_near``/``trail_near``), else
        the lead is the one on the right of the picture.
    led : str or None
        LED colour; None when the footage has no LED.
    camera : servoscope.camera.CameraModel or None
        When given, centroids are undistorted before angles are computed.
    exposure_s : float or None
        Exposure (shutter) time, for the LED's sub-frame switch time; None
        (unknown) assumes nothing about it: a switch that lit no frame partly
        is then anywhere between two frame times (see
        :mod:`servoscope.markers.led_timing`). Must be > 0 and no longer than
        the frame interval.
    search_radius_px : float
        Half-size of the search window beyond the marker's own extent (px).
    support_margin_px : float
        Background margin around the sticker over which its soft moments are
        taken (px); the sticker's edge blur must fit inside it.
    shape_tolerance : float
        Largest relative loss of a marker's soft area from the marker's
        reference before the frame is flagged as partly hidden (0.03 = 3 %);
        a gain of 2.5×, or a change of a second-moment axis of 2× this
        flags it as merged or misshapen.
    deinterlace : {None, "fields", "fields-bff"}
        Split each interlaced frame into its two fields, each with its own
        time (double rate): ``"fields"`` top field first, ``"fields-bff"``
        bottom field first. Centroids stay in frame-row coordinates.
    centroid : {"local", "projected"}
        Soft-membership estimator. ``"local"``: each pixel unmixed between
        the marker colour and its nearest background pixel, membership
        clipped to [0, 1], over the blob dilated by 3 px (robust on every
        footage measured). ``"projected"`` (experimental):
        :func:`~servoscope.markers.centroid.soft_centroid`, signed membership
        with the background's variation projected out, over a tapered disk;
        3× more accurate on uncompressed footage of the reference scene but
        not yet robust to H.264 chroma bleed and small stickers. Both are
        estimators of the RGB path (``engine="reference-rgb"``); the YUV
        engines have their own (see :mod:`servoscope.markers.kernels`).
    engine : {"auto", "numba", "numpy", "mono", "reference-rgb"}
        ``"numba"`` (what ``"auto"`` picks): the fused kernel on the
        decoder's YUV planes, classifying by chroma and unmixing with
        full-resolution luma, decoding on a second thread; the most accurate
        and the fastest. ``"numpy"``: the same maths in plain numpy (slow; a
        reference). ``"reference-rgb"``: the previous path (every frame
        converted to RGB, HSV masks, ``centroid`` estimator), for comparison.
        With ``centroid="projected"``, ``"auto"`` picks ``"reference-rgb"``.
        ``"mono"`` (what ``"auto"`` picks when both markers are told by
        brightness, on whole frames): the monochrome kernel on the camera's
        native samples (memory-mapped MRAW and CINE, TIFF sequences; no 8-bit
        rounding), see :mod:`servoscope.markers.mono_engine`; ``"reference-rgb"``
        is its oracle.
    backend : {"auto"}
        Where the kernel runs: ``"auto"``, the only choice, is this machine's
        CPU (kept for compatibility; the command line does not offer it).
        ``"cpu"``, which did the same, is a deprecated alias: it warns
        (:class:`DeprecationWarning`) and reads as ``"auto"``. ``"cuda"`` is
        refused with an error: no tracking engine runs on a GPU (the GPU pass
        of :mod:`servoscope.markers.gpu` is a whole-frame batch classifier,
        measured by ``servoscope bench``), and a track must not claim a GPU
        it did not use.
    lead_near, trail_near : (float, float) or None
        Pin a marker by position (px in the first frame), as a user clicks a
        point: the marker is the blob of its colour there (an error when
        there is none). None (the default): the best-scoring pair of blobs
        (see :mod:`servoscope.markers.selection`).
    led_near : (float, float) or None
        Pin the LED by position (px in the first frame): the blob of its colour
        (or brightness) there, fixed on the stand or on the blade, is followed
        (an error when there is none). None: the blob by the blade, or where
        that does not switch, the blob that does (:mod:`servoscope.markers.led_search`).
    readout_s : float
        Rolling-shutter readout time, seconds (0, the default: a global
        shutter). Row y of a frame is taken as exposed around
        ``frame_time + readout_s·y/height`` (y in the recorded image): the
        angle's sample time and the LED's switch time are corrected for the
        rows the stickers and the LED are on. Must be shorter than the frame
        (or field) interval.
    timestamp : {"middle", "start", "end"}
        Which point of its exposure a frame's timestamp marks ("middle", the
        default, as the digital twin and most containers' players assume).
        With a known exposure, angles and t0 are dated at the exposures'
        middles; the phases and the dead time do not depend on it (the LED
        and the markers share each frame's exposure).
    reference : (str, str) or None
        Two stickers on the airframe (colours as ``lead``/``trail``): the
        blade's angle is measured against the line joining them, which takes
        out camera roll and shake, a phone's stabilisation and the airframe's
        own rocking (:attr:`Track.reference_angle_rad` keeps that line's
        motion). None (the default): against the image's axes.
    extra : tuple of str
        More stickers on the blade, each its own colour (``"#rrggbb"`` or a CSS
        name): the blade's rigid motion is fitted to all markers (the angle
        its rotation) and each marker's residual across the chord line is its
        bending (see :func:`servoscope.angle.rigid_motion`). Tracked two at a
        time by passes of their own over the video. Empty (the default): two
        markers, tracked as always.
    plane : servoscope.camera.Plane or None
        The blade's plane (``servoscope plane``'s plane.json): every centroid, undistorted
        first, is mapped into the plane (:meth:`~servoscope.camera.plane.Plane.to_rectified`:
        pixels of a square-on view at the picture's own scale) and the angle, the separation,
        the heave and the bending are measured there, so that a camera that is not square-on
        reads true angles. The plane's own calibration undistorts the centroids when
        ``camera`` is None; a different ``camera`` is refused. None: angles in the image.
    """

    lead: str = LEAD_COLOUR
    trail: str = TRAIL_COLOUR
    led: str | None = LED_COLOUR
    # `camera` and `plane` are the camera stage's (servoscope.camera.CameraModel, .Plane), named in
    # these annotations only: markers comes before camera and carries them to the pipeline
    # (servoscope.pipeline.tracker), which applies them; nothing here imports them.
    camera: CameraModel | None = None  # noqa: F821
    exposure_s: float | None = None
    search_radius_px: float = 24.0
    support_margin_px: float = 2.0
    shape_tolerance: float = 0.03
    deinterlace: str | None = None
    centroid: str = "local"
    engine: str = "auto"
    backend: str = "auto"
    readout_s: float = 0.0
    timestamp: str = TIMESTAMP
    lead_near: tuple[float, float] | None = None
    trail_near: tuple[float, float] | None = None
    led_near: tuple[float, float] | None = None
    reference: tuple[str, str] | None = None
    extra: tuple[str, ...] = ()
    plane: Plane | None = None  # noqa: F821

    def __post_init__(self) -> None:
        if self.backend in DEPRECATED_BACKENDS:
            warnings.warn(f"TrackerSettings(backend={self.backend!r}) is deprecated: {DEPRECATED_BACKENDS[self.backend]}",
                          DeprecationWarning, stacklevel=3)
            # Read as "auto": the same track, and the same cache key.
            object.__setattr__(self, "backend", "auto")


ENGINES = ("auto", "numba", "numpy", "mono", "reference-rgb")
BACKENDS = ("auto",)
#: Backends that did what "auto" does: accepted with a DeprecationWarning, read as "auto".
DEPRECATED_BACKENDS = {"cpu": "it is what \"auto\" does (tracking runs on this machine's CPU); use backend=\"auto\""}
#: Backends once offered, refused with what to use instead.
RETIRED_BACKENDS = {"cuda": "no tracking engine runs on a GPU: the GPU pass (servoscope.markers.gpu, measured by "
                            "`servoscope bench`) classifies whole frames in batches and is not a tracker; "
                            "use backend=\"auto\" (the CPU)"}


def resolve_engine(settings: TrackerSettings) -> str:
    """The engine ``settings`` asks for, "auto" resolved; raises on unknown names."""
    if settings.engine not in ENGINES:
        raise ServoscopeError(f"engine: {settings.engine!r} is not one of {', '.join(ENGINES)}")
    if settings.backend in RETIRED_BACKENDS:
        raise ServoscopeError(f"backend: {settings.backend!r}: {RETIRED_BACKENDS[settings.backend]}")
    if settings.backend not in BACKENDS:
        raise ServoscopeError(f"backend: {settings.backend!r} is not one of {', '.join(BACKENDS)}")
    brightness = any(str(m).strip().lower() in BRIGHTNESS for m in (settings.lead, settings.trail))
    if brightness and settings.engine in ("numba", "numpy"):
        raise ServoscopeError(f"engine {settings.engine!r} tells markers by colour; markers told by brightness "
                              "(\"bright\", \"dark\") are tracked by engine=\"mono\" or \"reference-rgb\" "
                              "(or \"auto\")")
    # The monochrome engine: both markers told by brightness, whole frames, the local estimator.
    mono = (all(str(m).strip().lower() in BRIGHTNESS for m in (settings.lead, settings.trail))
            and settings.deinterlace is None and settings.centroid == "local")
    if settings.engine == "mono" and not mono:
        raise ServoscopeError("engine \"mono\" tracks whole frames of two markers told by brightness (\"bright\", "
                              "\"dark\") with centroid=\"local\"; use engine=\"reference-rgb\" (or \"auto\")")
    if settings.engine == "auto":
        if mono:
            return "mono"
        return "reference-rgb" if settings.centroid == "projected" or brightness else "numba"
    return settings.engine


def extra_marker_problems(extra, others: dict[str, object]) -> list[tuple[int, str]]:
    """What is wrong with extra markers' colours: ``(index, problem)`` for each that cannot be told apart.

    An extra marker must be a colour (not ``"auto"`` or a brightness), and not the colour
    of another marker: ``others`` names them (``{"the lead marker": "#d62728", …}``; values
    that are not colours are skipped), and each extra marker is another's for the ones after
    it. One home for the tracker's refusal and the manifest's problems.
    """
    seen: dict[tuple, str] = {}
    for name, colour in others.items():
        try:
            spec = parse_colour(colour, what="colour") if isinstance(colour, str) else None
        except ServoscopeError:
            continue
        if isinstance(spec, tuple):
            seen[tuple(round(float(c)) for c in spec)] = name
    problems = []
    for k, colour in enumerate(extra):
        try:
            spec = parse_colour(colour, what="colour") if isinstance(colour, str) else None
        except ServoscopeError as exc:
            problems.append((k, str(exc).removeprefix("colour: ")))
            continue
        if not isinstance(spec, tuple):
            problems.append((k, f"{colour!r}: extra markers are told by colour; give \"#rrggbb\" or a CSS name"))
            continue
        key = tuple(round(float(c)) for c in spec)
        if key in seen:
            problems.append((k, f"{colour} has the same colour as {seen[key]}: give each marker a colour of its own"))
        seen[key] = f"extra marker {k + 1}"
    return problems
