"""The monochrome engine's pace against the RGB reference engine, a user's OpenCV script and reading the file.

Run:  .venv/bin/python benchmarks/mono_engine_speed.py [--frames 1500] [--size 1024 1024] [--dir /tmp/mono_speed]

Writes (once) a synthetic 12-bit packed Photron MRAW: a gray gradient, a dark
blade turning ±0.15 rad, two white dots on it, 4 DN of sensor noise; then, in
one process, twice (the machine is shared: compare ratios within a run):

* reading the file alone (its bytes, and its bytes unpacked to uint16 by
  servoscope's reader, as a whole-frame reader must);
* ``track_video`` with ``engine="mono"``, whole (start-up included) and from
  its second frame on (the first frame's detection is a one-off);
* a user's OpenCV script (threshold, contours, moments of each whole frame),
  reading the frames, and on frames already in memory;
* the RGB reference engine on the first 60 frames.

Prints frames/s, gigapixels/s and the ratios the issue's targets are about
(≥ 5× the OpenCV script, ≥ 50 % of reading the file, ≥ 1 Gpx/s). See also
``servoscope bench --mono`` (its own twin clip, LED and pins).
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import cv2
import numpy as np

from servoscope.pipeline import TrackerSettings, track_video
from servoscope.markers.frame_record import TrackLog
from servoscope.video.frame_source import parse_frame_source
from servoscope.video.highspeed import PhotronMraw
from servoscope.video.sequence_writer import MrawWriter


def write_clip(folder: Path, frames: int, width: int, height: int) -> Path:
    """The synthetic MRAW (its CIH's path), written unless already there."""
    cih = folder / "frames.cih"
    if cih.exists():
        return cih
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:height, 0:width]
    base = (1800 + 300 * (yy / height) + 100 * (xx / width)).astype(np.float32)
    noise = rng.standard_normal((8, height, width)).astype(np.float32) * 4.0  # recycled, shifted a column a frame
    cx, cy, half = width // 2, height // 2, 0.41 * width
    with MrawWriter(folder, width, height, 2000, 12) as w:
        for i in range(frames):
            a = 0.15 * math.sin(2 * math.pi * 20 * i / 2000)
            c, s = math.cos(a), math.sin(a)
            img = base.copy()
            blade = np.array([[-half, -18], [half, -18], [half, 18], [-half, 18]], np.float32)
            blade = blade @ np.array([[c, s], [-s, c]], np.float32) + (cx, cy)
            cv2.fillPoly(img, [np.round(blade * 16).astype(np.int32)], 700.0, cv2.LINE_AA, 4)
            for d in (-0.37 * width, 0.37 * width):
                centre = (int(round((cx + d * c) * 16)), int(round((cy + d * s) * 16)))
                cv2.circle(img, centre, 12 * 16, 3900.0, -1, cv2.LINE_AA, 4)
            img += np.roll(noise[i % 8], i, axis=1)
            w.write_gray(np.clip(np.rint(img), 0, 4095).astype(np.uint16), 12)
    return cih


def opencv_script(frames, threshold: float = 2900.0) -> list:
    """A user's first script: threshold, contours and moments of each whole frame."""
    out = []
    for img in frames:
        _, bw = cv2.threshold(img, threshold, 255, cv2.THRESH_BINARY)
        contours, _ = cv2.findContours(bw.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        ms = [cv2.moments(c) for c in contours]
        out.append([(m["m10"] / m["m00"], m["m01"] / m["m00"]) for m in ms if m["m00"] > 0])
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=1500)
    parser.add_argument("--size", type=int, nargs=2, default=(1024, 1024), metavar=("WIDTH", "HEIGHT"))
    parser.add_argument("--dir", type=Path, default=Path("/tmp/mono_speed"))
    args = parser.parse_args()
    w, h = args.size
    big = write_clip(args.dir / f"{w}x{h}_{args.frames}", args.frames, w, h)
    small = write_clip(args.dir / f"{w}x{h}_60", 60, w, h)
    src = PhotronMraw(parse_frame_source(big))
    n, px = src.header.frame_count, w * h
    settings = TrackerSettings(lead="bright", trail="bright", led=None)
    stamps: list[float] = []
    add = TrackLog.add

    def stamped(self, rec):
        add(self, rec)
        stamps.append(time.perf_counter())

    TrackLog.add = stamped

    def report(name: str, frames: int, seconds: float) -> float:
        print(f"{name:50s} {frames:5d} frames {seconds:7.2f} s {frames / seconds:8.0f} frames/s "
              f"{frames * px / seconds / 1e9:6.3f} Gpx/s", flush=True)
        return frames / seconds

    with open(src.mraw, "rb") as f:  # the page cache warm, the compiled kernels loaded
        while f.read(1 << 26):
            pass
    track_video(small, settings)
    for run in (1, 2):
        print(f"--- run {run}: {w}x{h} 12-bit packed MRAW, {n} frames")
        r = {}
        start, buf = time.perf_counter(), bytearray(src.frame_bytes)
        with open(src.mraw, "rb", buffering=0) as f:
            for _ in range(n):
                f.readinto(buf)
        r["read"] = report("read the file alone (bytes)", n, time.perf_counter() - start)
        start = time.perf_counter()
        for i in range(n):
            src.read(i)
        r["read+unpack"] = report("read the file alone (unpacked to uint16)", n, time.perf_counter() - start)
        stamps.clear()
        start = time.perf_counter()
        track = track_video(big, settings)
        r["mono"] = report(f"mono engine, whole (valid {track.n_valid}/{track.n_frames})", n,
                           time.perf_counter() - start)
        r["mono 2..N"] = report("mono engine, second frame on", n - 1, stamps[-1] - stamps[0])
        start = time.perf_counter()
        opencv_script(src.read(i) for i in range(n))
        r["opencv+read"] = report("OpenCV script, reading the frames", n, time.perf_counter() - start)
        held = min(n, int(4e8 // (2 * px)))
        frames = [src.read(i) for i in range(held)]
        start = time.perf_counter()
        opencv_script(frames)
        r["opencv"] = report("OpenCV script, frames in memory", held, time.perf_counter() - start)
        start = time.perf_counter()
        track = track_video(small, TrackerSettings(lead="bright", trail="bright", led=None, engine="reference-rgb"))
        r["rgb"] = report(f"reference-rgb (valid {track.n_valid}/{track.n_frames})", 60, time.perf_counter() - start)
        for key in ("mono", "mono 2..N"):
            print(f"{key}: ×{r[key] / r['opencv+read']:.1f} OpenCV reading, ×{r[key] / r['opencv']:.1f} OpenCV in "
                  f"memory, ×{r[key] / r['read']:.2f} reading the bytes, ×{r[key] / r['read+unpack']:.1f} reading "
                  f"unpacked, ×{r[key] / r['rgb']:.0f} reference-rgb")
    src.close()


if __name__ == "__main__":
    main()
