"""``servoscope bench``: tracking speed against decoding alone and against an OpenCV pipeline.

Renders (once; later runs reuse them from the cache folder) three clips of
the digital twin (:data:`BENCH_CLIPS`): uncompressed yuv420p, a camcorder's
H.264 (20 Mbit/s at 50 frames/s, CABAC) and H.264 at 20 Mbit/s over 100
frames/s (lighter frames), and measures in one run, on this machine:

* **decode**: PyAV decoding every frame to its YUV planes, nothing else,
  with the tracker's decoder settings (like for like), and **decode_best**:
  the same at the thread count that decodes fastest on this machine (of 1,
  2, cores, cores + 1, 2·cores, 3·cores): the rate a decode-only program
  tuned for it would reach. ``track_over_best_decode`` is measured against
  that one;
* **track**: :func:`servoscope.pipeline.track_video` (the default engine:
  decoder thread + fused numba kernel on the YUV planes);
* **opencv**: a user's OpenCV pipeline — decode → BGR → HSV → ``inRange`` ×2
  → ``cv2.moments`` ×2 per frame;
* **gpu**: the CUDA batch reduction (:mod:`servoscope.markers.gpu`), when a
  CUDA GPU is present;
* **parallel**: several videos tracked by a pool of worker processes, and
  the same with one decoder thread per video against one process on one
  core (one decoder thread);
* **whole** (``--whole``): whole processes, start-up included —
  ``python -m servoscope track`` against an OpenCV script and a decode-only
  script run by the same Python.

Frames per second and the ratios track/opencv and track/decode are printed,
then each of the issue's targets (:data:`TARGETS`) this run measured, met or
not (``--json``: one JSON object). Timings are wall-clock, best of ``--repeat``.
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

from .bench_process import run_process
from .defaults import LEAD_COLOUR, LED_COLOUR, TRAIL_COLOUR

__all__ = ["bench", "run_bench", "render_bench_clips", "check_targets", "gpu_bench", "BENCH_CLIPS", "TARGETS",
           "opencv_pipeline", "decode_only", "whole_commands"]

LEAD = LEAD_COLOUR
TRAIL = TRAIL_COLOUR
LED = LED_COLOUR


def _default_cache() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "servoscope" / "bench"


#: The benchmark's clips: key → (codec, frames/s, x264 preset, file suffix). All at 20 Mbit/s when lossy.
#: ``h264`` is a camcorder's footage, the issue's yardstick: PAL's 50 frames/s, CABAC (x264 ``veryfast``,
#: as AVCHD's High profile), 50 kB a frame; its decoding runs at ~300 frames/s on 2 cores. ``h264_100fps``
#: spreads the same bit rate over twice the frames with x264 ``ultrafast`` (CAVLC), 25 kB a frame: decoding
#: is ~5× lighter, so tracking's own cost weighs most there.
BENCH_CLIPS: dict[str, tuple[str, float, str, str]] = {
    "raw": ("raw", 100.0, "ultrafast", ".avi"),
    "h264": ("h264", 50.0, "veryfast", ".mp4"),
    "h264_100fps": ("h264", 100.0, "ultrafast", ".mp4"),
}


#: Frames of the clips tracked once, untimed, before the measurements (:func:`_warm_up`).
_WARM_UP_FRAMES = 8


def render_bench_clips(cache: Path, frames: int, width: int, height: int,
                       keys: tuple[str, ...] | None = None) -> dict[str, Path]:
    """The benchmark's clips (:data:`BENCH_CLIPS`, or those of ``keys``), rendered unless already in ``cache``."""
    from .simulate import Scene
    from .simulate.clips import render_clip

    cache.mkdir(parents=True, exist_ok=True)
    scene = Scene.for_size(width, height, background_seed=2)
    clips = {}
    for key, (codec, fps, preset, suffix) in BENCH_CLIPS.items():
        if keys is not None and key not in keys:
            continue
        name = f"bench_{width}x{height}_{frames}_{codec}" if codec == "raw" else \
            f"bench_{width}x{height}_{frames}_{codec}_{fps:g}fps_{preset}"
        path = cache / (name + suffix)
        done = path.with_suffix(path.suffix + ".ok")
        if not done.exists():
            t = np.arange(frames) / fps
            pitch = 0.04 * np.sin(2 * np.pi * 1.5 * t) + 0.01 * np.sin(2 * np.pi * 7.0 * t)
            render_clip(path, scene, pitch, fps=fps, codec=codec, bit_rate=20_000_000, noise_seed=1, preset=preset)
            done.write_text("ok\n")
        clips[key] = path
    return clips


def decode_only(path: Path, threads: int = 0) -> int:
    """Decode every frame to its YUV planes (PyAV); the frame count.

    The same decoder settings and plane views as the tracker's decoder thread
    (:func:`servoscope.video.reader.configure_decoder`,
    :func:`~servoscope.video.reader.yuv_planes`), so that track/decode
    compares like with like.
    """
    import av

    from .video.reader import configure_decoder, yuv_planes

    n = 0
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        configure_decoder(stream, threads)
        for frame in container.decode(stream):
            yuv_planes(frame)
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
    """A user's OpenCV pipeline: decode → BGR → HSV → inRange ×2 → moments ×2; the frame count.

    The same source as the whole-command baseline (:data:`OPENCV_SCRIPT`), run in this process.
    """
    namespace: dict = {"__name__": "servoscope_opencv_baseline"}
    exec(compile(OPENCV_SCRIPT.format(bands=[_hsv_band(lead), _hsv_band(trail)]), "<opencv baseline>", "exec"), namespace)
    return namespace["run"](str(path))


def _track(path: str) -> int:
    from .markers import TrackerSettings
    from .pipeline import track_video

    return track_video(path, TrackerSettings(LEAD, TRAIL, LED)).n_frames


def _one_decoder_thread() -> None:
    """Pool initializer (and one-core run): a single decoder thread, so one video uses one core."""
    from .video import reader

    reader.DECODER_THREADS = 1


def _pin_one_core() -> None:
    """Pool initializer of the one-core baseline: this process on one CPU, one decoder thread.

    Without the pinning, "one process" is not one core: the decoder thread
    and the tracking thread run side by side on two.
    """
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    _one_decoder_thread()


#: The whole-command OpenCV baseline, written to a temporary file and run with the same Python:
#: what a user's script costs as a process (start-up and imports included).
OPENCV_SCRIPT = """\
import sys
import av, cv2
BANDS = {bands!r}


def run(path):
    n = 0
    with av.open(path) as container:
        stream = container.streams.video[0]
        stream.thread_type = "AUTO"
        for frame in container.decode(stream):
            hsv = cv2.cvtColor(frame.to_ndarray(format="bgr24"), cv2.COLOR_BGR2HSV)
            for marker in BANDS:
                mask = cv2.inRange(hsv, *marker[0])
                for extra in marker[1:]:
                    mask |= cv2.inRange(hsv, *extra)
                cv2.moments(mask, binaryImage=True)
            n += 1
    return n


if __name__ == "__main__":
    print(run(sys.argv[1]))
"""

#: The whole-command decode-only baseline (PyAV, the tracker's decoder settings).
DECODE_SCRIPT = """\
import sys
from servoscope.bench import decode_only
print(decode_only(sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 0))
"""


def whole_commands(clips: dict[str, Path], workdir: Path, repeat: int = 1, echo=None,
                   decode_threads: dict[str, int] | None = None) -> dict:
    """Whole-process timings: ``python -m servoscope track`` vs an OpenCV script and a decode-only script.

    Each is a fresh process of the same Python (imports, numba's cached
    kernels, the video's decoding and the CSV all included), best of
    ``repeat``; the ratios are time(baseline) / time(track). The decode-only
    script decodes with ``decode_threads[codec]`` threads (the fastest count
    found in-process) when given, else with the tracker's settings.
    """
    import sys
    import tempfile

    say = echo or (lambda s: None)
    result = {}
    with tempfile.TemporaryDirectory(dir=workdir) as tmp:
        opencv = Path(tmp) / "opencv_baseline.py"
        opencv.write_text(OPENCV_SCRIPT.format(bands=[_hsv_band(LEAD), _hsv_band(TRAIL)]))
        decode = Path(tmp) / "decode_baseline.py"
        decode.write_text(DECODE_SCRIPT)
        out = Path(tmp) / "track.csv"
        for codec, clip in clips.items():
            runs = {
                "track": [sys.executable, "-m", "servoscope", "track", str(clip), "--out", str(out)],
                "opencv": [sys.executable, str(opencv), str(clip)],
                "decode": [sys.executable, str(decode), str(clip)]
                + ([str(decode_threads[codec])] if decode_threads and codec in decode_threads else []),
            }
            row = {f"{name}_s": min(run_process(argv) for _ in range(max(1, repeat))) for name, argv in runs.items()}
            row["track_over_opencv"] = row["opencv_s"] / row["track_s"]
            row["track_over_decode"] = row["decode_s"] / row["track_s"]
            result[codec] = row
            say(f"  whole {codec:5s} track {row['track_s']:.2f} s, opencv {row['opencv_s']:.2f} s, decode "
                f"{row['decode_s']:.2f} s: track/opencv {row['track_over_opencv']:.1f}x, "
                f"track/decode {row['track_over_decode']:.2f}x")
    return result


def gpu_bench(path: Path, frames: int, check_frames: int = 16, batch: int = 256, resident_passes: int = 20) -> dict:
    """The GPU pass (:mod:`servoscope.markers.gpu`) on up to ``frames`` frames of ``path``; a dict.

    The frames are decoded first and held in host memory (their chroma, all
    the pass reads). Measured: frames/s on frames already in GPU memory,
    frames/s streamed from host memory, the same streaming without the kernel
    (the copy rate: the bound), and whether the sums of the first
    ``check_frames`` frames equal the CPU reference's. Without a usable GPU:
    ``{"gpu": "<why not>"}``. Under numba's CUDA simulator everything runs
    (a test's tiny clip), marked ``simulator: True``: its rates are not GPU timings.
    """
    import numba

    from .markers import TrackerSettings, gpu
    from .video.reader import iter_yuv_frames

    if not gpu.cuda_available():
        return {"gpu": "no CUDA GPU on this machine"}
    from numba import cuda

    classifier = None
    chroma, check = [], []
    for frame in iter_yuv_frames(path):
        if classifier is None:
            height, width = frame.y.shape
            params = gpu.bench_params(TrackerSettings(LEAD, TRAIL, LED), width, height)
            classifier = gpu.GpuClassifier(params, height, width)
        if len(check) < check_frames:
            check.append(frame.i420)
        chroma.append(classifier.chroma_from_planes(frame.u, frame.v))
        if len(chroma) == frames:
            break
    rates = gpu.measure_rates(classifier, np.stack(chroma), batch=batch, resident_passes=resident_passes)
    sums = rates.pop("sums")[:len(check)]
    rates["sums_equal_cpu"] = bool(np.array_equal(gpu.moments_from_sums(sums),
                                                  gpu.class_moments_cpu(np.stack(check), params)))
    rates["checked_frames"] = len(check)
    rates["resident_over_target"] = rates["resident_fps"] / 1e6
    rates["simulator"] = bool(numba.config.ENABLE_CUDASIM)
    name = "numba's CUDA simulator" if rates["simulator"] else cuda.get_current_device().name
    rates["device"] = name.decode(errors="replace") if isinstance(name, bytes) else str(name)
    rates["frames"] = len(chroma)
    return rates


def _decoder_thread_counts() -> list[int]:
    """Thread counts tried for the fastest decode-only rate (the tracker's own count among them)."""
    from .video.reader import default_decoder_threads

    cores = os.cpu_count() or 1
    return sorted({1, 2, cores, cores + 1, 2 * cores, default_decoder_threads()})


def _timed(fn, *args, repeat: int = 1) -> tuple[float, int]:
    best = math.inf
    n = 0
    for _ in range(max(1, repeat)):
        start = time.perf_counter()
        n = fn(*args)
        best = min(best, time.perf_counter() - start)
    return best, n


def _warm_up(cache: Path, width: int, height: int) -> None:
    """Compile (or load from numba's cache) everything tracking runs, before anything is timed.

    Tracks a short clip of each kind once. Compiling only the frame kernel left the rest of the tracker
    (the LED, the sub-pixel step, the checks) to compile inside the first clip's timing: on a fresh
    install (numba's cache empty) that read 960 frames/s in place of ~4,400 on the 2-core machine.
    """
    for path in render_bench_clips(cache, _WARM_UP_FRAMES, width, height, keys=("raw", "h264")).values():
        _track(str(path))


def _say_gpu(gpu_result: dict, say) -> None:
    if "resident_fps" in gpu_result:
        g = gpu_result
        say(f"  gpu ({g['device']}): {g['resident_fps']:.0f} frames/s in GPU memory, {g['host_fps']:.0f} frames/s "
            f"from host memory against {g['copy_fps']:.0f} copied alone ({g['host_over_copy']:.2f}x); "
            f"sums equal the CPU's: {g['sums_equal_cpu']}")
    else:
        say(f"  gpu: {gpu_result['gpu']}")


def _judge(result: dict, say) -> dict:
    result["targets"] = check_targets(result)
    for t in result["targets"]:
        say(f"  target {t['what']}: {t['measured']:.2f}x (>= {t['target']:g}x) {'met' if t['met'] else 'NOT met'}")
    return result


def run_bench(frames: int = 2000, width: int = 720, height: int = 576, cache: Path | None = None,
              repeat: int = 1, workers: int = 2, parallel_videos: int = 4, echo=None, whole: bool = False,
              gpu_only: bool = False) -> dict:
    """Run every measurement; a plain dict of frames/s and ratios (see the module's doc).

    ``gpu_only``: render the uncompressed clip only and time the GPU pass alone
    (what a short session on a GPU machine needs).
    """
    say = echo or (lambda s: None)
    cache = Path(cache) if cache is not None else _default_cache()
    say(f"clips: {cache} ({frames} frames {width}x{height}; rendered once)")
    clips = render_bench_clips(cache, frames, width, height, keys=("raw",) if gpu_only else None)
    result: dict = {"frames": frames, "size": f"{width}x{height}", "cpu_count": os.cpu_count(), "clips": {}}
    if gpu_only:
        result["gpu"] = gpu_bench(clips["raw"], frames)
        _say_gpu(result["gpu"], say)
        return _judge(result, say)
    _warm_up(cache, width, height)
    for codec, path in clips.items():
        row = {}
        for name, fn in (("decode", decode_only), ("track", lambda p: _track(str(p))), ("opencv", opencv_pipeline)):
            seconds, n = _timed(fn, path, repeat=repeat)
            row[f"{name}_fps"] = n / seconds
            say(f"  {codec:5s} {name:7s} {n / seconds:8.0f} frames/s ({seconds:.2f} s)")
        best = (0.0, 0)
        for threads in _decoder_thread_counts():
            seconds, n = _timed(decode_only, path, threads, repeat=repeat)
            best = max(best, (n / seconds, threads))
        row["decode_best_fps"], row["decode_best_threads"] = best
        say(f"  {codec:5s} decode, fastest thread count ({best[1]}): {best[0]:8.0f} frames/s")
        row["track_over_opencv"] = row["track_fps"] / row["opencv_fps"]
        row["track_over_decode"] = row["track_fps"] / row["decode_fps"]
        row["track_over_best_decode"] = row["track_fps"] / row["decode_best_fps"]
        say(f"  {codec:5s} track/opencv {row['track_over_opencv']:.1f}x, track/decode {row['track_over_decode']:.2f}x "
            f"(same decoder settings), {row['track_over_best_decode']:.2f}x (fastest decoding)")
        result["clips"][codec] = row
    result["gpu"] = gpu_bench(clips["raw"], frames)
    _say_gpu(result["gpu"], say)
    if workers > 1 and parallel_videos > 0:
        # The pair: uncompressed footage and a camcorder's H.264.
        videos = [str(clips["raw"]), str(clips["h264"])] * max(1, parallel_videos // 2)
        start = time.perf_counter()
        seq = sum(_track(v) for v in videos)
        t_seq = time.perf_counter() - start
        # One core: one process pinned to one CPU, one decoder thread (the default decoder is
        # multi-threaded and decodes beside the tracking thread, so "one process" above already
        # uses every core for H.264).
        start = time.perf_counter()
        with ProcessPoolExecutor(max_workers=1, initializer=_pin_one_core) as pool:
            one = sum(pool.map(_track, videos))
        t_one = time.perf_counter() - start
        start = time.perf_counter()
        with ProcessPoolExecutor(max_workers=workers) as pool:
            par = sum(pool.map(_track, videos))
        t_par = time.perf_counter() - start
        start = time.perf_counter()
        with ProcessPoolExecutor(max_workers=workers, initializer=_one_decoder_thread) as pool:
            par1 = sum(pool.map(_track, videos))
        t_par1 = time.perf_counter() - start
        result["parallel"] = {"videos": len(videos), "workers": workers, "sequential_fps": seq / t_seq,
                              "parallel_fps": par / t_par, "speedup": t_seq / t_par,
                              "one_core_fps": one / t_one, "parallel_one_thread_fps": par1 / t_par1,
                              "speedup_over_one_core": t_one / t_par1}
        say(f"  {len(videos)} videos: one process {seq / t_seq:.0f} frames/s, {workers} processes "
            f"{par / t_par:.0f} frames/s ({t_seq / t_par:.2f}x)")
        say(f"  {len(videos)} videos, one decoder thread each: one process on one core {one / t_one:.0f} frames/s, "
            f"{workers} processes {par1 / t_par1:.0f} frames/s ({t_one / t_par1:.2f}x)")
    if whole:
        result["whole"] = whole_commands(clips, cache, repeat=repeat, echo=say, decode_threads={
            codec: row["decode_best_threads"] for codec, row in result["clips"].items()})
    return _judge(result, say)


#: The issue's targets on a 2-core machine: (what, where in the result, at least).
TARGETS: tuple[tuple[str, tuple[str, ...], float], ...] = (
    ("raw, tracking / OpenCV, in-process", ("clips", "raw", "track_over_opencv"), 10.0),
    ("raw, tracking / OpenCV, whole commands", ("whole", "raw", "track_over_opencv"), 5.0),
    ("H.264 (camcorder), tracking / fastest decoding, in-process", ("clips", "h264", "track_over_best_decode"), 0.9),
    ("H.264 (camcorder), tracking / decoding, whole commands", ("whole", "h264", "track_over_decode"), 0.75),
    ("H.264 (100 fps, light frames), tracking / fastest decoding, in-process",
     ("clips", "h264_100fps", "track_over_best_decode"), 0.9),
    ("H.264 (100 fps, light frames), tracking / decoding, whole commands",
     ("whole", "h264_100fps", "track_over_decode"), 0.75),
    ("several videos, 2 processes / one core", ("parallel", "speedup_over_one_core"), 1.7),
    ("GPU, frames in GPU memory / 1,000,000 frames/s", ("gpu", "resident_over_target"), 1.0),
    ("GPU, frames from host memory / copying them alone", ("gpu", "host_over_copy"), 0.7),
)


def check_targets(result: dict) -> list[dict]:
    """The measured ratio against each of :data:`TARGETS` that this run measured."""
    rows = []
    for what, keys, target in TARGETS:
        value = result
        for key in keys:
            value = value.get(key) if isinstance(value, dict) else None
        if value is not None:
            rows.append({"what": what, "measured": float(value), "target": target, "met": bool(value >= target)})
    return rows


@click.command("bench")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object instead of text.")
@click.option("--frames", type=click.IntRange(min=2), default=None,
              help="Frames per clip.  [default: 2000; with --mono 10000]")
@click.option("--size", default=None, help="Frame size WxH (even).  [default: 720x576; with --mono 1024x1024]")
@click.option("--cache", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Folder for the rendered clips (default ~/.cache/servoscope/bench).")
@click.option("--repeat", type=click.IntRange(min=1), default=1, show_default=True, help="Best of this many runs.")
@click.option("--workers", type=click.IntRange(min=1), default=2, show_default=True,
              help="Processes of the multi-video run (1: skip it).")
@click.option("--whole", is_flag=True,
              help="Also time whole processes: `python -m servoscope track` vs an OpenCV script and decode-only.")
@click.option("--gpu-only", is_flag=True, help="Only the GPU pass, on the uncompressed clip.")
@click.option("--mono", is_flag=True,
              help="A monochrome high-speed camera's 12-bit MRAW instead: tracking vs reading the file alone and vs a "
                   "user's OpenCV script (threshold, contours, moments of each whole frame).")
def bench(as_json: bool, frames: int | None, size: str | None, cache: Path | None, repeat: int, workers: int,
          whole: bool, gpu_only: bool, mono: bool) -> None:
    """Tracking speed vs decoding alone and vs an OpenCV pipeline (raw and H.264 clips; --mono: an MRAW)."""
    size = size or ("1024x1024" if mono else "720x576")
    frames = frames or (10_000 if mono else 2000)
    try:
        width, height = (int(v) for v in size.lower().split("x"))
    except ValueError:
        raise click.BadParameter(f"{size!r} is not WxH", param_hint="--size") from None
    if width % 2 or height % 2 or width < 64 or height < 64:
        raise click.BadParameter("width and height must be even and ≥ 64", param_hint="--size")
    echo = None if as_json else click.echo
    if mono:
        from .bench_mono import MONO_TARGETS, mono_bench

        if width != height:
            raise click.BadParameter("--mono renders square frames (WxW)", param_hint="--size")
        result = mono_bench(cache or _default_cache(), frames, width, repeat, whole, echo=echo)
        result["targets"] = [{"what": what, "measured": result[key], "target": target,
                              "met": bool(result[key] >= target)} for what, key, target in MONO_TARGETS]
        if as_json:
            click.echo(json.dumps(result))
        else:
            for row in result["targets"]:
                click.echo(f"  target {row['what']}: {row['measured']:.2f} (>= {row['target']:g}) "
                           f"{'met' if row['met'] else 'NOT met'}")
        return
    result = run_bench(frames, width, height, cache, repeat, workers, echo=echo, whole=whole, gpu_only=gpu_only)
    if as_json:
        click.echo(json.dumps(result))
