"""Launch shapes of the GPU pass on a real GPU: threads x rows a strip x blocks along the frames, one process.

Usage: python benchmarks/gpu_launch_shapes.py CLIP [JSON grid, e.g. "[[256,512],[64,144],[65536]]"]
(CLIP: an uncompressed clip, e.g. the one `servoscope bench --gpu-only` renders). One JSON line a shape."""
import itertools
import json
import sys

import numpy as np

from servoscope.bench import LEAD, LED, TRAIL
from servoscope.markers import TrackerSettings, gpu
from servoscope.video.reader import iter_yuv_frames

chroma, check = [], []
for fr in iter_yuv_frames(sys.argv[1]):
    if not chroma:
        h, w = fr.y.shape
        params = gpu.bench_params(TrackerSettings(LEAD, TRAIL, LED), w, h)
    if len(check) < 8:
        check.append(fr.i420)
    chroma.append(np.concatenate((fr.u, fr.v), axis=None))
    if len(chroma) == 512:
        break
chroma = np.stack(chroma)
want = gpu.class_moments_cpu(np.stack(check), params)
grid = json.loads(sys.argv[2]) if len(sys.argv) > 2 else [[128, 256, 512], [32, 64, 144], [32, 64, 128, 256]]
for threads, rows, fb in itertools.product(*grid):
    try:
        c = gpu.GpuClassifier(params, h, w, threads=threads, rows_per_block=rows, frame_blocks=fb)
        r = gpu.measure_rates(c, chroma, batch=256, resident_passes=20)
        ok = bool(np.array_equal(gpu.moments_from_sums(r.pop("sums")[:8]), want))
        print(json.dumps({"threads": threads, "rows": rows, "frame_blocks": fb, "equal_cpu": ok,
                          **{k: round(v) for k, v in r.items() if k.endswith("fps")}}), flush=True)
    except Exception as exc:  # noqa: BLE001
        print(json.dumps({"threads": threads, "rows": rows, "frame_blocks": fb, "error": repr(exc)[-300:]}), flush=True)
