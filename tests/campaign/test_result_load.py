"""IdentificationResult.load: a result read back from its files is the result that wrote them."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from servoscope.campaign.result import IdentificationResult
from servoscope.errors import ServoscopeError


@pytest.fixture(scope="module")
def saved(quick_result, tmp_path_factory):
    out = tmp_path_factory.mktemp("saved")
    quick_result.write(out)
    return out


def _same(a, b, path=""):
    """Equal JSON values, floats to 1e-12 relative (the model is rebuilt from its parameters)."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and set(a) == set(b), (path, sorted(set(a) ^ set(b)))
        for k in a:
            _same(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            _same(x, y, f"{path}[{i}]")
    elif isinstance(a, float) and isinstance(b, float):
        assert math.isclose(a, b, rel_tol=1e-12, abs_tol=1e-15), (path, a, b)
    else:
        assert a == b, (path, a, b)


def test_summary_round_trips(quick_result, saved):
    loaded = IdentificationResult.load(saved / "result.json")
    _same(json.loads((saved / "result.json").read_text()), json.loads(json.dumps(loaded.summary())))
    # A folder is as good as its result.json.
    assert IdentificationResult.load(saved).summary()["model"]["params"] == loaded.summary()["model"]["params"]


def test_loaded_objects_work_like_the_originals(quick_result, saved):
    loaded = IdentificationResult.load(saved)
    # Tracks: every column the CSV holds, to the last bit.
    for label, track in quick_result.tracks.items():
        back = loaded.tracks[label]
        for name in ("time_s", "angle_rad", "angle_time_s", "lead_xy_px", "trail_xy_px", "led_level"):
            np.testing.assert_array_equal(getattr(back, name), getattr(track, name), err_msg=f"{label}.{name}")
        np.testing.assert_array_equal(back.valid, track.valid)
        assert back.t0_s == quick_result.summary()["tests"][list(quick_result.tracks).index(label)]["t0_s"]
    # The model: a working python-control transfer function, the same one.
    tf0, tf1 = quick_result.model.transfer_function, loaded.model.transfer_function
    np.testing.assert_allclose(tf1.num[0][0], tf0.num[0][0], rtol=1e-12)
    np.testing.assert_allclose(tf1.den[0][0], tf0.den[0][0], rtol=1e-12)
    w = np.logspace(0, 2, 7)
    np.testing.assert_allclose(loaded.model.frequency_response(w), quick_result.model.frequency_response(w), rtol=1e-12)
    np.testing.assert_allclose(loaded.model.covariance, quick_result.model.covariance, rtol=1e-12)
    # The frequency response and each dwell's fitted sine.
    np.testing.assert_array_equal(loaded.frequency_response.gain, quick_result.frequency_response.gain)
    for label, fit in quick_result.sine_fits.items():
        back = loaded.sine_fits[label]
        if fit.phase_rad is not None and fit.t0_s is not None:
            np.testing.assert_allclose(back.model(fit.time_s), fit.model(fit.time_s), rtol=1e-9, atol=1e-12)
        np.testing.assert_array_equal(back.y, fit.y)
    # The step's prediction curve is rebuilt from the model as the analysis built it.
    t = quick_result.step.time_s
    np.testing.assert_allclose(loaded.step.predicted(t), quick_result.step.predicted(t), rtol=1e-9, atol=1e-12)
    assert loaded.dead_time_s == pytest.approx(quick_result.dead_time_s, rel=1e-12)
    # And the Bode plot draws the same lines.
    import matplotlib

    matplotlib.use("Agg")
    a, b = quick_result.plot(), loaded.plot()
    for x, y in zip(a, b):
        if hasattr(x, "get_ydata"):
            np.testing.assert_allclose(y.get_ydata(), x.get_ydata(), rtol=1e-9)


def test_bad_files_are_one_clear_error(saved, tmp_path):
    with pytest.raises(ServoscopeError, match="no such result"):
        IdentificationResult.load(tmp_path / "nothing.json")
    bad = tmp_path / "result.json"
    bad.write_text("{not json")
    with pytest.raises(ServoscopeError, match="not a servoscope result.json"):
        IdentificationResult.load(bad)
    bad.write_text(json.dumps({"hello": 1}))
    with pytest.raises(ServoscopeError, match="not a servoscope result.json"):
        IdentificationResult.load(bad)
    bad.write_text((saved / "result.json").read_text())  # without its tracks/ folder
    with pytest.raises(ServoscopeError, match="tracks/ folder"):
        IdentificationResult.load(bad)
