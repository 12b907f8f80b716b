"""Moments against independent oracles (OpenCV, scikit-image) and invariances."""

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from skimage.measure import moments as sk_moments

from servoscope.markers import weighted_moments


def _blob(seed: int, h: int = 40, w: int = 50) -> np.ndarray:
    rng = np.random.default_rng(seed)
    img = np.zeros((h, w))
    img[8:30, 10:37] = rng.uniform(0.2, 1.0, size=(22, 27))
    return img


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_matches_opencv_moments(seed):
    img = _blob(seed)
    m = weighted_moments(img)
    ref = cv2.moments(img.astype(np.float32), binaryImage=False)
    assert m.m00 == pytest.approx(ref["m00"], rel=1e-6)
    assert m.x_px == pytest.approx(ref["m10"] / ref["m00"], abs=1e-5)
    assert m.y_px == pytest.approx(ref["m01"] / ref["m00"], abs=1e-5)
    assert m.mu20 == pytest.approx(ref["mu20"] / ref["m00"], rel=1e-5)
    assert m.mu11 == pytest.approx(ref["mu11"] / ref["m00"], rel=1e-4, abs=1e-6)
    assert m.mu02 == pytest.approx(ref["mu02"] / ref["m00"], rel=1e-5)


def test_matches_skimage_moments_binary_mask():
    mask = np.zeros((30, 30))
    mask[5:17, 9:26] = 1.0
    m = weighted_moments(mask)
    ref = sk_moments(mask, order=1)  # skimage: M[i, j] = Σ row^i col^j I
    assert m.m00 == pytest.approx(ref[0, 0])
    assert m.y_px == pytest.approx(ref[1, 0] / ref[0, 0], abs=1e-12)
    assert m.x_px == pytest.approx(ref[0, 1] / ref[0, 0], abs=1e-12)


@settings(max_examples=30, deadline=None)
@given(dx=st.integers(0, 20), dy=st.integers(0, 15), ox=st.floats(-500, 500), oy=st.floats(-500, 500))
def test_translation_moves_centroid_only(dx, dy, ox, oy):
    img = _blob(7)
    big = np.zeros((80, 90))
    big[dy : dy + 40, dx : dx + 50] = img
    a = weighted_moments(img)
    b = weighted_moments(big, (ox, oy))
    assert b.x_px == pytest.approx(a.x_px + dx + ox, abs=1e-9)
    assert b.y_px == pytest.approx(a.y_px + dy + oy, abs=1e-9)
    assert b.mu20 == pytest.approx(a.mu20, rel=1e-9)
    assert b.mu02 == pytest.approx(a.mu02, rel=1e-9)


def test_empty_weight_gives_none():
    assert weighted_moments(np.zeros((5, 5))) is None
