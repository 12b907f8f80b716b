"""IdentificationResult: a data object below the runner and the report."""

from __future__ import annotations

import ast
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from servoscope.report import write_report  # noqa: E402

from support import SRC


def test_the_result_module_imports_no_later_stage():
    tree = ast.parse((SRC / "campaign" / "result.py").read_text(encoding="utf-8"))
    imported = {n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    assert not any("report" in m or "runner" in m for m in imported), imported


def test_write_is_the_data_and_write_report_adds_the_report(tmp_path, quick_result):
    data = quick_result.write(tmp_path / "data")
    assert set(data) == {"tracks", "frequency_response", "result"}
    assert not (tmp_path / "data" / "report.html").exists()
    full = write_report(quick_result, tmp_path / "full")
    assert list(full) == ["tracks", "frequency_response", "report", "figures", "result"]
    # The same data files, byte for byte, whichever writes them.
    for name in ("result.json", "frequency_response.csv", *(f"tracks/{k}.csv" for k in quick_result.tracks)):
        assert (tmp_path / "data" / name).read_bytes() == (tmp_path / "full" / name).read_bytes(), name
    assert json.loads(full["result"].read_text())["model"]["num"] == list(quick_result.model.num)
    assert "<html" in full["report"].read_text().lower() and (full["figures"] / "bode.png").exists()


def test_plot_draws_the_measured_gains_and_the_model(quick_result):
    fig, (ax, phase_ax) = plt.subplots(2, 1)
    try:
        artists = quick_result.plot(ax, phase_ax=phase_ax)
        fr = quick_result.frequency_response
        model_gain, model_phase = artists[-2], artists[-1]
        w = np.asarray(model_gain.get_xdata())
        np.testing.assert_allclose(model_gain.get_ydata(), 20 * np.log10(quick_result.model.magnitude(w)))
        assert model_phase.axes is phase_ax and model_gain.axes is ax
        # The measured points span the dwells' frequencies.
        assert w.min() < fr.omega_rad_s.min() and w.max() > fr.omega_rad_s.max()
    finally:
        plt.close(fig)


def test_repr_html_shows_every_parameter(quick_result):
    html = quick_result._repr_html_()
    assert html.startswith("<p>G(s) = ") and html.count("<tr>") == 1 + len(quick_result.model.param_names)
