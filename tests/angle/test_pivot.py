"""The blade's axis in the picture (servoscope.angle.pivot): found where it stands, its motion measured where it moves."""

from __future__ import annotations

import math

import numpy as np
import pytest

from servoscope.angle import pivot_motion


def _pair(theta, pivot, shift=None):
    """Two markers 150 and 450 px from ``pivot`` on a line turned by theta (y down); the pivot moved by ``shift``."""
    shift = np.zeros((theta.size, 2)) if shift is None else shift
    u = np.stack([np.cos(theta), -np.sin(theta)], axis=1)
    p = np.asarray(pivot, float) + shift
    return p + 150.0 * u, p - 300.0 * u


def test_a_fixed_axis_is_found_and_does_not_move():
    theta = 0.05 * np.sin(np.linspace(0, 6 * np.pi, 300))
    lead, trail = _pair(theta, (412.3, 288.8))
    pm = pivot_motion(lead, trail, np.ones(300, bool))
    np.testing.assert_allclose(pm.centre_xy_px, (412.3, 288.8), atol=1e-6)
    assert pm.rms_px < 1e-6 and not pm.moved()
    assert pm.swing_rad == pytest.approx(0.1, rel=1e-3)


def test_a_moving_axis_is_measured():
    rng = np.random.default_rng(3)
    theta = 0.05 * np.sin(np.linspace(0, 6 * np.pi, 300))
    shift = rng.normal(0.0, 0.5, (300, 2))  # a camera shaking by 0.5 px RMS per axis
    lead, trail = _pair(theta, (412.3, 288.8), shift)
    pm = pivot_motion(lead, trail, np.ones(300, bool))
    assert pm.rms_px == pytest.approx(math.sqrt(2) * 0.5, rel=0.1) and pm.moved()
    # Noise alone (0.01 px a centroid) stays far below the warning.
    noisy = pivot_motion(*(xy + rng.normal(0, 0.01, xy.shape) for xy in _pair(theta, (412.3, 288.8))), np.ones(300, bool))
    assert noisy.rms_px < 0.05 and not noisy.moved(0.01)


def test_a_pair_that_hardly_turns_says_nothing():
    theta = np.full(50, 0.01)
    assert pivot_motion(*_pair(theta, (400, 300)), np.ones(50, bool)) is None
