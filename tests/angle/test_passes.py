"""The pass estimator (servoscope.angle.passes) against OpenCV's projection of the stickers (an independent oracle)."""

import math

import cv2
import numpy as np
import pytest

from servoscope.angle import angle_rad_from_centroids
from servoscope.angle.passes import (PassTable, centre_column, crossing_time, fit_passes, foreshortening,
                                     rotor_speed)

D_M, R_M, F_PX, W, H = 0.62, 0.30, 1100.0, 320, 240
LEAD_M, TRAIL_M = 0.012, -0.020  # along the chord from the pitch axis: not symmetric on purpose
K_PINHOLE = (D_M + R_M) / (2 * (D_M - R_M))


def project(psi, theta):
    """Lead and trail sticker centres (px) by cv2.projectPoints: camera in the rotor plane at D, looking at the axis."""
    rot = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, -1.0], [-1.0, 0.0, 0.0]])  # image right = +y, down = −z
    rvec, _ = cv2.Rodrigues(rot)
    tvec = np.array([0.0, 0.0, D_M])
    K = np.array([[F_PX, 0, (W - 1) / 2], [0, F_PX, (H - 1) / 2], [0, 0, 1.0]])
    psi, theta = np.broadcast_arrays(np.atleast_1d(psi).astype(float), np.atleast_1d(theta).astype(float))
    er = np.stack([np.cos(psi), np.sin(psi), 0 * psi], -1)
    et = np.stack([-np.sin(psi), np.cos(psi), 0 * psi], -1)
    chord = np.cos(theta)[:, None] * et + np.sin(theta)[:, None] * np.array([0, 0, 1.0])
    out = []
    for a in (LEAD_M, TRAIL_M):
        pts = R_M * er + a * chord
        uv, _ = cv2.projectPoints(pts.reshape(-1, 1, 3), rvec, tvec, K, None)
        out.append(uv.reshape(-1, 2))
    return out


@pytest.mark.parametrize("psi_deg", [-8.0, -4.0, 2.0, 6.0, 9.0])
def test_foreshortening_undoes_the_projection(psi_deg):
    theta = math.radians(7.0)
    lead, trail = project(math.radians(psi_deg), theta)
    phi = angle_rad_from_centroids(lead, trail)[0]
    recovered = math.atan(math.tan(phi) / foreshortening(math.radians(psi_deg), K_PINHOLE))
    assert abs(math.degrees(recovered - theta)) < 2e-3
    # ...where the orthographic correction alone leaves a visible error.
    ortho = math.atan(math.tan(phi) / foreshortening(math.radians(psi_deg), 0.5))
    assert abs(math.degrees(ortho - theta)) > 5 * abs(math.degrees(recovered - theta))


def make_passes(rng, noise_px=0.02):
    rev = 20.0
    fps = 4000.0
    pitch = lambda t: math.radians(5.0) + 0.03 * np.sin(2 * np.pi * 7.0 * t)  # noqa: E731
    t_true = 0.01 + np.arange(8) / rev
    data, xm, sep, pid, truth = [], [], [], [], []
    for j, tc in enumerate(t_true):
        t = np.arange(math.ceil((tc - 0.0012) * fps), math.floor((tc + 0.0012) * fps)) / fps
        psi = 2 * np.pi * rev * (t - tc)
        lead, trail = project(psi, pitch(t))
        lead += rng.normal(0, noise_px, lead.shape)
        trail += rng.normal(0, noise_px, trail.shape)
        data.append((t, lead, trail))
        xm.append(0.5 * (lead[:, 0] + trail[:, 0]))
        sep.append(lead[:, 0] - trail[:, 0])
        pid.append(np.full(t.size, j))
        truth.append(tc)
    return rev, pitch, data, np.concatenate(xm), np.concatenate(sep), np.concatenate(pid), np.array(truth)


def test_pitch_at_psi_zero_recovered_from_projected_passes():
    rng = np.random.default_rng(3)
    rev, pitch, data, xm, sep, pid, t_true = make_passes(rng)
    xc, xc_err = centre_column(xm, sep, pid)
    assert math.isfinite(xc) and xc_err < 2.0
    tc = np.array([crossing_time(t, 0.5 * (l[:, 0] + tr[:, 0]), xc)[0] for t, l, tr in data])
    # The stickers' midpoint is not the pitch axis: ψ = 0 is read within a tenth of a millisecond.
    assert np.max(np.abs(tc - t_true)) < 1e-4
    speed, speed_err, revs = rotor_speed(tc, np.zeros(tc.size, int))
    assert abs(speed / rev - 1) < 1e-4
    assert list(revs) == list(range(8))
    fits, k, k_err = fit_passes([(t, angle_rad_from_centroids(l, tr)) for t, l, tr in data], tc, speed)
    assert abs(k - K_PINHOLE) < 3 * k_err + 0.2
    err = np.array([f.pitch_rad - pitch(f.time_s) for f in fits])
    assert np.degrees(np.sqrt(np.mean(err ** 2))) < 0.01
    z = err / np.array([f.pitch_stderr_rad for f in fits])
    assert np.sqrt(np.mean(z ** 2)) < 2.0
    # Without the correction (k = 0) the pitch reads high: the foreshortening is what was taken out.
    raw, _, _ = fit_passes([(t, angle_rad_from_centroids(l, tr)) for t, l, tr in data], tc, speed, k=0.0)
    raw_err = np.array([f.pitch_rad - pitch(f.time_s) for f in raw])
    assert np.mean(raw_err) > 3 * np.sqrt(np.mean(err ** 2))


def test_rotor_speed_with_drift_and_two_blades():
    # Ω(t) = 20·(1 + 0.002·t/0.5): the revolutions' count n(t) = ∫Ω; the passes where n + blade/2 is whole.
    t = np.linspace(0, 0.5, 200001)
    omega = 20.0 * (1 + 0.004 * t)
    n = np.concatenate([[0], np.cumsum(0.5 * (omega[1:] + omega[:-1]) * np.diff(t))])
    times, blades = [], []
    for b in (0, 1):
        for m in range(1, 9):
            times.append(np.interp(m - 0.5 * b, n, t))
            blades.append(b)
    speed, err, _ = rotor_speed(np.array(times), np.array(blades))
    span = (np.interp(max(times), t, n) - np.interp(min(times), t, n)) / (max(times) - min(times))
    assert abs(speed / span - 1) < 1e-4
    assert err > 0


def test_pass_table_round_trip():
    tab = PassTable("v.mp4", time_s=[0.01, 0.035], blade=[0, 1], pitch_rad=[0.08, 0.09],
                    pitch_stderr_rad=[1e-4, 2e-4], azimuth_from_rad=[-0.1, -0.09], azimuth_to_rad=[0.1, 0.11],
                    frames=[12, 13], rev_per_s=20.0, rev_per_s_stderr=0.001, t0_s=None,
                    centre_column_px=(150.0, 151.0), warnings=("w",))
    back = PassTable.from_summary(tab.summary())
    assert back.summary() == tab.summary()
    assert back.blade.dtype == np.int64 and list(back.frames) == [12, 13]
    df = tab.to_pandas()
    assert list(df["blade"]) == [0, 1] and "pitch_stderr_rad" in df
    assert "PassTable" in tab._repr_html_()


def test_midpoint_null_channel_measures_a_shared_error():
    # Each pass's two stickers carry a vertical error shared by its frames (σ each); the pitch's error is
    # then √2·σ/L, and the midpoint's height, which otherwise moves with the pitch alone, tells it.
    from servoscope.angle.passes import midpoint_variance_rad2

    rng = np.random.default_rng(11)
    sigma_px, sep_px, n = 0.02, 68.0, 400
    pitch = np.radians(5.0) + 0.02 * rng.standard_normal(n)
    e_lead, e_trail = rng.normal(0, sigma_px, n), rng.normal(0, sigma_px, n)
    measured_pitch = pitch + (e_trail - e_lead) / sep_px
    height = 120.0 - 20.0 * np.sin(pitch) + 0.5 * (e_lead + e_trail)
    var, dof = midpoint_variance_rad2(measured_pitch, height, sep_px)
    assert dof == n - 2
    truth = 2 * sigma_px ** 2 / sep_px ** 2
    assert abs(var / truth - 1) < 0.2
    assert midpoint_variance_rad2(measured_pitch[:4], height[:4], sep_px) == (math.nan, 0) or \
        math.isnan(midpoint_variance_rad2(measured_pitch[:4], height[:4], sep_px)[0])


def test_short_passes_against_the_projection():
    # Passes of 2-3 frames (25 rev/s at 2,000 frames/s) projected by OpenCV: each pass's pitch at ψ = 0 from its
    # few frames, the rate shrunk towards the passes' pooled slope, against the true pitch at t_c.
    from servoscope.angle.pass_short import fit_short_pass, pitch_rate_spread_rad_s, pooled_slope_rad_s

    rng = np.random.default_rng(7)
    rev, fps, noise_px = 25.0, 2000.0, 0.005
    pitch = lambda t: math.radians(5.0) + 0.03 * np.sin(2 * np.pi * 9.0 * t)  # noqa: E731
    t_true = 0.01 + np.arange(40) / (2 * rev)
    data = []
    for j, tc in enumerate(t_true):
        t = np.arange(math.ceil((tc - 0.0007 + 0.0002 * (j % 3)) * fps), math.floor((tc + 0.0007) * fps) + 1) / fps
        lead, trail = project(2 * np.pi * rev * (t - tc), pitch(t))
        lead += rng.normal(0, noise_px, lead.shape)
        trail += rng.normal(0, noise_px, trail.shape)
        data.append((t, angle_rad_from_centroids(lead, trail)))
    assert {t.size for t, _ in data} <= {2, 3} and min(t.size for t, _ in data) == 2
    prior, prior_var = pooled_slope_rad_s(data, t_true, rev, K_PINHOLE)
    held = [fit_short_pass(t, a, tc, rev, K_PINHOLE) for (t, a), tc in zip(data, t_true)]
    spread = pitch_rate_spread_rad_s(t_true, np.array([f.pitch_rad for f in held]), np.zeros(40, int))
    lead0, trail0 = project(0.0, math.radians(5.0))
    frame_var = 2 * (noise_px / float(np.hypot(*(lead0 - trail0)[0]))) ** 2  # one frame's angle noise (rad²)
    fits = [fit_short_pass(t, a, tc, rev, K_PINHOLE, rate_spread_rad_s=spread, frame_variance_rad2=frame_var,
                           rate_prior_rad_s=prior, rate_prior_var=prior_var) for (t, a), tc in zip(data, t_true)]
    err = np.array([f.pitch_rad - pitch(f.time_s) for f in fits])
    held_err = np.array([f.pitch_rad - pitch(f.time_s) for f in held])
    # The rate from the frames' own slope takes out what holding it at 0 leaves: 0.0029° against 0.0103°.
    assert np.sqrt(np.mean(err ** 2)) < 0.5 * np.sqrt(np.mean(held_err ** 2))
    own = np.array([f.pitch_stderr_rad for f in fits])  # the rate's part alone (the frames' is the caller's)
    total = np.sqrt(own ** 2 + frame_var / np.array([f.frames_used for f in fits]))
    assert 0.5 < np.sqrt(np.mean((err / total) ** 2)) < 1.5  # measured 0.95
