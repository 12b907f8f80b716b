"""Property-based robustness: random but well-formed inputs give a result or a clear error, never a crash."""

from __future__ import annotations

import json
import math

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from servoscope.campaign import load_campaign
from servoscope.errors import ServoscopeError
from servoscope.sysid import FrequencyResponse, fit_second_order, fit_sine

scalars = st.one_of(
    st.integers(-10**6, 10**6),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=12),
    st.booleans(),
)
keys = st.sampled_from(["video", "kind", "frequency_hz", "amplitude", "t0_s", "label", "colour", "freq"])


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    return json.dumps(v)  # a JSON string is a TOML basic string


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    markers=st.dictionaries(st.sampled_from(["lead", "trail", "led", "lid"]), st.one_of(scalars, st.sampled_from(["red", "#00ff00", "auto"])), max_size=4),
    tests=st.lists(st.dictionaries(keys, st.one_of(scalars, st.sampled_from(["sine", "step", "a.mp4"])), max_size=6), max_size=4),
)
def test_manifest_parser_never_crashes(tmp_path, markers, tests):
    lines = ["[markers]"] + [f"{k} = {_toml_value(v)}" for k, v in markers.items()]
    for entry in tests:
        lines.append("[[tests]]")
        lines += [f"{k} = {_toml_value(v)}" for k, v in entry.items()]
    path = tmp_path / "campaign.toml"
    path.write_text("\n".join(lines) + "\n")
    try:
        campaign = load_campaign(path, check_videos=False)
    except ServoscopeError as exc:
        assert str(exc).startswith(str(path)) and "\n" not in str(exc)
    else:
        assert campaign.tests and all(t.kind in ("sine", "step") for t in campaign.tests)
        assert all(math.isfinite(t.amplitude) and t.amplitude != 0 for t in campaign.tests)


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(0, 400),
    f_hz=st.floats(0.05, 60.0),
    amp=st.floats(0.0, 1.0),
    noise=st.floats(0.0, 0.1),
    nan_share=st.floats(0.0, 1.0),
    seed=st.integers(0, 2**16),
)
def test_sine_fit_gives_finite_answers_or_a_clear_error(n, f_hz, amp, noise, nan_share, seed):
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 100.0
    y = amp * np.sin(2 * np.pi * f_hz * t) + noise * rng.standard_normal(n)
    y[rng.random(n) < nan_share] = np.nan
    try:
        fit = fit_sine(t, y, f_hz, t0_s=0.0, settle_s=0.0)
    except ServoscopeError as exc:
        assert "\n" not in str(exc)
        return
    assert math.isfinite(fit.amplitude) and fit.amplitude >= 0
    assert math.isfinite(fit.offset)
    assert fit.phase_rad is None or math.isfinite(fit.phase_rad)
    kept = int(np.count_nonzero(np.isfinite(y)))
    if kept >= 40 and kept / 100.0 * f_hz >= 2 and f_hz < 40 and amp > 20 * noise and amp > 1e-3:
        # A sine that the data show well (two periods of samples, well below Nyquist, clearly
        # above the noise) is measured within its stated uncertainty: amplitude and phase.
        assert abs(fit.amplitude - amp) <= 5 * fit.amplitude_stderr + 1e-6 * amp, (fit.amplitude, amp)
        if fit.phase_rad is not None:
            assert abs(math.remainder(fit.phase_rad, 2 * math.pi)) <= 5 * fit.phase_stderr_rad + 1e-6


@settings(max_examples=40, deadline=None)
@given(
    freqs=st.lists(st.floats(0.1, 50.0), min_size=0, max_size=10, unique=True),
    gains=st.lists(st.floats(1e-4, 10.0), min_size=10, max_size=10),
)
def test_transfer_function_fit_gives_a_model_or_a_clear_error(freqs, gains):
    f = np.sort(np.asarray(freqs, dtype=float))
    g = np.asarray(gains[: f.size], dtype=float)
    fr = FrequencyResponse(
        frequency_hz=f, gain=g, gain_stderr=0.01 * g, phase_deg=np.full(f.size, np.nan),
        phase_stderr_deg=np.full(f.size, np.nan), fidelity=np.ones(f.size), labels=tuple(f"d{i}" for i in range(f.size)),
    )
    try:
        fit = fit_second_order(fr)
    except ServoscopeError as exc:
        assert "\n" not in str(exc)
        return
    for value in (fit.gain, fit.natural_frequency_rad_s, fit.damping_ratio):
        assert math.isfinite(value) and value > 0
