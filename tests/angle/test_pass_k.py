"""The foreshortening's k from short passes (angle/pass_k.py) and the midpoint's null channel read as the pitch is
(angle/pass_error.py), against synthetic passes drawn from the model with a known k, pitch and noise."""

import math

import numpy as np
import pytest

from servoscope.angle.pass_error import midpoint_heights_px
from servoscope.angle.pass_k import fit_k_mixed, fit_k_pooled, foreshortening

K_TRUE = 1.44
REV_PER_S = 30.0
FPS = 2000.0
LATE_S = 60e-6  # ψ = 0 read late, as on the twin: a slope common to every pass


def pitch(t):
    return math.radians(5.0) + 0.03 * np.sin(2 * np.pi * 11.0 * t)


def short_passes(seed, n_pass=24, sigma_rad=math.radians(0.005)):
    """Passes of 2-3 frames 0.5 ms apart about ψ = 0 at random phases; the image angle tan φ = tan θ(t)·F(ψ)."""
    rng = np.random.default_rng(seed)
    passes, t_c, blade = [], [], []
    for j in range(n_pass):
        tc = 0.01 + j / (2 * REV_PER_S)
        n = 2 + int(rng.random() < 0.4)
        t = tc + (rng.uniform(-0.5, 0.5) + np.arange(n) - (n - 1) / 2) / FPS
        psi = 2 * np.pi * REV_PER_S * (t - tc)
        phi = np.arctan(np.tan(pitch(t) + (j % 2) * math.radians(0.2)) * foreshortening(psi, K_TRUE))
        passes.append((t, phi + rng.normal(0.0, sigma_rad, n)))
        t_c.append(tc + LATE_S)
        blade.append(j % 2)
    return passes, np.array(t_c), np.array(blade)


def test_k_from_short_passes_weighs_each_by_what_it_tells():
    # The pitch's own rate through a 2-frame pass (up to 2 rad/s, 1e-3 rad a frame) is as large as the
    # foreshortening's curvature there: the pooled residual (each short pass's mean alone) reads k ±0.2;
    # weighed by what each pass tells, k within a few hundredths, its error honest over the seeds.
    errs, ses, pooled_ses = [], [], []
    for seed in range(6):
        passes, t_c, blade = short_passes(seed)
        k, se = fit_k_mixed(passes, t_c, REV_PER_S, blade)
        errs.append(k - K_TRUE)
        ses.append(se)
        pooled_ses.append(fit_k_pooled(passes, t_c, REV_PER_S)[1])
    errs, ses = np.array(errs), np.array(ses)
    assert np.all(np.abs(errs) < 0.15), errs
    assert np.all(ses < 0.1) and np.all(np.array(pooled_ses) > 2 * ses), (ses, pooled_ses)
    assert 0.4 < math.sqrt(np.mean((errs / ses) ** 2)) < 1.8, errs / ses


def test_long_passes_alone_keep_the_pooled_fit():
    rng = np.random.default_rng(1)
    passes, t_c = [], []
    for j in range(10):
        tc = 0.01 + j / 40.0
        t = tc + (np.arange(8) - 3.5 + rng.uniform(-0.5, 0.5)) / 4000.0
        psi = 2 * np.pi * 20.0 * (t - tc)
        phi = np.arctan(np.tan(pitch(t)) * foreshortening(psi, K_TRUE)) + rng.normal(0, 1e-4, t.size)
        passes.append((t, phi))
        t_c.append(tc)
    assert fit_k_mixed(passes, np.array(t_c), 20.0) == fit_k_pooled(passes, np.array(t_c), 20.0)


def test_a_short_pass_midpoint_height_is_carried_by_its_own_pitch_rate():
    # The midpoint sits off the pitch axis (B px/rad): within a pass it moves with the pitch's own rate.
    # Its height at ψ = 0, read the way the pitch is (the mean carried by the rate), has only the frames'
    # noise left; carried by the blade's pooled slope alone it carries B·rate·(t̄ − t_c) besides.
    rng = np.random.default_rng(3)
    B, y0, noise = 17.0, 120.0, 0.001
    taus, ys, p0, rates = [], [], [], []
    for j in range(30):
        tc = 0.01 + j / 30.0
        tau = (rng.uniform(-0.5, 0.5) + np.arange(2) - 0.5) / FPS
        rate = 0.03 * 2 * np.pi * 11.0 * math.cos(2 * np.pi * 11.0 * tc)
        th = pitch(tc) + rate * tau
        taus.append(tau)
        ys.append(y0 + B * th + 3.0 * tau + rng.normal(0, noise, tau.size))  # 3 px/s: the path's own slope
        p0.append(pitch(tc))
        rates.append(rate)
    heights, slope_b = midpoint_heights_px(taus, ys, np.array(p0), np.array(rates))
    truth = y0 + B * np.array(p0)
    assert abs(slope_b - B) < 0.5
    assert np.sqrt(np.mean((heights - truth) ** 2)) < 1.5 * noise / math.sqrt(2)
    pooled_only = np.array([y.mean() - 3.0 * t.mean() for t, y in zip(taus, ys)])
    assert np.sqrt(np.mean((pooled_only - truth) ** 2)) > 3 * noise  # what the null channel read before


@pytest.mark.parametrize("n_frames", [2, 3])
def test_foreshortening_is_flat_at_psi_zero(n_frames):
    psi = np.linspace(-0.1, 0.1, 2 * n_frames + 1)
    f = foreshortening(psi, K_TRUE)
    assert f[n_frames] == 1.0 and np.allclose(f, f[::-1])
