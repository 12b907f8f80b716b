"""Rolling-shutter flicker bands: valid frames and angle errors, frame gain (before) against band gain (now).

Run:  .venv/bin/python benchmarks/flicker_bands.py [--size 640x480] [--codec h264] [--pivot-y 0.8]

Issue 29's footage in the twin: 240 frames/s, 2 ms exposure, a rolling shutter read out in
3.5 ms, lamps flickering at 100 or 120 Hz at several depths (each row integrates the lamps
over its own exposure: bands along the rows), two sine dwells (1 and 3 Hz). The blade's pivot
sits at ``--pivot-y`` of the height (0.8: the stickers in the lower bands, lit unlike the
frame's median; 0.5: the middle, where the frame's median is about right). Each video is
tracked twice: with the frame's gain for both markers (``BAND_GAIN = False``, the tracker
before issue 29) and with each marker's band gain. Prints, per depth and frequency, the
worst dwell's fraction of valid frames and the angle's mean and RMS error against the twin's
truth (degrees, valid frames); compare them with the steady (depth 0) row.
Deterministic (fixed seeds). ~1 min at 640×480 on 2 cores.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

import servoscope.markers.yuv_engine as yuv_engine
from servoscope.pipeline import TrackerSettings, track_video
from servoscope.simulate import simulate_campaign

FPS, EXPOSURE_S, READOUT_S = 240, 0.002, 0.0035
CASES = [(0.0, 100.0)] + [(d, f) for f in (100.0, 120.0) for d in (0.04, 0.08, 0.15)]


def render(out: Path, depth: float, hz: float, width: int, height: int, codec: str, pivot_y: float) -> dict:
    """The campaign's truth (rendered into ``out``)."""
    simulate_campaign(out, "quick", seed=1, include_step=False, fps=FPS, exposure_s=EXPOSURE_S, readout_s=READOUT_S,
                      flicker_hz=hz, flicker_depth=depth, width=width, height=height, codec=codec,
                      frequencies_hz=(1.0, 3.0), min_dwell_s=0.5, pivot_xy_px=(0.74 * width, pivot_y * height))
    return json.loads((out / "truth.json").read_text())


def measure(out: Path, truth: dict, band: bool) -> tuple[float, float, float]:
    """(worst dwell's valid fraction, mean error °, RMS error °) with the band gain or the frame's."""
    yuv_engine.BAND_GAIN = band
    fractions, errors = [], []
    for rec in truth["tests"]:
        tr = track_video(out / rec["video"], TrackerSettings(readout_s=READOUT_S))
        fractions.append(float(tr.valid.mean()))
        err = np.degrees(np.angle(np.exp(1j * (tr.angle_rad - np.asarray(rec["angle_rad"])))))
        errors.append(err[tr.valid])
    yuv_engine.BAND_GAIN = True
    err = np.concatenate(errors)
    return min(fractions), float(err.mean()), float(np.sqrt(np.mean(err**2)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="640x480")
    ap.add_argument("--codec", default="h264")
    ap.add_argument("--pivot-y", type=float, default=0.8)
    args = ap.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    print(f"{width}x{height} {args.codec}, {FPS} frames/s, exposure {EXPOSURE_S * 1e3:g} ms, readout "
          f"{READOUT_S * 1e3:g} ms, pivot at {args.pivot_y:g} of the height")
    print(f"{'lamps':>14} | {'valid (frame gain)':>18} {'mean':>8} {'rms':>7} | {'valid (band gain)':>17} "
          f"{'mean':>8} {'rms':>7}")
    with tempfile.TemporaryDirectory() as tmp:
        for depth, hz in CASES:
            out = Path(tmp) / f"{depth}_{hz}"
            truth = render(out, depth, hz, width, height, args.codec, args.pivot_y)
            old, new = measure(out, truth, False), measure(out, truth, True)
            name = "steady" if depth == 0 else f"{hz:g} Hz {100 * depth:g} %"
            print(f"{name:>14} | {100 * old[0]:17.1f}% {old[1]:+8.4f} {old[2]:7.4f} | {100 * new[0]:16.1f}% "
                  f"{new[1]:+8.4f} {new[2]:7.4f}")


if __name__ == "__main__":
    main()
