"""Three blades, each its own colours, at 25 rev/s and 5000 frames/s (markers.passes, pipeline.rotor) against the twin."""

import math

import numpy as np
import pytest

from servoscope.markers.settings import TrackerSettings
from servoscope.pipeline.rotor import track_passes
from servoscope.simulate.rotor import ROTOR_BLADE_COLOURS, RotorRig
from servoscope.simulate.rotor_render import render_rotor_clip

EXPOSURE_S = 1 / 50000
OFFSETS = (0.0, math.radians(0.2), math.radians(-0.15))


def collective(t):
    return np.radians(7.0) + 0.035 * np.sin(2 * np.pi * 17.0 * np.asarray(t))


@pytest.fixture(scope="module")
def clip(tmp_path_factory):
    rig = RotorRig(blades=ROTOR_BLADE_COLOURS[:3], rev_per_s=25.0, blade_offsets_rad=OFFSETS, azimuth0_rad=2.5,
                   drift_fraction=0.003, cyclic_rad=0.0)
    path = tmp_path_factory.mktemp("rotor3") / "clip.mp4"
    truth = render_rotor_clip(path, rig, collective, duration_s=0.2, fps=5000, exposure_s=EXPOSURE_S, width=320,
                              height=240, led_off_s=0.05, noise_seed=4, background_seed=2)
    table = track_passes(path, TrackerSettings(exposure_s=EXPOSURE_S), rotor=ROTOR_BLADE_COLOURS[:3])
    return rig, truth, table


def test_three_blades_against_truth(clip):
    rig, truth, table = clip
    listed = [p for p in truth["passes"] if p["first_frame"] > 0 and p["last_frame"] < len(truth["time_s"]) - 1]
    assert len(table) == len(listed) >= 12
    assert table.blades == (0, 1, 2)
    for p in listed:
        j = int(np.argmin(np.abs(table.time_s - p["time_s"])))
        assert table.blade[j] == p["blade"] and abs(table.time_s[j] - p["time_s"]) < 1e-4
    err = table.pitch_rad - (collective(table.time_s) + np.array(OFFSETS)[table.blade])
    # Measured 0.0219° on this seed (0.0176–0.0254° over seeds 1–10; docs/rotor.md): blade 1's blue lead, its
    # height the colour kernel's, reads +0.018°, the other blades within ±0.006°.
    assert math.degrees(math.sqrt(np.mean(err ** 2))) < 0.03
    z = err / table.pitch_stderr_rad
    assert 0.6 < math.sqrt(np.mean(z ** 2)) < 1.6  # measured 1.31 (0.80–1.42 over seeds 1–10): blade 1's bias
    # The stated error is the pass-to-pass one (what a dwell's sine, with one offset a blade, sees): about each
    # blade's mean it holds (measured 1.29, 12 degrees of freedom); the blade's constant bias (frozen from pass
    # to pass) reads as a rigging offset, not an error here.
    zw = []
    for b in range(3):
        mine = table.blade == b
        n = int(mine.sum())
        zw.extend((err[mine] - err[mine].mean()) / table.pitch_stderr_rad[mine] * math.sqrt(n / (n - 1)))
    zw = np.array(zw)
    assert 0.6 < math.sqrt(np.mean(zw ** 2)) < 1.4
    t = table.time_s
    span = (rig.azimuth_rad(t.max(), 0) - rig.azimuth_rad(t.min(), 0)) / (2 * np.pi * (t.max() - t.min()))
    assert abs(table.rev_per_s / span - 1) < 1e-4
    assert abs(table.t0_s - truth["t0_s"]) < 5 * table.t0_uncertainty_s + 2e-6
