"""The monochrome engine's per-frame shortcuts give what the general code gives, to the bit.

The LED search's candidates measured in one compiled call on the native samples
(:meth:`~servoscope.markers.led_search.LedSearch.measure_native`, packed 12-bit
read in place) against NumPy's masks of the same disks on the unpacked samples;
the duplicate-frame check started from any row.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from servoscope.markers.led_search import LedCandidate, LedSearch
from servoscope.markers.mono_engine import _same_samples
from servoscope.markers.moments import Moments
from servoscope.video.native import iter_native_frames
from servoscope.video.sequence_writer import MrawWriter


def _search() -> LedSearch:
    # One inside, one across the right edge (a part of its disk off the picture), one off it (NaN).
    return LedSearch([LedCandidate(30.3, 20.7, 4.2, np.array([0.4, -0.3])),
                      LedCandidate(78.6, 40.1, 3.0, np.array([1.2, 0.25])),
                      LedCandidate(-40.0, 10.0, 2.0, np.array([-3.0, 0.0]))], 0, None)


def _numpy_disk(image, cx, cy, r):
    """The oracle: NumPy's mask of the disk, its mean (exact for integer samples) and maximum; NaN off the picture."""
    yy, xx = np.mgrid[0:image.shape[0], 0:image.shape[1]]
    inside = (xx - cx) ** 2 + (yy - cy) ** 2 <= r * r
    if not inside.any():
        return math.nan, math.nan
    px = image[inside].astype(np.float64)
    return float(px.mean()), float(px.max())


def _numpy_measure(search, image, lead, trail):
    """Each candidate's disks by :func:`_numpy_disk`, placed as LedSearch.find placed them (Python floats)."""
    for c in search.candidates:
        r = 1.5 * c.radius_px + 1.0
        level, peak = _numpy_disk(image, c.x_px, c.y_px, r)
        c.fixed.append(level)
        c.peak_fixed.append(peak)
        if lead is None or trail is None:
            c.borne.append(math.nan)
            continue
        ox, oy = trail.x_px, trail.y_px
        ax, ay = lead.x_px - ox, lead.y_px - oy
        length = math.hypot(ax, ay)
        ex, ey = ax / length, ay / length
        u, v = float(c.local[0]), float(c.local[1])
        level, peak = _numpy_disk(image, ox + length * (u * ex - v * ey), oy + length * (u * ey + v * ex), r)
        c.borne.append(level)
        c.peak_borne.append(peak)


@pytest.mark.parametrize("word_bits, bits", [(8, 8), (12, 12), (16, 12)])
def test_led_candidates_in_one_call_are_measure_to_the_bit(tmp_path, word_bits, bits):
    rng = np.random.default_rng(11)
    with MrawWriter(tmp_path, 80, 48, 100, word_bits) as w:
        for _ in range(3):
            w.write_gray(rng.integers(0, 2**bits, (48, 80)).astype(np.uint8 if bits == 8 else np.uint16), bits)
    lead, trail = Moments(120.0, 60.2, 22.9, 4.0, 0.1, 3.5), Moments(118.0, 14.6, 27.3, 3.9, -0.2, 3.6)
    markers = [(lead, trail), (None, trail), (lead, trail)]
    general, native = _search(), _search()
    for f, (a, b) in zip(iter_native_frames(w.cih), markers):
        _numpy_measure(general, f.gray, a, b)
        native.measure_native(f.samples, f.packed, f.width, a, b)
    for g, n in zip(general.candidates, native.candidates):
        for name in ("fixed", "borne", "peak_fixed", "peak_borne"):
            x, y = getattr(g, name), getattr(n, name)
            assert len(x) == len(y) and all(u == v or (math.isnan(u) and math.isnan(v)) for u, v in zip(x, y)), name
    # measure() on a 2-D image is the same call: the same levels on the unpacked samples.
    again = _search()
    for f, (a, b) in zip(iter_native_frames(w.cih), markers):
        again.measure(f.gray, a, b)
    for c, n in zip(again.candidates, native.candidates):
        for name in ("fixed", "borne", "peak_fixed", "peak_borne"):
            np.testing.assert_array_equal(getattr(c, name), getattr(n, name))
    assert math.isnan(native.candidates[2].fixed[0]) and not math.isnan(native.candidates[1].fixed[0])
    assert math.isnan(native.candidates[0].borne[1])  # a marker missing: not carried


def test_duplicate_check_is_the_same_from_any_row():
    rng = np.random.default_rng(2)
    a = rng.integers(0, 4096, (16, 24)).astype(np.uint16)
    b = a.copy()
    for start in (0, 5, 15):
        assert _same_samples(a, b, start)
    b[3, 7] += 1
    for start in (0, 5, 15):
        assert not _same_samples(a, b, start)
    assert not _same_samples(a, a[:8], 0)
