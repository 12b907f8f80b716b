"""The paper's GPU reduction: classify pixels by colour, block-reduce their moments, per frame.

A batch of frames goes to the GPU at once, as their chroma planes only (U
then V of each frame, PyAV's yuv420p order): the class test needs nothing
else, and chroma is a third of a 4:2:0 frame's bytes. One fused pass reads
every chroma sample once for all markers (lead, trail, LED, ...):

* **classify** by a table of the 65 536 (U, V) pairs per marker, made on the
  host by the CPU classifier itself (:func:`class_tables`), bit-packed
  (8 kB a marker) and held in shared memory. The GPU therefore classifies
  every sample exactly as the CPU does, whatever the colour model;
* **reduce** each marker's m00, m10, m01 (in integers: the class count and
  the sums of the samples' column and row indices) within a block, a tree
  in shared memory as in the paper, then one atomic add per block into the
  frame's totals. Integer sums do not depend on the order of the additions,
  so the results equal the CPU's bit for bit (:func:`class_moments_cpu`),
  on any GPU and in any launch configuration.

Blocks run over (frames, strip of chroma rows), ``THREADS`` threads across a
row, so that a warp reads consecutive bytes.

Needs numba's CUDA support and a CUDA GPU, or numba's simulator
(``NUMBA_ENABLE_CUDASIM=1``, slow; the tests use it on small frames). Install
with the ``gpu`` extra (``pip install servoscope[gpu]``): numba already
brings ``numba.cuda``; a GPU needs only the NVIDIA driver and CUDA runtime.
:func:`measure_rates` is what ``servoscope bench`` runs on a GPU.
"""

from __future__ import annotations

import functools
import importlib.util
import math
import os
import time
from pathlib import Path

import numpy as np
from numba import cuda, int64, uint32

from . import kernels as K

__all__ = ["cuda_available", "require_cuda", "class_tables", "chroma_windows", "class_moments_cpu", "moments_from_sums",
           "GpuClassifier", "measure_rates", "bench_params", "THREADS", "ROWS_PER_BLOCK", "FRAME_BLOCKS",
           "MAX_MARKERS", "class_sums_kernel",
           "NVVM_WHEEL"]

#: Threads per block (a power of two, for the tree reduction), laid across a chroma row. Measured on an
#: H100 (720x576, 3 markers, batches of 256 frames in GPU memory, frames/s): 128 threads 589k, 256
#: threads 727k, 512 threads 755k (32 rows a block); the pass is bound by each thread's serial work,
#: not by memory (900k frames/s read 190 GB/s of the card's 3 TB/s), so more threads a block help.
THREADS = 512
#: Chroma rows per block. Each block first loads its markers' tables (8 kB each, from the L2 cache)
#: into shared memory, so the more rows a block reads the less that load weighs: on the H100, 512
#: threads read 755k frames/s with 32 rows, 849k with 64 and 908k with 144 (half a 720x576 frame).
ROWS_PER_BLOCK = 144
#: Most blocks along the frames; a block takes frames f, f + FRAME_BLOCKS, ... of a batch. Fewer
#: blocks than frames load the tables less often but run fewer blocks at once, which cost more on the
#: H100 (512 threads, 144 rows: 908k frames/s with a block a frame, 711k with 128, 494k with 64 for
#: 256 frames), so by default every frame has its own block.
FRAME_BLOCKS = 1 << 16
#: Markers one pass can classify (their tables share the block's shared memory: 8 kB each).
MAX_MARKERS = 4
#: 32-bit words of one marker's class table (65 536 bits).
TABLE_WORDS = 2048
_SHARED_TABLE_WORDS = MAX_MARKERS * TABLE_WORDS  # a shared array's size must be one compile-time constant


def _nvvm_from_wheel() -> str | None:
    """Point numba at NVIDIA's pip wheel of NVVM (``nvidia-cuda-nvcc-cu12``, in the ``gpu`` extra).

    Only when no toolkit is named (``CUDA_HOME``, ``CUDA_PATH``) and the
    wheel is installed; numba reads the variable when it first compiles.
    Returns the folder used, or None.
    """
    if os.environ.get("CUDA_HOME") or os.environ.get("CUDA_PATH"):
        return None
    try:
        spec = importlib.util.find_spec("nvidia")
    except (ImportError, ValueError):
        return None
    if spec is None:
        return None
    for base in spec.submodule_search_locations or []:
        home = Path(base) / "cuda_nvcc"
        if (home / "nvvm" / "libdevice").is_dir():
            os.environ["CUDA_HOME"] = str(home)
            return str(home)
    return None


NVVM_WHEEL = _nvvm_from_wheel()


def cuda_available() -> bool:
    """Whether numba can run CUDA kernels here (a GPU, or the simulator)."""
    try:
        return bool(cuda.is_available())
    except Exception:  # noqa: BLE001 - any failure means no
        return False


def require_cuda() -> None:
    """Raise :class:`~servoscope.errors.ServoscopeError` unless numba can run CUDA kernels here."""
    if not cuda_available():
        from ..errors import ServoscopeError

        raise ServoscopeError("backend 'cuda': no CUDA GPU found by numba (set NUMBA_ENABLE_CUDASIM=1 to simulate)")


def class_tables(params: np.ndarray) -> np.ndarray:
    """Bit-packed class tables, (markers, 2048) uint32.

    Bit ``(u·256 + v) mod 32`` of word ``(u·256 + v) // 32`` of row k is set
    when the CPU classifier (the one :func:`class_moments_cpu` uses) puts
    chroma (U, V) = (u, v) in marker k's class.
    """
    u, v = np.meshgrid(np.arange(256.0), np.arange(256.0), indexing="ij")
    rows = []
    for prm in np.atleast_2d(params):
        member = K.classify_np(prm, u, v).ravel()  # index u·256 + v
        rows.append(np.packbits(member, bitorder="little").view("<u4"))
    return np.ascontiguousarray(np.array(rows, dtype=np.uint32))


def chroma_windows(params: np.ndarray, height: int, width: int) -> np.ndarray:
    """Each marker's window in chroma samples, (markers, 4) int64: i0, i1, j0, j1 (half-open)."""
    return np.array([K.chroma_window(prm, 0, 1, height // 2, width // 2) for prm in np.atleast_2d(params)],
                    dtype=np.int64).reshape(-1, 4)


def class_moments_cpu(i420: np.ndarray, params: np.ndarray) -> np.ndarray:
    """CPU reference: (frames, markers, 3) class sums m00, m10, m01 (luma pixels; whole frames)."""
    b, rows, w = i420.shape
    h = rows * 2 // 3
    out = np.zeros((b, params.shape[0], 3))
    for f in range(b):
        chroma = i420[f, h:].reshape(2, h // 2, w // 2)
        for k in range(params.shape[0]):
            prm = params[k]
            i0, i1, j0, j1 = K.chroma_window(prm, 0, 1, h // 2, w // 2)
            cls = K.classify_np(prm, chroma[0, j0:j1, i0:i1].astype(np.float64),
                                 chroma[1, j0:j1, i0:i1].astype(np.float64))
            jj, ii = np.nonzero(cls)
            out[f, k, 0] = 4.0 * cls.sum()
            out[f, k, 1] = 4.0 * (2.0 * (ii + i0) + 0.5).sum()
            out[f, k, 2] = 4.0 * (2.0 * (jj + j0) + 0.5).sum()
    return out


def moments_from_sums(sums: np.ndarray) -> np.ndarray:
    """m00, m10, m01 in luma pixels from the kernel's integer sums (count, Σi, Σj of chroma samples).

    A chroma sample (i, j) covers 2×2 luma pixels centred on (2i + 0.5, 2j + 0.5).
    """
    n = sums[..., 0].astype(np.float64)
    out = np.empty(sums.shape, dtype=np.float64)
    out[..., 0] = 4.0 * n
    out[..., 1] = 8.0 * sums[..., 1] + 2.0 * n
    out[..., 2] = 8.0 * sums[..., 2] + 2.0 * n
    return out


@functools.lru_cache(maxsize=None)
def class_sums_kernel(threads: int = THREADS, rows_per_block: int = ROWS_PER_BLOCK):
    """The pass's CUDA kernel for a launch shape (``threads`` a power of two); compiled on first launch.

    The shape is baked in as constants (a shared array's size must be one), so each shape is its own
    kernel, made once. Arguments: ``(chroma, frames, hc, wc, n_markers, tables, windows, box, out)``;
    launch with ``threads`` threads a block and a grid of (any number ≤ frames, strips of
    ``rows_per_block`` rows of ``box``).
    """
    if threads < 1 or threads & (threads - 1):
        raise ValueError(f"threads must be a power of two, not {threads}")

    # `cuda` must be this module's global for the simulator.
    @cuda.jit
    def kernel(chroma, frames, hc, wc, n_markers, tables, windows, box, out):
        t = cuda.threadIdx.x
        table = cuda.shared.array(_SHARED_TABLE_WORDS, uint32)
        red = cuda.shared.array((3, threads), int64)
        # The tables are loaded once a block and serve every frame the block takes: with a block a frame,
        # loading 3 markers' 24 kB took a third of the block's time at 720x576 (measured on an H100).
        idx = t
        while idx < n_markers * TABLE_WORDS:
            table[idx] = tables[idx // TABLE_WORDS, idx % TABLE_WORDS]
            idx += threads
        win = cuda.local.array((MAX_MARKERS, 4), int64)
        acc = cuda.local.array((MAX_MARKERS, 3), int64)
        for k in range(n_markers):
            for q in range(4):
                win[k, q] = windows[k, q]
        cuda.syncthreads()
        j_start = box[2] + cuda.blockIdx.y * rows_per_block
        j_stop = j_start + rows_per_block
        if j_stop > box[3]:  # not min(): numba's CUDA min() is a device function that needs a driver to compile
            j_stop = box[3]
        v_plane = hc * wc
        f = cuda.blockIdx.x
        while f < frames:  # the same on every thread of the block, so the syncthreads below are safe
            for k in range(n_markers):
                for q in range(3):
                    acc[k, q] = 0
            for j in range(j_start, j_stop):
                row = j * wc
                i = box[0] + t
                while i < box[1]:
                    uv = (int64(chroma[f, row + i]) << 8) | int64(chroma[f, v_plane + row + i])
                    for k in range(n_markers):
                        if win[k, 0] <= i < win[k, 1] and win[k, 2] <= j < win[k, 3]:
                            if (table[k * TABLE_WORDS + (uv >> 5)] >> (uv & 31)) & 1:
                                acc[k, 0] += 1
                                acc[k, 1] += i
                                acc[k, 2] += j
                    i += threads
            for k in range(n_markers):
                for q in range(3):
                    red[q, t] = acc[k, q]
                cuda.syncthreads()
                step = threads // 2
                while step > 0:
                    if t < step:
                        for q in range(3):
                            red[q, t] += red[q, t + step]
                    cuda.syncthreads()
                    step //= 2
                if t == 0 and red[0, 0] > 0:
                    for q in range(3):
                        cuda.atomic.add(out, (f, k, q), red[q, 0])
                cuda.syncthreads()
            f += cuda.gridDim.x

    return kernel


def _union_box(windows: np.ndarray) -> np.ndarray:
    live = windows[(windows[:, 1] > windows[:, 0]) & (windows[:, 3] > windows[:, 2])]
    if not len(live):
        return np.zeros(4, dtype=np.int64)
    return np.array([live[:, 0].min(), live[:, 1].max(), live[:, 2].min(), live[:, 3].max()], dtype=np.int64)


class GpuClassifier:
    """Class moments of batches of frames on the GPU (see the module doc).

    Parameters
    ----------
    params : ndarray, shape (markers, K.NP)
        The markers' kernel rows (colour test and window), as the CPU kernel's.
    height, width : int
        Frame size in luma pixels (even).
    threads, rows_per_block, frame_blocks : int, optional
        The launch shape (threads a block, a power of two; chroma rows a block; most blocks along
        the frames). Default: the module's :data:`THREADS`, :data:`ROWS_PER_BLOCK` and
        :data:`FRAME_BLOCKS`, the shape measured fastest on an H100.
    """

    def __init__(self, params: np.ndarray, height: int, width: int, *, threads: int | None = None,
                 rows_per_block: int | None = None, frame_blocks: int | None = None) -> None:
        require_cuda()
        # None: the module's THREADS, ROWS_PER_BLOCK and FRAME_BLOCKS as they are now (read at each construction).
        threads = THREADS if threads is None else threads
        rows_per_block = ROWS_PER_BLOCK if rows_per_block is None else rows_per_block
        frame_blocks = FRAME_BLOCKS if frame_blocks is None else frame_blocks
        self._kernel = class_sums_kernel(int(threads), int(rows_per_block))
        self.threads, self.rows_per_block, self.frame_blocks = int(threads), int(rows_per_block), int(frame_blocks)
        params = np.atleast_2d(np.asarray(params, dtype=np.float64))
        if not 1 <= params.shape[0] <= MAX_MARKERS:
            raise ValueError(f"1 to {MAX_MARKERS} markers per pass, not {params.shape[0]}")
        if height % 2 or width % 2:
            raise ValueError(f"frame size {width}x{height} must be even")
        self.height, self.width = int(height), int(width)
        self.hc, self.wc = self.height // 2, self.width // 2
        self.n_markers = params.shape[0]
        windows = chroma_windows(params, self.height, self.width)
        self.box = _union_box(windows)
        self._tables = cuda.to_device(class_tables(params))
        self._windows = cuda.to_device(windows)
        self._box = cuda.to_device(self.box)

    @property
    def chroma_bytes(self) -> int:
        """Bytes of one frame's chroma (U then V): what goes to the GPU per frame."""
        return 2 * self.hc * self.wc

    def chroma_of(self, i420: np.ndarray) -> np.ndarray:
        """(frames, chroma_bytes) uint8: the chroma planes of (frames, h·3/2, w) yuv420p frames."""
        i420 = np.asarray(i420, dtype=np.uint8)
        return np.ascontiguousarray(i420[:, self.height:, :]).reshape(i420.shape[0], self.chroma_bytes)

    def launch(self, d_chroma, d_sums, frames: int, stream=0) -> None:
        """Queue the pass over ``frames`` frames of device chroma into zeroed device sums (frames, markers, 3)."""
        strips = max(1, -(-int(self.box[3] - self.box[2]) // self.rows_per_block))
        if frames and self.box[1] > self.box[0] and self.box[3] > self.box[2]:
            grid = (min(int(frames), self.frame_blocks), strips)
            self._kernel[grid, self.threads, stream](d_chroma, int(frames), self.hc, self.wc, self.n_markers,
                                                     self._tables, self._windows, self._box, d_sums)

    def class_sums(self, chroma: np.ndarray) -> np.ndarray:
        """(frames, markers, 3) int64: class count, Σi, Σj (chroma samples) of each marker in each frame."""
        chroma = np.ascontiguousarray(chroma, dtype=np.uint8)
        if chroma.shape[0] == 0:  # no device allocation of zero bytes
            return np.zeros((0, self.n_markers, 3), dtype=np.int64)
        d_sums = cuda.to_device(np.zeros((chroma.shape[0], self.n_markers, 3), dtype=np.int64))
        self.launch(cuda.to_device(chroma), d_sums, chroma.shape[0])
        return d_sums.copy_to_host()

    def class_moments(self, i420: np.ndarray) -> np.ndarray:
        """(frames, markers, 3): m00, m10, m01 of each marker's chroma class, as :func:`class_moments_cpu`."""
        return moments_from_sums(self.class_sums(self.chroma_of(i420)))


def measure_rates(classifier: GpuClassifier, chroma: np.ndarray, batch: int = 256,
                  resident_passes: int = 20) -> dict:
    """Frames/s of the GPU pass: on frames already in GPU memory, and on frames streamed from host memory.

    Parameters
    ----------
    classifier : GpuClassifier
    chroma : ndarray, shape (frames, chroma_bytes), uint8
        Frames in host memory (e.g. decoded footage), chroma only.
    batch : int
        Frames per launch and per host-to-device copy.
    resident_passes : int
        Passes over one resident batch for the in-memory rate.

    Returns
    -------
    dict
        ``resident_fps`` (frames in GPU memory), ``host_fps`` (from
        page-locked host memory, copied and reduced on two streams so that
        one batch's copy overlaps the other's kernel), ``copy_fps`` (the same
        copies without the kernel: the host-to-device copy rate, the bound
        for ``host_fps``), ``host_over_copy``, ``bytes_per_frame``,
        ``batch``, and ``sums`` (frames, markers, 3): the streamed run's
        integer sums of every frame, to check against the CPU.
    """
    n, nbytes = chroma.shape
    batch = max(1, min(batch, n))
    shape = (classifier.n_markers, 3)
    d_batch = cuda.to_device(np.ascontiguousarray(chroma[:batch]))
    d_sums = cuda.to_device(np.zeros((batch,) + shape, dtype=np.int64))
    classifier.launch(d_batch, d_sums, batch)  # compile before timing
    cuda.synchronize()
    start = time.perf_counter()
    for _ in range(resident_passes):
        classifier.launch(d_batch, d_sums, batch)
    cuda.synchronize()
    resident = batch * resident_passes / (time.perf_counter() - start)

    chroma = np.ascontiguousarray(chroma, dtype=np.uint8)
    streams = [cuda.stream(), cuda.stream()]
    sums_host = [cuda.pinned_array((batch,) + shape, dtype=np.int64) for _ in streams]
    zeros = cuda.pinned_array((batch,) + shape, dtype=np.int64)
    zeros[:] = 0
    d_in = [cuda.device_array((batch, nbytes), dtype=np.uint8) for _ in streams]
    d_out = [cuda.to_device(zeros) for _ in streams]
    sums = np.zeros((n,) + shape, dtype=np.int64)

    def stream_all(with_kernel: bool) -> float:
        pending: list[tuple[int, int] | None] = [None, None]  # each slot's batch whose sums are on their way

        def collect(s: int) -> None:  # once slot s's stream is idle
            if pending[s] is not None:
                lo, m = pending[s]
                sums[lo:lo + m] = sums_host[s][:m]
                pending[s] = None

        cuda.synchronize()
        start = time.perf_counter()
        for b, lo in enumerate(range(0, n, batch)):
            s = b % 2
            m = min(batch, n - lo)
            streams[s].synchronize()  # this slot's previous batch is done with its buffers
            collect(s)
            d_in[s][:m].copy_to_device(chroma[lo:lo + m], stream=streams[s])
            if with_kernel:
                d_out[s].copy_to_device(zeros, stream=streams[s])
                classifier.launch(d_in[s], d_out[s], m, stream=streams[s])
                d_out[s].copy_to_host(sums_host[s], stream=streams[s])
                pending[s] = (lo, m)
        cuda.synchronize()
        for s in range(len(streams)):
            collect(s)
        return n / (time.perf_counter() - start)

    # The frames' host memory is page-locked for the copies (as a decoder writing into pinned buffers
    # would hand them over), so that copies are asynchronous and the copy rate is the link's.
    with cuda.pinned(chroma):
        copy_fps = stream_all(False)
        host_fps = stream_all(True)
    return {"resident_fps": resident, "host_fps": host_fps, "copy_fps": copy_fps,
            "host_over_copy": host_fps / copy_fps, "bytes_per_frame": int(nbytes), "batch": batch, "sums": sums}


def bench_params(settings, width: int = 1 << 20, height: int = 1 << 20) -> np.ndarray:
    """Kernel rows for the settings' lead and trail seed colours over the whole frame (±15° hue)."""
    from .colour import parse_colour, ycbcr_bt601

    rows = []
    for spec in (settings.lead, settings.trail):
        y, u, v = ycbcr_bt601(parse_colour(spec))
        sat = math.hypot(u - 128.0, v - 128.0)
        prm = np.zeros(K.NP)
        prm[K.P.X0:K.P.Y1 + 1] = (0, 0, width, height)
        prm[K.P.DIR_U], prm[K.P.DIR_V] = (u - 128.0) / sat, (v - 128.0) / sat
        prm[K.P.COS_TOL] = math.cos(math.radians(15.0))
        prm[K.P.SAT_MIN] = 0.45 * sat
        prm[K.P.ENABLED] = 1.0
        rows.append(prm)
    return np.array(rows)
