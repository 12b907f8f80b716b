"""How far lighting, white balance and codecs move a sticker's colour: the numbers behind MARKER_HUE_GATE.

Run:  .venv/bin/python benchmarks/marker_colour_gate.py [CASE ...] [--video FILE --lead C --trail C]

Renders the twin's blade (480×384, 200 frames/s, 40 frames, a 0.3 rad sine) under each case
(codec and bit rate, lamp flicker, camera shake, a white-balance cast as per-channel gains,
small stickers, sticker colours other than the defaults), decodes it as the tracker does, and
prints for every 3rd frame's best-scoring candidate of each marker the largest hue distance
from the colour asked (OpenCV units, 2° each: the candidates' ``hue_distance``,
servoscope/markers/selection.py), with that candidate's median colour. ``inf``: no candidate
at all (the colour left the tracker's ±12-unit band). With ``--video``: the first frame's
candidates of a real video for the colours given (e.g. OpenCV's vtest.avi, pedestrians).
Deterministic (fixed seeds).
"""

from __future__ import annotations

import argparse
import math
import tempfile
from pathlib import Path

import numpy as np

from servoscope.markers.colour import ColourModel, parse_colour
from servoscope.markers.selection import marker_candidates
from servoscope.simulate import Scene
from servoscope.simulate.render import FrameRenderer
from servoscope.video.reader import iter_yuv_frames
from servoscope.video.writer import VideoWriter

W, H, FPS, N = 480, 384, 200.0, 40
WARM, COOL, GREEN, MAGENTA = (1.15, 1.0, 0.85), (0.85, 1.0, 1.15), (0.9, 1.1, 0.9), (1.1, 0.9, 1.1)
OV, PO, BC = ("#ff7f0e", "#9467bd"), ("#e377c2", "#bcbd22"), ("#1f77b4", "#17becf")
CASES = {
    "h264 20M": {}, "h264 4M": {"bit_rate": 4_000_000}, "h264 1M": {"bit_rate": 1_000_000},
    "h264 0.3M": {"bit_rate": 300_000}, "hevc 20M": {"codec": "hevc"}, "hevc 2M": {"codec": "hevc", "bit_rate": 2_000_000},
    "hevc 0.3M": {"codec": "hevc", "bit_rate": 300_000}, "mpeg2 25M": {"codec": "mpeg2", "bit_rate": 25_000_000},
    "mpeg2 4M": {"codec": "mpeg2", "bit_rate": 4_000_000}, "mpeg2 1M": {"codec": "mpeg2", "bit_rate": 1_000_000},
    "raw": {"codec": "raw"}, "flicker 30%": {"flicker": 0.3}, "flicker 30% 4M": {"flicker": 0.3, "bit_rate": 4_000_000},
    "flicker 8% 1M": {"flicker": 0.08, "bit_rate": 1_000_000}, "shake 1px": {"shake": 1.0},
    "flicker 8% shake 1px 4M": {"flicker": 0.08, "shake": 1.0, "bit_rate": 4_000_000},
    "dim x0.4": {"wb": (0.4, 0.4, 0.4)}, "wb warm": {"wb": WARM}, "wb cool": {"wb": COOL},
    "wb green": {"wb": GREEN}, "wb magenta": {"wb": MAGENTA}, "wb cool 4M": {"wb": COOL, "bit_rate": 4_000_000},
    "10px 4M": {"diameter": 10, "bit_rate": 4_000_000}, "10px 1M": {"diameter": 10, "bit_rate": 1_000_000},
    "10px wb cool 4M": {"diameter": 10, "wb": COOL, "bit_rate": 4_000_000},
    "orange/violet": {"colours": OV}, "orange/violet wb warm 4M": {"colours": OV, "wb": WARM, "bit_rate": 4_000_000},
    "orange/violet wb cool 4M": {"colours": OV, "wb": COOL, "bit_rate": 4_000_000},
    "blue/cyan": {"colours": BC}, "pink/olive": {"colours": PO},
    "pink/olive wb warm 4M": {"colours": PO, "wb": WARM, "bit_rate": 4_000_000},
    "pink/olive wb cool 1M": {"colours": PO, "wb": COOL, "bit_rate": 1_000_000},
}


def render(path: Path, *, colours=("#d62728", "#2ca02c"), codec="h264", bit_rate=20_000_000, flicker=0.0,
           shake=0.0, wb=(1.0, 1.0, 1.0), diameter=None) -> Path:
    """One clip of the twin's blade under a case; returns its path."""
    kw = {"lead_colour": colours[0], "trail_colour": colours[1]}
    if diameter:
        kw["sticker_diameter_px"] = diameter
    scene = Scene.for_size(W, H, background_seed=1, **kw)
    t = np.arange(N) / FPS
    pitch = 0.3 * np.sin(2 * np.pi * 1.5 * t)
    renderer = FrameRenderer(scene, noise_sigma_dn=1.5, noise_seed=0)
    rng = np.random.default_rng(0)
    path = path.with_suffix({"h264": ".mp4", "hevc": ".mp4", "mpeg2": ".mpg", "raw": ".avi"}[codec])
    with VideoWriter(path, W, H, FPS, codec=codec, bit_rate=bit_rate) as writer:
        for i in range(N):
            gain = 1.0 + flicker * math.sin(2 * math.pi * 100.0 * t[i] + math.pi / 2)
            dxy = tuple(rng.normal(0.0, shake, 2)) if shake else (0.0, 0.0)
            f = renderer.render(float(pitch[i]), 1.0, i, gain, dxy).astype(np.float64) * np.array(wb)
            writer.write(np.clip(np.round(f), 0, 255).astype(np.uint8))
    return path


def worst_distance(path: Path, colours, step: int = 3) -> list[tuple[float, str]]:
    """Per marker: the largest hue distance of its best candidate over every ``step``-th frame, and its colour."""
    models = [ColourModel.from_seed(parse_colour(c)) for c in colours]
    worst = [(0.0, "")] * len(models)
    for k, frame in enumerate(iter_yuv_frames(path)):
        if k % step:
            continue
        for j, m in enumerate(models):
            cands = marker_candidates(frame.rgb, m, m.hue)
            best = max(cands, key=lambda c: c.score) if cands else None
            d = (best.hue_distance, best.colour_hex) if best else (math.inf, "")
            worst[j] = max(worst[j], d, key=lambda v: v[0])
    return worst


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("cases", nargs="*", help=f"cases (default all): {', '.join(CASES)}")
    ap.add_argument("--video", type=Path, help="a real video: list its first frame's candidates instead")
    ap.add_argument("--lead", default="#d62728")
    ap.add_argument("--trail", default="#2ca02c")
    args = ap.parse_args()
    if args.video:
        rgb = next(iter(iter_yuv_frames(args.video))).rgb
        for name, colour in (("lead", args.lead), ("trail", args.trail)):
            m = ColourModel.from_seed(parse_colour(colour))
            for c in marker_candidates(rgb, m, m.hue):
                print(f"{name} {colour}: {c.describe()}, hue distance {c.hue_distance:.2f}")
        return
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.cases or list(CASES):
            kw = dict(CASES[name])
            colours = kw.get("colours", ("#d62728", "#2ca02c"))
            path = render(Path(tmp) / f"clip{list(CASES).index(name)}", **kw)
            (dl, hl), (dt, ht) = worst_distance(path, colours)
            print(f"{name:28s} lead {colours[0]} {dl:5.2f} {hl:8s} trail {colours[1]} {dt:5.2f} {ht}", flush=True)


if __name__ == "__main__":
    main()
