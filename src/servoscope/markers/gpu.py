"""The paper's GPU reduction: classify pixels by colour, block-reduce their moments, per frame.

A batch of frames goes to the GPU at once, as their chroma planes only (U
then V of each frame, PyAV's yuv420p order): the class test needs nothing
else, and chroma is a third of a 4:2:0 frame's bytes. One fused pass reads
every chroma sample once for all markers (lead, trail, LED, ...):

* **classify** by one table of the 65 536 (U, V) pairs with a bit a marker
  (:func:`packed_class_table`: 1, 2 or 4 bits an entry, 8 to 32 kB), made on
  the host by the CPU classifier itself (:func:`class_tables`) and held in
  shared memory: one read classifies a sample for every marker. The GPU
  therefore classifies every sample exactly as the CPU does, whatever the
  colour model;
* **reduce** each marker's m00, m10, m01 (in integers: the class count and
  the sums of the samples' column and row indices) within a block, a tree
  in shared memory as in the paper, then one atomic add per block into the
  frame's totals. Integer sums do not depend on the order of the additions,
  so the results equal the CPU's bit for bit (:func:`class_moments_cpu`),
  on any GPU and in any launch configuration.

Chroma is read as 32-bit words of 4 samples (rows padded to whole words where
the chroma width is not a multiple of 4: :meth:`GpuClassifier.chroma_of`).
Blocks run over (frames, strip of chroma rows); a block's ``THREADS`` threads
take the strip's words in row-major turn, so that a warp reads consecutive
words and no thread idles on a narrow row. The kernel is made per number of
markers, so that their sums and windows live in registers.

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
from numba import cuda, int32, int64, uint32

from . import kernels as K

__all__ = ["cuda_available", "require_cuda", "class_tables", "packed_class_table", "table_bits", "as_words",
           "chroma_windows", "class_moments_cpu", "moments_from_sums",
           "GpuClassifier", "measure_rates", "bench_params", "THREADS", "ROWS_PER_BLOCK", "FRAME_BLOCKS",
           "MAX_MARKERS", "class_sums_kernel", "kernel_signature",
           "NVVM_WHEEL"]

#: Threads per block (a power of two, for the tree reduction). Measured on an H100 (session 13; 720x576,
#: the bench's 2 markers, batches of 256 frames in GPU memory, frames/s, benchmarks/gpu_launch_shapes.py):
#: 256 threads 1.98-2.19M, 512 threads 2.12-2.23M, 1024 threads 1.70-2.21M over 72, 144 and 288 rows a
#: block. The kernel's registers a thread (48-56 for 1-2 markers, 66 for 3, 76 for 4; no local memory) allow
#: 1024 threads a block for 1-2 markers, 896 for 3 and 768 for 4: a larger block is refused (ValueError).
THREADS = 512
#: Chroma rows per block. Each block first loads the class table (8-32 kB, from the L2 cache) into
#: shared memory, so the more rows a block reads the less that load weighs: on the H100, 512 threads
#: read 2.12M frames/s with 72 rows, 2.19M with 144 and 2.23M with 288 (a whole 720x576 frame; 4 markers:
#: 1.21M with 144, 1.31M with 288).
ROWS_PER_BLOCK = 288
#: Most blocks along the frames; a block takes frames f, f + FRAME_BLOCKS, ... of a batch. Fewer
#: blocks than frames load the table less often but run fewer blocks at once, which cost more on the
#: H100 (session 8's kernel, 512 threads, 144 rows: 908k frames/s with a block a frame, 711k with 128,
#: 494k with 64 for 256 frames), so by default every frame has its own block.
FRAME_BLOCKS = 1 << 16
#: Markers one pass can classify (a 4-bit entry of the packed table each).
MAX_MARKERS = 4
#: 32-bit words of one marker's class table (65 536 bits; :func:`class_tables`).
TABLE_WORDS = 2048
#: Static shared memory a block may hold (CUDA's limit without opting in to more): the table and the reduction's rows.
_SHARED_BYTES = 48 * 1024


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


def packed_class_table(params: np.ndarray) -> np.ndarray:
    """Every marker's class of each (U, V) pair in one table: (words,) uint32, what the pass holds in shared memory.

    Entry ``uv = u·256 + v`` has :func:`table_bits` bits (1, 2 or 4, the markers rounded up to a power of
    two): bit k is set when marker k's class holds (u, v), as in :func:`class_tables`. One shared-memory
    read then classifies a sample for every marker at once. Entry ``uv`` is bits
    ``(uv mod e)·b`` to ``(uv mod e)·b + b − 1`` of word ``uv // e``, with b bits an entry and e = 32 / b
    entries a word.
    """
    tables = class_tables(params)
    bits = table_bits(tables.shape[0])
    member = np.unpackbits(tables.view(np.uint8), bitorder="little").reshape(tables.shape[0], 65536)
    entry = np.zeros(65536, dtype=np.uint32)
    for k in range(tables.shape[0]):
        entry |= member[k].astype(np.uint32) << k
    per_word = 32 // bits
    shifts = (np.arange(per_word, dtype=np.uint32) * bits)
    return np.bitwise_or.reduce(entry.reshape(-1, per_word) << shifts, axis=1).astype(np.uint32)


def table_bits(n_markers: int) -> int:
    """Bits a (U, V) entry of :func:`packed_class_table` takes for ``n_markers`` markers: 1, 2 or 4."""
    if not 1 <= n_markers <= MAX_MARKERS:
        raise ValueError(f"1 to {MAX_MARKERS} markers per pass, not {n_markers}")
    return 1 if n_markers == 1 else 2 if n_markers == 2 else 4


def _slots_per_round(threads: int, n_markers: int) -> int:
    """Sums reduced at once: as many (threads,) int64 rows as fit in shared memory beside the table."""
    table_bytes = 65536 * table_bits(n_markers) // 8
    return max(1, min(3 * n_markers, (_SHARED_BYTES - table_bytes) // (8 * threads)))


@functools.lru_cache(maxsize=None)
def class_sums_kernel(threads: int = THREADS, rows_per_block: int = ROWS_PER_BLOCK, n_markers: int = 2):
    """The pass's CUDA kernel for a launch shape and a number of markers; compiled on first launch.

    ``threads`` (a power of two) and the markers are baked in as constants (a shared array's size must
    be one, and the markers' sums then live in registers: loops over them unroll), so each is its own
    kernel, made once. Arguments: ``(chroma, frames, hc, wq, table, windows, box, out)``: chroma as
    32-bit words (4 samples each; rows of ``wq`` words, the V plane after the U plane), the
    :func:`packed_class_table`, windows and box in chroma samples, zeroed sums ``(frames, markers, 3)``.
    Launch with ``threads`` threads a block and a grid of (any number ≤ frames, strips of
    ``rows_per_block`` rows of ``box``).

    Long because the kernel is one function: a call to a ``cuda.jit`` device function is compiled
    for the current device, so it needs a GPU driver, and the kernel must compile to PTX without
    one (the tests do, with NVIDIA's NVVM wheel).
    """
    if threads < 1 or threads & (threads - 1):
        raise ValueError(f"threads must be a power of two, not {threads}")
    nm = int(n_markers)
    bits = table_bits(nm)
    word_shift = {1: 5, 2: 4, 4: 3}[bits]  # log2 of the entries a word holds
    entry_mask, class_mask, table_words = (1 << word_shift) - 1, (1 << bits) - 1, 65536 * bits // 32
    slots = 3 * nm
    per_round = _slots_per_round(threads, nm)

    # `cuda` must be this module's global for the simulator. Index arithmetic is in 32 bits (frames of up
    # to 2^31 samples); the sums are in 64.
    @cuda.jit
    def kernel(chroma, frames, hc, wq, table, windows, box, out):
        t = cuda.threadIdx.x
        shared_table = cuda.shared.array(table_words, uint32)
        red = cuda.shared.array((per_round, threads), int64)
        # The table is loaded once a block and serves every frame the block takes: with a block a frame,
        # loading 3 markers' 24 kB took a third of the block's time at 720x576 (measured on an H100).
        idx = t
        while idx < table_words:
            shared_table[idx] = table[idx]
            idx += threads
        win = cuda.local.array((nm, 4), int32)
        acc = cuda.local.array(slots, int64)
        for k in range(nm):
            for q in range(4):
                win[k, q] = int32(windows[k, q])
        cuda.syncthreads()
        j_start = int32(box[2]) + int32(cuda.blockIdx.y) * int32(rows_per_block)
        j_stop = j_start + int32(rows_per_block)
        if j_stop > box[3]:  # not min(): numba's CUDA min() is a device function that needs a driver to compile
            j_stop = int32(box[3])
        # The strip's words, row-major: a thread takes word t, t + threads, ... of rows x columns, so that
        # every thread works however narrow the box (a row at a time left most threads idle on 720x576),
        # and a warp reads consecutive words. Row and column advance without a division per word.
        q0 = int32(box[0]) >> 2
        nq = ((int32(box[1]) + 3) >> 2) - q0
        rows = j_stop - j_start
        dr = int32(threads) // nq
        dc = int32(threads) - dr * nq
        v_plane = int32(hc) * int32(wq)
        f = cuda.blockIdx.x
        while f < frames:  # the same on every thread of the block, so the syncthreads below are safe
            for s in range(slots):
                acc[s] = 0
            r = int32(t) // nq
            c = int32(t) - r * nq
            while r < rows:
                j = j_start + r
                q = q0 + c
                word = j * int32(wq) + q
                uw = chroma[f, word]
                vw = chroma[f, v_plane + word]
                for b in range(4):
                    i = (q << 2) + b
                    uv = (((uw >> (8 * b)) & 255) << 8) | ((vw >> (8 * b)) & 255)
                    member = (shared_table[uv >> word_shift] >> ((uv & entry_mask) * bits)) & class_mask
                    for k in range(nm):
                        if (member >> k) & 1:
                            if win[k, 0] <= i < win[k, 1] and win[k, 2] <= j < win[k, 3]:
                                acc[3 * k] += 1
                                acc[3 * k + 1] += i
                                acc[3 * k + 2] += j
                c += dc
                r += dr
                if c >= nq:
                    c -= nq
                    r += 1
            # Tree reduction in shared memory, as many sums a round as fit beside the table.
            s0 = 0
            while s0 < slots:
                for p in range(per_round):
                    if s0 + p < slots:
                        red[p, t] = acc[s0 + p]
                cuda.syncthreads()
                step = threads // 2
                while step > 0:
                    if t < step:
                        for p in range(per_round):
                            red[p, t] += red[p, t + step]
                    cuda.syncthreads()
                    step //= 2
                if t == 0:
                    for p in range(per_round):
                        s = s0 + p
                        if s < slots and red[p, 0] != 0:  # a zero sum adds nothing: no atomic for it
                            cuda.atomic.add(out, (f, s // 3, s % 3), red[p, 0])
                cuda.syncthreads()
                s0 += per_round
            f += cuda.gridDim.x

    return kernel


def kernel_signature() -> tuple:
    """The argument types :func:`class_sums_kernel`'s kernel is launched with, to compile it without a launch."""
    from numba import types

    def c_array(dtype, ndim):
        return types.Array(dtype, ndim, "C")

    return (c_array(types.uint32, 2), types.int64, types.int64, types.int64, c_array(types.uint32, 1),
            c_array(types.int64, 2), c_array(types.int64, 1), c_array(types.int64, 3))


def _check_block_fits(kernel, threads: int, n_markers: int) -> None:
    """Compile the kernel now (as its first launch would) and refuse a block larger than it can run.

    A kernel's registers a thread bound its threads a block: on an H100 the 4-marker pass does not launch
    with 1024 threads. CUDA's own launch error names arguments or registers without saying which; this
    says what to choose. numba's simulator has no registers and is not checked.
    """
    from numba import config

    if config.ENABLE_CUDASIM:
        return
    most = kernel.compile(kernel_signature()).max_threads_per_block
    if threads > most:
        raise ValueError(f"{threads} threads a block are more than this GPU runs the {n_markers}-marker pass "
                         f"with (at most {most}, for the kernel's registers): choose {1 << (most.bit_length() - 1)} "
                         f"or fewer")


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

    Notes
    -----
    The GPU reads chroma as 32-bit words of 4 samples, so each chroma row is laid out padded to a
    multiple of 4 samples (:attr:`row_words` words; no padding where the chroma width is a multiple
    of 4, as for every common frame size): use :meth:`chroma_of` or :meth:`chroma_from_planes` to lay
    frames out, and :attr:`chroma_bytes` for one frame's size.
    """

    def __init__(self, params: np.ndarray, height: int, width: int, *, threads: int | None = None,
                 rows_per_block: int | None = None, frame_blocks: int | None = None) -> None:
        require_cuda()
        # None: the module's THREADS, ROWS_PER_BLOCK and FRAME_BLOCKS as they are now (read at each construction).
        threads = THREADS if threads is None else threads
        rows_per_block = ROWS_PER_BLOCK if rows_per_block is None else rows_per_block
        frame_blocks = FRAME_BLOCKS if frame_blocks is None else frame_blocks
        params = np.atleast_2d(np.asarray(params, dtype=np.float64))
        if not 1 <= params.shape[0] <= MAX_MARKERS:
            raise ValueError(f"1 to {MAX_MARKERS} markers per pass, not {params.shape[0]}")
        if height % 2 or width % 2:
            raise ValueError(f"frame size {width}x{height} must be even")
        self.n_markers = params.shape[0]
        self._kernel = class_sums_kernel(int(threads), int(rows_per_block), self.n_markers)
        self.threads, self.rows_per_block, self.frame_blocks = int(threads), int(rows_per_block), int(frame_blocks)
        _check_block_fits(self._kernel, self.threads, self.n_markers)
        self.height, self.width = int(height), int(width)
        self.hc, self.wc = self.height // 2, self.width // 2
        #: 32-bit words of one chroma row on the GPU (4 samples each, the row padded to a whole word).
        self.row_words = -(-self.wc // 4)
        windows = chroma_windows(params, self.height, self.width)
        self.box = _union_box(windows)
        self._table = cuda.to_device(packed_class_table(params))
        self._windows = cuda.to_device(windows)
        self._box = cuda.to_device(self.box)

    @property
    def chroma_bytes(self) -> int:
        """Bytes of one frame's chroma on the GPU (U then V, rows padded to whole words): what goes per frame."""
        return 2 * self.hc * 4 * self.row_words

    def chroma_from_planes(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(chroma_bytes,) uint8: one frame's U and V planes (hc, wc each) laid out for the GPU."""
        return self._laid_out(np.stack((u, v))[None])[0]

    def chroma_of(self, i420: np.ndarray) -> np.ndarray:
        """(frames, chroma_bytes) uint8: the chroma planes of (frames, h·3/2, w) yuv420p frames, laid out for the GPU."""
        i420 = np.asarray(i420, dtype=np.uint8)
        return self._laid_out(i420[:, self.height:, :].reshape(i420.shape[0], 2, self.hc, self.wc))

    def _laid_out(self, planes: np.ndarray) -> np.ndarray:
        """(frames, chroma_bytes) uint8 from (frames, 2, hc, wc) planes: rows padded to whole words where needed."""
        if self.row_words * 4 == self.wc:
            return np.ascontiguousarray(planes, dtype=np.uint8).reshape(planes.shape[0], self.chroma_bytes)
        out = np.zeros(planes.shape[:3] + (4 * self.row_words,), dtype=np.uint8)
        out[..., :self.wc] = planes
        return out.reshape(planes.shape[0], self.chroma_bytes)

    def launch(self, d_chroma, d_sums, frames: int, stream=0) -> None:
        """Queue the pass over ``frames`` frames of device chroma into zeroed device sums (frames, markers, 3).

        ``d_chroma``: (frames, chroma_bytes // 4) uint32 on the device, :meth:`chroma_of`'s bytes as words.
        """
        strips = max(1, -(-int(self.box[3] - self.box[2]) // self.rows_per_block))
        if frames and self.box[1] > self.box[0] and self.box[3] > self.box[2]:
            grid = (min(int(frames), self.frame_blocks), strips)
            self._kernel[grid, self.threads, stream](d_chroma, int(frames), self.hc, self.row_words,
                                                     self._table, self._windows, self._box, d_sums)

    def class_sums(self, chroma: np.ndarray) -> np.ndarray:
        """(frames, markers, 3) int64: class count, Σi, Σj (chroma samples) of each marker in each frame.

        ``chroma``: (frames, chroma_bytes) uint8, as :meth:`chroma_of` lays it out.
        """
        words = as_words(chroma)
        if words.shape[0] == 0:  # no device allocation of zero bytes
            return np.zeros((0, self.n_markers, 3), dtype=np.int64)
        d_sums = cuda.to_device(np.zeros((words.shape[0], self.n_markers, 3), dtype=np.int64))
        self.launch(cuda.to_device(words), d_sums, words.shape[0])
        return d_sums.copy_to_host()

    def class_moments(self, i420: np.ndarray) -> np.ndarray:
        """(frames, markers, 3): m00, m10, m01 of each marker's chroma class, as :func:`class_moments_cpu`."""
        return moments_from_sums(self.class_sums(self.chroma_of(i420)))


def as_words(chroma: np.ndarray) -> np.ndarray:
    """(frames, bytes // 4) uint32: laid-out chroma (:meth:`GpuClassifier.chroma_of`) as the kernel's words, no copy."""
    chroma = np.ascontiguousarray(chroma, dtype=np.uint8)
    if chroma.ndim != 2 or chroma.shape[1] % 4:
        raise ValueError(f"chroma must be (frames, bytes) with whole 32-bit words a frame, not {chroma.shape}")
    return chroma.view("<u4")


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
    words = as_words(chroma)
    d_batch = cuda.to_device(words[:batch])
    d_sums = cuda.to_device(np.zeros((batch,) + shape, dtype=np.int64))
    classifier.launch(d_batch, d_sums, batch)  # compile before timing
    cuda.synchronize()
    start = time.perf_counter()
    for _ in range(resident_passes):
        classifier.launch(d_batch, d_sums, batch)
    cuda.synchronize()
    resident = batch * resident_passes / (time.perf_counter() - start)

    streams = [cuda.stream(), cuda.stream()]
    sums_host = [cuda.pinned_array((batch,) + shape, dtype=np.int64) for _ in streams]
    zeros = cuda.pinned_array((batch,) + shape, dtype=np.int64)
    zeros[:] = 0
    d_in = [cuda.device_array((batch, words.shape[1]), dtype=np.uint32) for _ in streams]
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
            d_in[s][:m].copy_to_device(words[lo:lo + m], stream=streams[s])
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
    with cuda.pinned(words):
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
