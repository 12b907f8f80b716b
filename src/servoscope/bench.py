"""``servoscope bench``: tracking speed against decoding alone and against an OpenCV pipeline.

Renders (once; later runs reuse them from the cache folder) two clips of the
digital twin, uncompressed yuv420p and H.264 at 20 Mbit/s, and measures in
one run, on this machine:

* **decode**: PyAV decoding every frame to its YUV planes, nothing else;
* **track**: :func:`servoscope.markers.track_video` (the default engine:
  decoder thread + fused numba kernel on the YUV planes);
* **opencv**: a user's OpenCV pipeline — decode → BGR → HSV → ``inRange`` ×2
  → ``cv2.moments`` ×2 per frame;
* **gpu**: the CUDA batch reduction (:mod:`servoscope.markers.gpu`), when a
  CUDA GPU is present;
* **parallel**: several videos tracked by a pool of worker processes.

Frames per second and the ratios track/opencv and track/decode are printed
(``--json``: one JSON object). Timings are wall-clock, best of ``--repeat``.
"""

from __future__ import annotations

import json
import math
import os
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import click
import numpy as np

__all__ = ["bench", "run_bench", "render_bench_clips", "opencv_pipeline", "decode_only"]

LEAD = "#d62728"
TRAIL = "#2ca02c"
LED = "#ffd400"


def _default_cache() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "servoscope" / "bench"


def render_bench_clips(cache: Path, frames: int, width: int, height: int, fps: float = 100.0) -> dict[str, Path]:
    """The benchmark's clips (raw and H.264), rendered unless already in ``cache``."""
    from .simulate import Scene
    from .simulate.clips import render_clip

    cache.mkdir(parents=True, exist_ok=True)
    scene = Scene.for_size(width, height, background_seed=2)
    t = np.arange(frames) / fps
    pitch = 0.04 * np.sin(2 * np.pi * 1.5 * t) + 0.01 * np.sin(2 * np.pi * 7.0 * t)
    clips = {}
    for codec, suffix in (("raw", ".avi"), ("h264", ".mp4")):
        path = cache / f"bench_{width}x{height}_{frames}_{codec}{suffix}"
        done = path.with_suffix(path.suffix + ".ok")
        if not done.exists():
            render_clip(path, scene, pitch, fps=fps, codec=codec, bit_rate=20_000_000, noise_seed=1)
            done.write_text("ok\n")
        clips[codec] = path
    return clips


def decode_only(path: Path) -> int:
    """Decode every frame to its YUV planes (PyAV); the frame count."""
    import av

    n = 0
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        stream.thread_type = "AUTO"
        for frame in container.decode(stream):
            frame.to_ndarray()  # yuv420p: the planes, (h·3/2, w)
            n += 1
    return n


def _hsv_band(colour: str, half: int = 10) -> list[tuple[tuple[int, int, int], tuple[int, int, int]]]:
    import cv2
    from matplotlib.colors import to_rgb

    rgb = np.uint8([[[round(255 * c) for c in to_rgb(colour)]]])
    h = int(cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV)[0, 0, 0])
    lo, hi = h - half, h + half
    bands = [((max(lo, 0), 100, 60), (min(hi, 179), 255, 255))]
    if lo < 0:
        bands.append(((180 + lo, 100, 60), (179, 255, 255)))
    if hi > 179:
        bands.append(((0, 100, 60), (hi - 180, 255, 255)))
    return bands


def opencv_pipeline(path: Path, lead: str = LEAD, trail: str = TRAIL) -> int:
    """A user's OpenCV pipeline: decode → BGR → HSV → inRange ×2 → moments ×2; the frame count."""
    import av
    import cv2

    bands = [_hsv_band(lead), _hsv_band(trail)]
    n = 0
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        stream.thread_type = "AUTO"
        for frame in container.decode(stream):
            hsv = cv2.cvtColor(frame.to_ndarray(format="bgr24"), cv2.COLOR_BGR2HSV)
            for marker in bands:
                mask = cv2.inRange(hsv, *marker[0])
                for extra in marker[1:]:
                    mask |= cv2.inRange(hsv, *extra)
                cv2.moments(mask, binaryImage=True)
            n += 1
    return n


def _track(path: str) -> int:
    from .markers import TrackerSettings, track_video

    return track_video(path, TrackerSettings(LEAD, TRAIL, LED)).n_frames


def _gpu_rate(path: Path, batch: int = 64) -> float | None:
    from .markers import gpu

    if not gpu.cuda_available():
        return None
    from .markers import TrackerSettings
    from .video.reader import iter_yuv_frames

    classifier = gpu.GpuClassifier()
    prm = gpu.bench_params(TrackerSettings(LEAD, TRAIL, LED))
    frames = []
    n = 0
    start = time.perf_counter()
    for frame in iter_yuv_frames(path):
        frames.append(frame.i420)
        if len(frames) == batch:
            classifier.class_moments(np.stack(frames), prm)
            n += len(frames)
            frames = []
    if frames:
        classifier.class_moments(np.stack(frames), prm)
        n += len(frames)
    return n / (time.perf_counter() - start)


def _timed(fn, *args, repeat: int = 1) -> tuple[float, int]:
    best = math.inf
    n = 0
    for _ in range(max(1, repeat)):
        start = time.perf_counter()
        n = fn(*args)
        best = min(best, time.perf_counter() - start)
    return best, n


def _warm_up() -> None:
    """Compile (or load from numba's cache) the kernels before anything is timed."""
    from .markers import kernels as K

    y = np.zeros((16, 16), np.uint8)
    c = np.full((8, 8), 128, np.uint8)
    prm = np.zeros((2, K.NP))
    K.track_frame_numba(y, c, c, 0, 1, prm, np.zeros(K.LED_NP), np.zeros((2, K.NQ)), np.zeros(K.LED_NQ))


def run_bench(frames: int = 2000, width: int = 720, height: int = 576, cache: Path | None = None,
              repeat: int = 1, workers: int = 2, parallel_videos: int = 4, echo=None) -> dict:
    """Run every measurement; a plain dict of frames/s and ratios (see the module's doc)."""
    say = echo or (lambda s: None)
    cache = Path(cache) if cache is not None else _default_cache()
    say(f"clips: {cache} ({frames} frames {width}x{height}; rendered once)")
    clips = render_bench_clips(cache, frames, width, height)
    _warm_up()
    result: dict = {"frames": frames, "size": f"{width}x{height}", "cpu_count": os.cpu_count(), "clips": {}}
    for codec, path in clips.items():
        row = {}
        for name, fn in (("decode", decode_only), ("track", lambda p: _track(str(p))), ("opencv", opencv_pipeline)):
            seconds, n = _timed(fn, path, repeat=repeat)
            row[f"{name}_fps"] = n / seconds
            say(f"  {codec:5s} {name:7s} {n / seconds:8.0f} frames/s ({seconds:.2f} s)")
        gpu_fps = _gpu_rate(path)
        row["gpu_fps"] = gpu_fps
        row["track_over_opencv"] = row["track_fps"] / row["opencv_fps"]
        row["track_over_decode"] = row["track_fps"] / row["decode_fps"]
        say(f"  {codec:5s} track/opencv {row['track_over_opencv']:.1f}x, track/decode {row['track_over_decode']:.2f}x"
            + ("" if gpu_fps is None else f", gpu {gpu_fps:.0f} frames/s"))
        result["clips"][codec] = row
    if gpu_fps is None:
        result["gpu"] = "no CUDA GPU on this machine"
    if workers > 1 and parallel_videos > 0:
        videos = [str(p) for p in clips.values()] * max(1, parallel_videos // len(clips))
        start = time.perf_counter()
        seq = sum(_track(v) for v in videos)
        t_seq = time.perf_counter() - start
        start = time.perf_counter()
        with ProcessPoolExecutor(max_workers=workers) as pool:
            par = sum(pool.map(_track, videos))
        t_par = time.perf_counter() - start
        result["parallel"] = {"videos": len(videos), "workers": workers, "sequential_fps": seq / t_seq,
                              "parallel_fps": par / t_par, "speedup": t_seq / t_par}
        say(f"  {len(videos)} videos: one process {seq / t_seq:.0f} frames/s, {workers} processes "
            f"{par / t_par:.0f} frames/s ({t_seq / t_par:.2f}x)")
    return result


@click.command("bench")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object instead of text.")
@click.option("--frames", type=click.IntRange(min=2), default=2000, show_default=True, help="Frames per clip.")
@click.option("--size", default="720x576", show_default=True, help="Frame size WxH (even).")
@click.option("--cache", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Folder for the rendered clips (default ~/.cache/servoscope/bench).")
@click.option("--repeat", type=click.IntRange(min=1), default=1, show_default=True, help="Best of this many runs.")
@click.option("--workers", type=click.IntRange(min=1), default=2, show_default=True,
              help="Processes of the multi-video run (1: skip it).")
def bench(as_json: bool, frames: int, size: str, cache: Path | None, repeat: int, workers: int) -> None:
    """Tracking speed vs decoding alone and vs an OpenCV pipeline (raw and H.264 clips)."""
    try:
        width, height = (int(v) for v in size.lower().split("x"))
    except ValueError:
        raise click.BadParameter(f"{size!r} is not WxH", param_hint="--size") from None
    if width % 2 or height % 2 or width < 64 or height < 64:
        raise click.BadParameter("width and height must be even and ≥ 64", param_hint="--size")
    echo = None if as_json else click.echo
    result = run_bench(frames, width, height, cache, repeat, workers, echo=echo)
    if as_json:
        click.echo(json.dumps(result))
