"""``servoscope bench --mono``: tracking a monochrome high-speed camera's file against reading it and a user's script.

The clip is what a Photron camera saves: a 12-bit monochrome MRAW (samples in
16-bit words, its CIH header beside it), 1024×1024 and 10,000 frames by default,
of the digital twin's blade with two white dots and an LED that switches off half
way. Rendering 10,000 megapixel frames would take the twin a quarter of an hour,
so it renders one period of the blade's sine (``DISTINCT_FRAMES`` frames, with the
LED lit and dark) and the file cycles through them: the motion is seamless, each
frame differs from the next, and the bytes on disk are as many as a real
recording's. Measured in one run, in this process, each over the whole file:

* **read**: the file alone, as a user's first look at it: pyMRAW's memory map,
  every frame touched once (its maximum): the pace of the disk and the page cache;
* **servoscope**: :func:`~servoscope.pipeline.track_video` with the markers pinned
  by position, the engine ``auto`` picks (and, ``reference=True``, the RGB
  reference engine on the first frames, for the ratio the issue started from);
* **opencv**: a user's first OpenCV script: for every frame, a threshold of the
  whole frame, its contours and their moments (the two largest taken).

Ratios: servoscope over opencv (target ≥ 5×) and over read (≥ 0.5×), and
servoscope's gigapixels per second (≥ 1). With ``whole=True`` the same two
are also timed as whole processes (``python -m servoscope track`` and the script
as a file), start-up included.
"""

from __future__ import annotations

import math
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from .bench_process import run_process

__all__ = ["DISTINCT_FRAMES", "MONO_TARGETS", "OPENCV_MONO_SCRIPT", "mono_bench", "opencv_mono", "read_only",
           "render_mono_clip"]

#: Frames of one period of the bench's sine (rendered; the file cycles through them).
DISTINCT_FRAMES = 100
#: The sensor's depth and its noise (8-bit DN, scaled to the depth as the twin's monochrome camera does).
BITS = 12
NOISE_DN = 1.0
#: The recording's frame rate (frames/s).
FPS = 2000.0
#: The issue's targets: (what, key in the result, least value).
MONO_TARGETS = (("tracking / OpenCV script (in-process)", "track_over_opencv", 5.0),
                ("tracking / reading the file alone", "track_over_read", 0.5),
                ("tracking, gigapixels/s", "track_gpx_s", 1.0))

#: A user's first OpenCV script on the MRAW (pyMRAW's memory map; threshold, contours, moments of each
#: whole frame), run as a process by ``whole=True`` and, as :func:`opencv_mono`, in this one.
OPENCV_MONO_SCRIPT = """\
import sys
import cv2
import numpy as np
import pyMRAW


def run(cih, threshold):
    images, info = pyMRAW.load_video(cih)
    centres = []
    for frame in images:
        _, mask = cv2.threshold(frame, threshold, 255, cv2.THRESH_BINARY)
        contours, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        largest = sorted(contours, key=cv2.contourArea, reverse=True)[:2]
        moments = [cv2.moments(c) for c in largest]
        centres.append([(m["m10"] / m["m00"], m["m01"] / m["m00"]) for m in moments if m["m00"] > 0])
    return centres


if __name__ == "__main__":
    print(len(run(sys.argv[1], float(sys.argv[2]))))
"""


def _scene(size: int):
    from .simulate import Scene

    # White dots on the dark blade: what a monochrome camera's users stick on (as the twin's monochrome presets).
    return replace(Scene.for_size(size, size, background_seed=2), lead_colour="#f4f4f4", trail_colour="#f4f4f4")


def _pitch(k: np.ndarray | int) -> np.ndarray:
    return 0.05 * np.sin(2.0 * np.pi * np.asarray(k, dtype=np.float64) / DISTINCT_FRAMES)


def render_mono_clip(cache: Path, frames: int = 10_000, size: int = 1024, fps: float = FPS) -> Path:
    """The bench's MRAW (its ``.cih`` header's path), rendered unless already in ``cache``.

    The LED is lit for the first half of the frames and dark after.
    """
    from .markers.colour import luma_bt601
    from .simulate.render import FrameRenderer
    from .video.sequence_writer import MrawWriter

    folder = Path(cache) / f"mono_{size}x{size}_{frames}_{BITS}bit"
    cih = folder / "frames.cih"
    done = folder / "frames.ok"
    if done.exists():
        return cih
    if folder.exists():
        for stale in folder.iterdir():  # a run stopped half-way
            stale.unlink()
    renderer = FrameRenderer(_scene(size), None)
    top = 2**BITS - 1
    rng = np.random.default_rng(7)
    cycle: dict[tuple[float, int], np.ndarray] = {}

    def frame(lit: float, k: int) -> np.ndarray:
        if (lit, k) not in cycle:  # rendered once, when first needed (a short clip renders only its own)
            y = luma_bt601(renderer.render(float(_pitch(k)), lit, k)).astype(np.float64) * (top / 255.0)
            y += rng.standard_normal(y.shape) * (NOISE_DN * top / 255.0)
            cycle[lit, k] = np.clip(np.rint(y), 0, top).astype(np.uint16)
        return cycle[lit, k]

    with MrawWriter(folder, size, size, fps, word_bits=16) as out:
        for i in range(frames):
            out.write_gray(frame(1.0 if i < frames // 2 else 0.0, i % DISTINCT_FRAMES), BITS)
    done.write_text("ok\n")
    return cih


def read_only(cih: Path) -> tuple[int, float]:
    """Every frame of the MRAW touched once through pyMRAW's memory map: (frames, seconds)."""
    import pyMRAW

    start = time.perf_counter()
    images, _ = pyMRAW.load_video(str(cih))
    n = 0
    for frame in images:
        frame.max()
        n += 1
    return n, time.perf_counter() - start


def opencv_mono(cih: Path, threshold: float) -> tuple[list, float]:
    """The user's OpenCV script (:data:`OPENCV_MONO_SCRIPT`) in this process: (each frame's centres, seconds)."""
    namespace: dict = {"__name__": "opencv_mono"}
    exec(compile(OPENCV_MONO_SCRIPT, "<opencv mono baseline>", "exec"), namespace)
    start = time.perf_counter()
    centres = namespace["run"](str(cih), threshold)
    return centres, time.perf_counter() - start


def _agreement_px(track, centres: list) -> float:
    """Median distance (px) from the script's two centres to servoscope's nearest marker, over valid frames.

    A check that both measure the same dots (the script's thresholded moments are
    biased by the threshold's pixel steps; a few tenths of a pixel, not more).
    """
    d = []
    for k in np.flatnonzero(track.valid):
        if k >= len(centres) or len(centres[k]) != 2:
            continue
        ours = np.array([track.lead_xy_px[k], track.trail_xy_px[k]])
        for c in centres[k]:
            d.append(float(np.min(np.hypot(*(ours - np.asarray(c)).T))))
    return float(np.median(d)) if d else math.nan


def _settings(size: int, engine: str = "auto"):
    from .markers import TrackerSettings

    lead, trail = (tuple(float(v) for v in p) for p in _scene(size).sticker_centres_px(float(_pitch(0))))
    return TrackerSettings(lead="bright", trail="bright", led="bright", lead_near=lead, trail_near=trail,
                           engine=engine)


def _track(cih: Path, size: int, engine: str = "auto"):
    from .pipeline import track_video

    start = time.perf_counter()
    track = track_video(cih, _settings(size, engine))
    return track, time.perf_counter() - start


def _whole(cih: Path, size: int, threshold: float, workdir: Path, repeat: int) -> dict:
    """``python -m servoscope track`` and the OpenCV script as processes, best of ``repeat``: seconds and ratio."""
    import tempfile

    s = _settings(size)
    with tempfile.TemporaryDirectory(dir=workdir) as tmp:
        script = Path(tmp) / "opencv_mono.py"
        script.write_text(OPENCV_MONO_SCRIPT)
        runs = {"track": [sys.executable, "-m", "servoscope", "track", str(cih), "--out", str(Path(tmp) / "t.csv"),
                          "--lead", "bright@{:.1f},{:.1f}".format(*s.lead_near),
                          "--trail", "bright@{:.1f},{:.1f}".format(*s.trail_near), "--led", "bright"],
                "opencv": [sys.executable, str(script), str(cih), f"{threshold:g}"]}
        row = {f"{name}_s": min(run_process(argv) for _ in range(max(1, repeat))) for name, argv in runs.items()}
    row["track_over_opencv"] = row["opencv_s"] / row["track_s"]
    return row


#: Frames of the clip tracked once, untimed, before the measurements.
WARM_UP_FRAMES = 8


def warm_up(cache: Path, size: int) -> None:
    """Compile (or load from numba's cache) everything tracking runs, untimed: a short clip tracked once.

    Without it a first run after installing timed the tracker's compilation: 507 frames/s in place of
    18,727 (256x256, 2000 frames, numba's cache empty, 2-core machine).
    """
    _track(render_mono_clip(cache, WARM_UP_FRAMES, size), size)


def mono_bench(cache: Path, frames: int = 10_000, size: int = 1024, repeat: int = 1, whole: bool = False,
               echo=None) -> dict:
    """Render (once) and measure the monochrome clip; a dict of rates and ratios (see the module's docstring).

    Parameters
    ----------
    cache : Path
        Folder for the clip (it is large: ``frames · size² · 2`` bytes).
    frames, size : int
    repeat : int
        Best of this many runs of each.
    whole : bool
        Also time whole processes.
    echo : callable, optional
        Called with a line of progress text.

    Returns
    -------
    dict
        ``frames``, ``size``, ``file_gb``, each run's ``*_fps``, ``track_over_opencv``,
        ``track_over_read``, ``track_gpx_s``, the engine, the track's valid fraction and
        LED switch frame, ``load`` (the load average), and ``whole`` when asked.
    """
    say = echo or (lambda s: None)
    say(f"rendering (once) a {size}x{size} {BITS}-bit MRAW of {frames} frames in {cache} ...")
    cih = render_mono_clip(cache, frames, size)
    mraw = cih.with_suffix(".mraw")
    warm_up(cache, size)
    # The script's threshold: halfway between the blade and the dots, as a user would pick it from a frame.
    top = 2**BITS - 1
    threshold = 0.6 * top
    reads, opencvs, tracks = [], [], []
    track, centres = None, []
    for _ in range(max(1, repeat)):
        n, seconds = read_only(cih)
        if n != frames:
            raise RuntimeError(f"{cih}: read {n} of {frames} frames")
        reads.append(seconds)
        track, seconds = _track(cih, size)
        tracks.append(seconds)
        centres, seconds = opencv_mono(cih, threshold)
        opencvs.append(seconds)
    r, o, t = min(reads), min(opencvs), min(tracks)
    result = {"frames": frames, "size": size, "bits": BITS, "file_gb": mraw.stat().st_size / 1e9,
              "read_fps": frames / r, "opencv_fps": frames / o, "track_fps": frames / t,
              "track_over_opencv": o / t, "track_over_read": r / t, "track_gpx_s": frames * size * size / t / 1e9,
              "engine": _engine(size), "valid_fraction": float(np.mean(track.valid)), "tracked_frames": track.n_frames,
              "opencv_frames": len(centres), "opencv_agreement_px": _agreement_px(track, centres),
              "led_t0_s": track.t0_s, "led_t0_true_s": (frames // 2) / FPS,
              "load": os.getloadavg()[0] if hasattr(os, "getloadavg") else None}
    say(f"  read {result['read_fps']:.0f} fps, servoscope {result['track_fps']:.0f} fps "
        f"({result['track_gpx_s']:.2f} Gpx/s), OpenCV script {result['opencv_fps']:.0f} fps: "
        f"servoscope/OpenCV {result['track_over_opencv']:.1f}x, servoscope/read {result['track_over_read']:.2f}x")
    if whole:
        result["whole"] = _whole(cih, size, threshold, Path(cache), repeat)
        w = result["whole"]
        say(f"  whole: track {w['track_s']:.2f} s, OpenCV script {w['opencv_s']:.2f} s: "
            f"{w['track_over_opencv']:.1f}x")
    return result


def _engine(size: int) -> str:
    from .markers.settings import resolve_engine

    return resolve_engine(_settings(size))
