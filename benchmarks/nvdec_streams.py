"""NVDEC (PyNvVideoCodec) streams in parallel against PyAV processes, and NVDEC's frames against FFmpeg's, bit for bit.

Usage (on a GPU machine with ``pip install pynvvideocodec``): python benchmarks/nvdec_streams.py [FRAMES [FOLDER]]
Renders the bench's two H.264 clips (720x576, 20 Mbit/s: the camcorder's CABAC at 50 frames/s and CAVLC at 100)
into FOLDER and prints one JSON line a measurement. PyNvVideoCodec is not a servoscope dependency: this measures
whether decoding on the GPU would pay (docs/performance.md, "Decoding on the GPU").
"""
import json
import sys
import time
import traceback
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from pathlib import Path

import numpy as np
import PyNvVideoCodec as nvc
from numba import cuda

from servoscope.bench import decode_only, render_bench_clips
from servoscope.video.reader import iter_yuv_frames


def say(**kw):
    print(json.dumps(kw, default=str), flush=True)


def nvdec_all(path: Path, batch: int = 64) -> int:
    """Decode every frame of ``path`` on the GPU (frames left in GPU memory); the frame count."""
    dec = nvc.SimpleDecoder(str(path), gpu_id=0, use_device_memory=True)
    total, n = len(dec), 0
    while n < total:  # never ask past the end: the decoder warns once a missing frame
        got = dec.get_batch_frames(min(batch, total - n))
        if not got:
            break
        n += len(got)
    cuda.synchronize()
    return n


def compare(key: str, path: Path, frames: int = 60) -> None:
    """NVDEC's NV12 planes against PyAV's (FFmpeg's) yuv420p planes: H.264 decoding is exact, so they must agree."""
    try:
        got = nvc.SimpleDecoder(str(path), gpu_id=0, use_device_memory=True).get_batch_frames(frames)
        same = worst = 0
        for f, ref in zip(got, iter_yuv_frames(path)):
            y_plane, uv_plane = f.cuda()
            y = cuda.as_cuda_array(y_plane).copy_to_host()[..., 0]
            uv = cuda.as_cuda_array(uv_plane).copy_to_host()
            d = max(int(np.abs(y.astype(int) - ref.y).max()), int(np.abs(uv[..., 0].astype(int) - ref.u).max()),
                    int(np.abs(uv[..., 1].astype(int) - ref.v).max()))
            same += d == 0
            worst = max(worst, d)
        say(clip=key, frames_compared=len(got), identical=same, max_abs_diff=worst)
    except Exception:  # noqa: BLE001 - a failed comparison is a line of the output, the rates still follow
        say(clip=key, compare_error=traceback.format_exc()[-1500:])


def main() -> None:
    frames = int(sys.argv[1]) if len(sys.argv) > 1 else 1000
    folder = Path(sys.argv[2] if len(sys.argv) > 2 else "/tmp/servoscope-nvdec")
    for key, path in render_bench_clips(folder, frames, 720, 576, keys=("h264", "h264_100fps")).items():
        compare(key, path)
        for n in (1, 2, 4, 7, 8, 14):  # an H100 has 7 NVDEC engines
            start = time.perf_counter()
            with ThreadPoolExecutor(n) as ex:
                got = sum(ex.map(nvdec_all, [path] * n))
            say(clip=key, what=f"nvdec {n} streams (threads)", frames=got, fps=round(got / (time.perf_counter() - start)))
        for n in (1, 4, 8, 16):
            start = time.perf_counter()
            with ProcessPoolExecutor(n) as ex:
                got = sum(ex.map(decode_only, [path] * n))
            say(clip=key, what=f"pyav {n} processes (default threads each)", frames=got,
                fps=round(got / (time.perf_counter() - start)))


if __name__ == "__main__":
    main()
