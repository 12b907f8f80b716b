"""The paper's GPU reduction: classify pixels by colour, block-reduce their moments, per frame.

A batch of frames (YUV 4:2:0, PyAV's (h·3/2, w) layout) goes to the GPU at
once; one CUDA block per (frame, marker) walks that marker's window of
chroma samples, classifies each by chroma (the same test as
:mod:`servoscope.markers.kernels`), and reduces m00, m10, m01 of the class
in shared memory (a tree reduction). The CPU reference
(:func:`class_moments_cpu`) gives the same sums.

Needs numba's CUDA support and a CUDA GPU, or numba's simulator
(``NUMBA_ENABLE_CUDASIM=1``, slow; the tests use it on small frames). Install
with the ``gpu`` extra (``pip install servoscope[gpu]``): numba already
brings ``numba.cuda``; a GPU needs only the NVIDIA driver and CUDA runtime.
"""

from __future__ import annotations

import math

import numpy as np
from numba import cuda, float64

from . import kernels as K

__all__ = ["cuda_available", "class_moments_cpu", "GpuClassifier", "bench_params", "THREADS"]

#: Threads per block (a power of two, for the tree reduction).
THREADS = 128


def cuda_available() -> bool:
    """Whether numba can run CUDA kernels here (a GPU, or the simulator)."""
    try:
        return bool(cuda.is_available())
    except Exception:  # noqa: BLE001 - any failure means no
        return False


def class_moments_cpu(i420: np.ndarray, params: np.ndarray) -> np.ndarray:
    """CPU reference: (frames, markers, 3) class sums m00, m10, m01 (luma pixels; whole frames)."""
    b, rows, w = i420.shape
    h = rows * 2 // 3
    out = np.zeros((b, params.shape[0], 3))
    for f in range(b):
        chroma = i420[f, h:].reshape(2, h // 2, w // 2)
        for k in range(params.shape[0]):
            prm = params[k]
            i0, i1, j0, j1 = K._chroma_window(prm, 0, 1, h // 2, w // 2)
            cls = K._classify_np(prm, chroma[0, j0:j1, i0:i1].astype(np.float64),
                                 chroma[1, j0:j1, i0:i1].astype(np.float64))
            jj, ii = np.nonzero(cls)
            out[f, k, 0] = 4.0 * cls.sum()
            out[f, k, 1] = 4.0 * (2.0 * (ii + i0) + 0.5).sum()
            out[f, k, 2] = 4.0 * (2.0 * (jj + j0) + 0.5).sum()
    return out


def _get_kernel():
    return _reduce_classes


if True:  # the kernel (compiled on first launch); `cuda` must be this module's global for the simulator

    @cuda.jit
    def _reduce_classes(frames, params, h, out):
        f = cuda.blockIdx.x
        k = cuda.blockIdx.y
        t = cuda.threadIdx.x
        s0 = cuda.shared.array(THREADS, float64)
        s1 = cuda.shared.array(THREADS, float64)
        s2 = cuda.shared.array(THREADS, float64)
        hc = h // 2
        wc = frames.shape[2] // 2
        i0 = max(0, int(params[k, 0]) // 2)
        i1 = min(wc, (int(params[k, 2]) + 1) // 2)
        j0 = max(0, int(params[k, 1]) // 2)
        j1 = min(hc, (int(params[k, 3]) - 1) // 2 + 1)
        ni = i1 - i0
        total = ni * (j1 - j0)
        a0 = 0.0
        a1 = 0.0
        a2 = 0.0
        idx = t
        while idx < total:
            j = j0 + idx // ni
            i = i0 + idx % ni
            # U then V follow the luma rows, each (h/2)·(w/2) samples, row-major.
            pos = j * wc + i
            u = float(frames[f, h + pos // frames.shape[2], pos % frames.shape[2]]) - 128.0
            pos2 = hc * wc + pos
            v = float(frames[f, h + pos2 // frames.shape[2], pos2 % frames.shape[2]]) - 128.0
            sat = math.sqrt(u * u + v * v)
            if sat >= params[k, 10] and (u * params[k, 7] + v * params[k, 8]) >= params[k, 9] * sat:
                a0 += 4.0
                a1 += 4.0 * (2.0 * i + 0.5)
                a2 += 4.0 * (2.0 * j + 0.5)
            idx += THREADS
        s0[t] = a0
        s1[t] = a1
        s2[t] = a2
        cuda.syncthreads()
        step = THREADS // 2
        while step > 0:
            if t < step:
                s0[t] += s0[t + step]
                s1[t] += s1[t + step]
                s2[t] += s2[t + step]
            cuda.syncthreads()
            step //= 2
        if t == 0:
            out[f, k, 0] = s0[0]
            out[f, k, 1] = s1[0]
            out[f, k, 2] = s2[0]


class GpuClassifier:
    """Class moments of batches of frames on the GPU (see the module doc)."""

    def __init__(self) -> None:
        if not cuda_available():
            from ..errors import ServoscopeError

            raise ServoscopeError("backend 'cuda': no CUDA GPU found by numba (set NUMBA_ENABLE_CUDASIM=1 to simulate)")
        self.kernel = _get_kernel()

    def class_moments(self, i420: np.ndarray, params: np.ndarray) -> np.ndarray:
        """(frames, markers, 3): m00, m10, m01 of each marker's chroma class in each frame."""
        i420 = np.ascontiguousarray(i420, dtype=np.uint8)
        b, rows, _ = i420.shape
        h = rows * 2 // 3
        d_frames = cuda.to_device(i420)
        d_params = cuda.to_device(np.ascontiguousarray(params, dtype=np.float64))
        d_out = cuda.device_array((b, params.shape[0], 3), dtype=np.float64)
        self.kernel[(b, params.shape[0]), THREADS](d_frames, d_params, h, d_out)
        return d_out.copy_to_host()


def bench_params(settings, width: int = 1 << 20, height: int = 1 << 20) -> np.ndarray:
    """Kernel rows for the settings' lead and trail seed colours over the whole frame (±15° hue)."""
    from .colour import parse_colour
    from .tracker import _bt601

    rows = []
    for spec in (settings.lead, settings.trail):
        y, u, v = _bt601(parse_colour(spec))
        sat = math.hypot(u - 128.0, v - 128.0)
        prm = np.zeros(K.NP)
        prm[K.P.X0:K.P.Y1 + 1] = (0, 0, width, height)
        prm[K.P.DIR_U], prm[K.P.DIR_V] = (u - 128.0) / sat, (v - 128.0) / sat
        prm[K.P.COS_TOL] = math.cos(math.radians(15.0))
        prm[K.P.SAT_MIN] = 0.45 * sat
        prm[K.P.ENABLED] = 1.0
        rows.append(prm)
    return np.array(rows)
