"""What several test folders share: paths, a tiny video, a manifest, the kernels' synthetic frame.

The suite mirrors ``src/servoscope/`` (one folder per stage, package-wide checks at the top);
``tests/`` is on ``sys.path`` (pytest puts the root conftest's folder there), so any test
imports these as ``from support import ...``.
"""

from __future__ import annotations

from pathlib import Path

import av
import numpy as np

from servoscope.markers import kernels as K
from servoscope.video.writer import rgb_to_yuv420p

#: The repository's root, its sources and the tests' own data.
ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src" / "servoscope"
DATA = Path(__file__).resolve().parent / "data"
#: The read-only shared folder beside the checkout (real calibration photos); absent in a clone elsewhere.
CHESSBOARD = (ROOT / ".." / "shared" / "data" / "opencv-chessboard").resolve()


def tiny_video(path: Path, frames: int = 3) -> Path:
    with av.open(str(path), "w") as out:
        stream = out.add_stream("mpeg4", rate=25)
        stream.width, stream.height, stream.pix_fmt = 64, 48, "yuv420p"
        for i in range(frames):
            img = np.full((48, 64, 3), 40 * i, np.uint8)
            for packet in stream.encode(av.VideoFrame.from_ndarray(img, format="rgb24")):
                out.mux(packet)
        for packet in stream.encode():
            out.mux(packet)
    return path


GOOD = """
[markers]
lead = "#d62728"
trail = "green"
led = "#ffd400"
[[tests]]
video = "a.mp4"
kind = "sine"
frequency_hz = 1.0
amplitude = 0.1
[[tests]]
video = "b.mp4"
label = "stepper"
kind = "step"
amplitude = 0.5
"""


def kernel_frame(seed: int = 0, h: int = 96, w: int = 128) -> np.ndarray:
    """A synthetic yuv420p frame: textured grey background, a red and a green disk (anti-aliased), noise."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w] + 0.5
    rgb = np.empty((h, w, 3))
    rgb[:] = (90.0, 95.0, 100.0)
    rgb[: h // 3] = (150.0, 170.0, 200.0)  # a "sky" band
    for (cx, cy, r, col) in ((85.3, 40.7, 9.0, (214, 39, 40)), (30.6, 52.2, 8.0, (44, 160, 44))):
        cov = np.clip(r + 0.5 - np.hypot(xx - cx, yy - cy), 0.0, 1.0)[..., None]
        rgb = cov * np.asarray(col, float) + (1 - cov) * rgb
    rgb += rng.normal(0, 1.5, rgb.shape)
    return rgb_to_yuv420p(np.clip(rgb, 0, 255).round().astype(np.uint8))


def kernel_params(i420: np.ndarray) -> np.ndarray:
    from servoscope.markers.colour import ycbcr_bt601 as _bt601

    rows = []
    for rgb, (x0, y0, x1, y1), r in (((214, 39, 40), (60, 15, 115, 70), 11.0), ((44, 160, 44), (5, 25, 60, 80), 10.0)):
        y, u, v = _bt601(rgb)
        sat = np.hypot(u - 128, v - 128)
        p = np.zeros(K.NP)
        p[[K.P.X0, K.P.Y0, K.P.X1, K.P.Y1]] = (x0, y0, x1, y1)
        p[[K.P.YM, K.P.UM, K.P.VM]] = (y, u, v)
        p[[K.P.DIR_U, K.P.DIR_V]] = ((u - 128) / sat, (v - 128) / sat)
        p[K.P.COS_TOL] = np.cos(np.radians(15))
        p[K.P.SAT_MIN] = 0.45 * sat
        p[K.P.AGREE] = 0.25
        p[K.P.RADIUS] = r
        p[K.P.RING] = 4.0
        p[K.P.W_Y] = 1.0
        p[K.P.ITER] = 2
        p[K.P.ENABLED] = 1
        p[K.P.VAR_Y] = p[K.P.VAR_C] = 2.25
        p[K.P.ALPHA_LO], p[K.P.ALPHA_HI] = 0.0, 1.0
        p[K.P.MIN_DEN] = 100.0
        rows.append(p)
    return np.array(rows)


def run_kernel(engine, i420, params, led, row_off=0, row_step=1):
    h = i420.shape[0] * 2 // 3
    y = i420[:h][row_off::row_step]
    u, v = i420[h:].reshape(2, h // 2, -1)
    out = np.zeros((params.shape[0], K.NQ))
    led_out = np.zeros(K.LED_NQ)
    K.track_frame(engine, y, u, v, row_off, row_step, params, led, out, led_out)
    return out, led_out
