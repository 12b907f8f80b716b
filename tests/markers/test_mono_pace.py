"""The monochrome engine's per-frame shortcuts give what the general code gives, to the bit.

The LED search's candidates measured in one compiled call on the native samples
(:meth:`~servoscope.markers.led_search.LedSearch.measure_native`, packed 12-bit
read in place) against :meth:`~servoscope.markers.led_search.LedSearch.measure`
on the unpacked samples; the duplicate-frame check started from any row.
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
        general.measure(f.gray if f.packed else f.samples, a, b)
        native.measure_native(f.samples, f.packed, f.width, a, b)
    for g, n in zip(general.candidates, native.candidates):
        for name in ("fixed", "borne", "peak_fixed", "peak_borne"):
            x, y = getattr(g, name), getattr(n, name)
            assert len(x) == len(y) and all(u == v or (math.isnan(u) and math.isnan(v)) for u, v in zip(x, y)), name
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
