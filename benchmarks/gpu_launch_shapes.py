"""Launch shapes of the GPU pass on a real GPU: threads x rows a strip x blocks along the frames, one process.

Usage: python benchmarks/gpu_launch_shapes.py CLIP [JSON grid, e.g. "[[256,512],[64,144],[65536]]"]
                                              [--markers N] [--baseline OLD_GPU_PY]
(CLIP: an uncompressed clip, e.g. the one `servoscope bench --gpu-only` renders.) One JSON line a shape.

``--markers N``: classify N markers a pass (the bench's lead and trail, then blue and orange; default 2).
``--baseline OLD_GPU_PY``: a ``markers/gpu.py`` of an earlier commit (``git show REV:src/servoscope/markers/gpu.py``),
timed first and last at its own default shape in the same process, so that every shape reads as a ratio to it.
"""
import argparse
import importlib.util
import itertools
import json

import numpy as np

from servoscope.bench import LEAD, LED, TRAIL
from servoscope.markers import TrackerSettings, gpu
from servoscope.video.reader import iter_yuv_frames

ap = argparse.ArgumentParser()
ap.add_argument("clip")
ap.add_argument("grid", nargs="?", default="[[128, 256, 512], [32, 64, 144], [32, 64, 128, 256]]")
ap.add_argument("--markers", type=int, default=2)
ap.add_argument("--baseline")
ap.add_argument("--frames", type=int, default=512)
args = ap.parse_args()

frames, check = [], []
for fr in iter_yuv_frames(args.clip):
    if not frames:
        h, w = fr.y.shape
        params = np.vstack([gpu.bench_params(TrackerSettings(LEAD, TRAIL, LED), w, h),
                            gpu.bench_params(TrackerSettings("#1f77b4", "#ff7f0e"), w, h)])[:args.markers]
    frames.append(fr.i420)
    if len(frames) == args.frames:
        break
frames = np.stack(frames)
want = gpu.class_moments_cpu(frames[:8], params)


def run(module, label, **shape):
    try:
        c = module.GpuClassifier(params, h, w, **shape)
        r = module.measure_rates(c, c.chroma_of(frames), batch=256, resident_passes=20)
        ok = bool(np.array_equal(module.moments_from_sums(r.pop("sums")[:8]), want))
        out = {"kernel": label, "markers": args.markers, "equal_cpu": ok,
               **{k: round(v) for k, v in r.items() if k.endswith("fps")}}
    except Exception as exc:  # noqa: BLE001 - one shape's failure is a line of the table, not the end of it
        out = {"kernel": label, "error": repr(exc)[-300:]}
    print(json.dumps({**shape, **out}), flush=True)
    return out


old = None
if args.baseline:
    # Imported as a sibling of markers/gpu.py, so that its relative imports resolve.
    spec = importlib.util.spec_from_file_location("servoscope.markers._gpu_baseline", args.baseline)
    old = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(old)
    run(old, "baseline")
for threads, rows, fb in itertools.product(*json.loads(args.grid)):
    run(gpu, "this", threads=threads, rows_per_block=rows, frame_blocks=fb)
if old is not None:
    run(old, "baseline")
