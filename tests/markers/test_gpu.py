"""The GPU pass (markers/gpu.py): its class tables, its sums in numba's CUDA simulator, its PTX for an H100.

No GPU is needed: the simulator runs the kernel's Python on the CPU (slow, so
the frames are small), and NVIDIA's NVVM (the ``nvidia-cuda-nvcc-cu12``
wheel) compiles it to the PTX a GPU would run.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from servoscope.markers import kernels as K

TESTS = str(Path(__file__).resolve().parents[1])  # where support.py is


def _run(code: str, **env: str) -> str:
    res = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], env=dict(os.environ, **env),
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stdout + res.stderr
    return res.stdout


def test_class_tables_are_the_cpu_classifier_bit_for_bit():
    sys.path.insert(0, TESTS)
    from support import kernel_frame as _frame, kernel_params as _params

    from servoscope.markers import gpu

    params = _params(_frame(0))
    tables = gpu.class_tables(params)
    assert tables.shape == (2, gpu.TABLE_WORDS) and tables.dtype == np.uint32
    u, v = np.meshgrid(np.arange(256), np.arange(256), indexing="ij")
    u, v = u.ravel(), v.ravel()
    # Unpacked the way the kernel reads it: word (u·256 + v) >> 5, bit (u·256 + v) & 31.
    idx = u * 256 + v
    for k in range(2):
        bits = (tables[k, idx >> 5] >> (idx & 31).astype(np.uint32)) & 1
        want = K.classify_np(params[k], u.astype(float), v.astype(float))
        np.testing.assert_array_equal(bits.astype(bool), want)
        assert 0 < want.sum() < want.size  # a real class: neither empty nor everything
    # The red and the green marker's classes do not overlap.
    assert not np.any(tables[0] & tables[1])


_SIMULATED = """
    import sys
    import numpy as np
    sys.path.insert(0, {tests!r})
    from support import kernel_frame as _frame, kernel_params as _params
    from servoscope.markers import TrackerSettings, gpu
    from servoscope.markers import kernels as K
    assert gpu.cuda_available()
    import numba
    # The simulator runs each thread as a Python thread: a small launch shape there, the default on a GPU.
    shape = dict(threads=64, rows_per_block=32) if numba.config.ENABLE_CUDASIM else {{}}
    frames = np.stack([_frame(s) for s in range(3)])
    h, w = 96, 128
    params = _params(frames[0])
    whole = gpu.bench_params(TrackerSettings("#d62728", "#2ca02c"), w, h)[:1]    # red, the whole frame
    outside = params[1].copy()
    outside[[K.P.X0, K.P.Y0, K.P.X1, K.P.Y1]] = (100, 70, 400, 300)              # runs past the frame's corner
    params = np.vstack([params, whole, outside])
    classifier = gpu.GpuClassifier(params, h, w, **shape)
    cpu = gpu.class_moments_cpu(frames, params)
    sim = classifier.class_moments(frames)
    assert cpu[:, :3, 0].min() > 0, cpu
    np.testing.assert_array_equal(sim, cpu)
    # Another launch shape (a block takes every other frame, 32 threads, 8 rows a strip): the same sums
    # (one marker: the shape is what is tested, and the simulator's time goes as the markers).
    other = gpu.GpuClassifier(params[:1], h, w, threads=32, rows_per_block=8, frame_blocks=2)
    np.testing.assert_array_equal(other.class_moments(frames), cpu[:, :1])
    # Streamed from host memory in batches of 2 (the last one short), on two streams: the same sums (one
    # marker: the streaming is what is tested).
    one = gpu.GpuClassifier(params[:1], h, w, **shape)
    rates = gpu.measure_rates(one, one.chroma_of(frames), batch=2, resident_passes=1)
    np.testing.assert_array_equal(gpu.moments_from_sums(rates["sums"]), cpu[:, :1])
    assert rates["bytes_per_frame"] == h * w // 2 and min(rates[k] for k in ("resident_fps", "host_fps", "copy_fps")) > 0
    # A window wholly outside the frame: nothing to do, zero sums.
    empty = params[:1].copy()
    empty[0, [K.P.X0, K.P.Y0, K.P.X1, K.P.Y1]] = (300, 300, 400, 400)
    assert not gpu.GpuClassifier(empty, h, w, **shape).class_moments(frames).any()
    assert classifier.class_moments(frames[:0]).shape == (0, 4, 3)
    # Rows wider than a block's threads (272 chroma samples, 64 threads: each takes 5, the last pass partly):
    # random chroma, so that both classes are scattered over the whole row.
    rng = np.random.default_rng(5)
    wide = rng.integers(0, 256, size=(2, 48 * 3 // 2, 544), dtype=np.uint8)
    both = gpu.bench_params(TrackerSettings("#d62728", "#2ca02c"), 544, 48)
    cpu = gpu.class_moments_cpu(wide, both)
    assert cpu[:, :, 0].min() > 0
    np.testing.assert_array_equal(gpu.GpuClassifier(both, 48, 544, threads=64).class_moments(wide), cpu)
    # Chroma rows that are not whole 32-bit words (100 px: 50 samples, laid out as 13 words with 2 padding
    # samples), 3 markers (4 bits a table entry, one unused), windows that start and end inside a word.
    odd = rng.integers(0, 256, size=(2, 36 * 3 // 2, 100), dtype=np.uint8)
    three = np.vstack([gpu.bench_params(TrackerSettings("#d62728", "#2ca02c"), 100, 36),
                       gpu.bench_params(TrackerSettings("#1f77b4", "#2ca02c"), 100, 36)[:1]])
    three[1, [K.P.X0, K.P.Y0, K.P.X1, K.P.Y1]] = (6, 3, 90, 33)
    cpu = gpu.class_moments_cpu(odd, three)
    assert cpu[:, :, 0].min() > 0
    padded = gpu.GpuClassifier(three, 36, 100, threads=32, rows_per_block=5)
    assert padded.row_words == 13 and padded.chroma_bytes == 2 * 18 * 52
    laid = padded.chroma_of(odd)
    u, v = odd[1, 36:].reshape(2, 18, 50)
    np.testing.assert_array_equal(laid[1], padded.chroma_from_planes(u, v))
    np.testing.assert_array_equal(padded.class_moments(odd), cpu)
    if not numba.config.ENABLE_CUDASIM:
        # On a GPU: a block larger than the 4-marker kernel's registers allow is refused before any launch,
        # with what to choose (an H100 runs it with 512 threads, not 1024).
        try:
            gpu.GpuClassifier(params, h, w, threads=1024)
        except ValueError as exc:
            assert "threads a block are more than this GPU runs the 4-marker pass with" in str(exc), exc
        else:
            assert gpu.class_sums_kernel(1024, gpu.ROWS_PER_BLOCK, 4).get_max_threads_per_block() >= 1024
    print("ok")
"""


@pytest.mark.parametrize("n_markers", [1, 2, 3, 4])
def test_packed_class_table_holds_each_markers_class_bit_for_bit(n_markers):
    # The kernel's one table: entry u·256 + v has a bit a marker, read as the kernel reads it.
    sys.path.insert(0, TESTS)
    from support import kernel_frame as _frame, kernel_params as _params

    from servoscope.markers import TrackerSettings, gpu

    params = np.vstack([_params(_frame(0)), gpu.bench_params(TrackerSettings("#1f77b4", "#ff7f0e"))])[:n_markers]
    tables = gpu.class_tables(params)
    packed = gpu.packed_class_table(params)
    bits = gpu.table_bits(n_markers)
    assert packed.dtype == np.uint32 and packed.size == 65536 * bits // 32
    uv = np.arange(65536)
    per_word = 32 // bits
    entry = (packed[uv // per_word] >> ((uv % per_word) * bits).astype(np.uint32)) & ((1 << bits) - 1)
    for k in range(n_markers):
        want = (tables[k, uv >> 5] >> (uv & 31).astype(np.uint32)) & 1
        np.testing.assert_array_equal((entry >> k) & 1, want)
    assert not np.any(entry >> n_markers)  # no bit beyond the markers'
    with pytest.raises(ValueError, match="1 to 4 markers"):
        gpu.table_bits(5)


def test_gpu_sums_equal_the_cpu_reference_in_the_simulator():
    assert _run(_SIMULATED.format(tests=TESTS), NUMBA_ENABLE_CUDASIM="1").startswith("ok")


def test_gpu_sums_equal_the_cpu_reference_on_a_gpu():
    # The same checks on a real GPU where one is present (the simulator runs the kernel's Python, not its PTX).
    from servoscope.markers import gpu

    if not gpu.cuda_available():
        pytest.skip("no CUDA GPU on this machine (the simulator test above runs the same checks)")
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_ENABLE_CUDASIM"}
    res = subprocess.run([sys.executable, "-c", textwrap.dedent(_SIMULATED.format(tests=TESTS))], env=env,
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0 and res.stdout.startswith("ok"), res.stdout + res.stderr[-3000:]


def test_gpu_classifier_needs_a_gpu():
    from servoscope.errors import ServoscopeError
    from servoscope.markers import gpu

    if gpu.cuda_available():
        pytest.skip("a CUDA GPU is present")
    with pytest.raises(ServoscopeError, match="no CUDA GPU"):
        gpu.GpuClassifier(np.zeros((1, K.NP)), 64, 64)


_PTX = """
    from numba import cuda
    from servoscope.markers import gpu
    assert gpu.NVVM_WHEEL, "the nvidia-cuda-nvcc-cu12 wheel was not found"
    ptx, _ = cuda.compile_ptx(gpu.class_sums_kernel(gpu.THREADS, gpu.ROWS_PER_BLOCK, 3).py_func,
                              gpu.kernel_signature(), cc=(9, 0))
    print(ptx)
"""


def test_gpu_kernel_compiles_to_ptx_for_an_h100():
    env = {k: v for k, v in os.environ.items() if k not in ("CUDA_HOME", "CUDA_PATH", "NUMBA_ENABLE_CUDASIM")}
    res = subprocess.run([sys.executable, "-c", textwrap.dedent(_PTX)], env=env, capture_output=True, text=True,
                         timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    ptx = res.stdout
    assert ".target sm_90" in ptx
    # The class tables and the tree reduction live in shared memory; each block adds its totals atomically,
    # in 64-bit integers (exact, whatever the order).
    assert "ld.shared.u32" in ptx and "bar.sync" in ptx
    assert "atom.global.add.u64" in ptx
    assert ".f64" not in ptx  # no floating point in the pass at all
    # The markers' sums and windows stay in registers: no local (stack) memory. (Indexed by a marker count known
    # only at run time, they were in local memory, read and written at every sample.)
    assert "ld.local" not in ptx and "st.local" not in ptx
    # The chroma is read as 32-bit words, 4 samples a load.
    assert "ld.global.u32" in ptx and "ld.global.u8" not in ptx


_BENCH = """
    import sys
    from pathlib import Path
    from servoscope.bench import check_targets, gpu_bench, render_bench_clips
    from servoscope.markers import gpu
    gpu.THREADS = 64  # the simulator runs each thread as a Python thread: a small block there
    clip = render_bench_clips(Path({tmp!r}), 3, 64, 48)["raw"]
    out = gpu_bench(clip, frames=3, check_frames=2, batch=2, resident_passes=1)
    assert out["simulator"] is True and out["frames"] == 3 and out["checked_frames"] == 2, out
    assert out["sums_equal_cpu"] is True, out
    assert out["bytes_per_frame"] == 64 * 48 // 2
    judged = [t["what"] for t in check_targets({{"gpu": out}})]
    assert judged == ["GPU, frames in GPU memory / 1,000,000 frames/s", "GPU, frames from host memory / copying them alone"]
    print("ok")
"""


def test_bench_gpu_path_runs_whole_in_the_simulator(tmp_path):
    # What `servoscope bench` runs on a GPU: decode, stream, check against the CPU. Its rates here are not timings.
    assert _run(_BENCH.format(tmp=str(tmp_path)), NUMBA_ENABLE_CUDASIM="1").startswith("ok")
