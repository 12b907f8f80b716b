"""One number, one answer (issue 30): the report, ``identify``'s table, the notebook view and result.json
state every headline parameter the same way, for a linear servo and for one with play.

The oracle for each view is the headline's own :class:`~servoscope.parameters.Parameter` as result.json
stores it (``model.parameters``): the same value, standard error and interval, written by the one
formatter (:meth:`Parameter.cells`) in every text.
"""

from __future__ import annotations

import html
import json
from pathlib import Path

import pytest

from servoscope.campaign.result import IdentificationResult
from servoscope.cli_tables import print_model
from servoscope.parameters import Parameter

# result.json's flat name for each parameter's standard error (the transfer function's, kept).
FLAT_STDERR = {"gain": "gain_stderr", "natural_frequency_rad_s": "natural_frequency_stderr_rad_s",
               "damping_ratio": "damping_ratio_stderr", "dead_time_s": "dead_time_stderr_s"}
STORED = Path(__file__).resolve().parents[1] / "data" / "result_before_issue30"


def _views(result: IdentificationResult, out: Path, capsys) -> tuple[dict, str, str, str]:
    data = json.loads((out / "result.json").read_text())
    report = html.unescape((out / "report.html").read_text())
    capsys.readouterr()
    print_model(result)
    table = capsys.readouterr().out
    notebook = html.unescape(result._repr_html_())
    return data, report, table, notebook


def _check_every_view(result: IdentificationResult, out: Path, capsys) -> list[str]:
    data, report, table, notebook = _views(result, out, capsys)
    head = result.headline
    model = data["model"]
    stored = model["parameters"]
    assert list(stored) == list(head.parameters)
    for name, entry in stored.items():
        p = Parameter.from_summary(name, entry)
        assert p == head.parameters[name]  # result.json holds the headline's parameter whole
        # result.json's older fields say the same.
        assert model[name] == p.value and model["ci95"][name] == list(p.ci95)
        flat = FLAT_STDERR.get(name)
        assert (model[flat] if flat in model else model["stderr"][name]) == p.stderr
        cells = [head.label(name) + p.held_text(), *p.cells()]
        row = "<td>" + "</td><td>".join(cells) + "</td>"
        assert row in report, (name, row)
        assert row in notebook, (name, row)
        # The terminal table may wrap a long label: the row's first line holds its start and every number.
        lines = [ln for ln in table.splitlines() if ln.startswith("│ " + cells[0][:14])]
        assert lines and all(c in lines[0] for c in cells[1:]), (name, cells, lines)
    # The headline's dead time is the one result.json states at the top level.
    if "dead_time_s" in stored:
        assert data["dead_time_s"] == stored["dead_time_s"]["value"]
    return list(stored)


def test_a_linear_servos_numbers_agree_everywhere(quick_result, tmp_path, capsys):
    from servoscope.report import write_report

    write_report(quick_result, tmp_path / "out")
    names = _check_every_view(quick_result, tmp_path / "out", capsys)
    assert names == ["gain", "natural_frequency_rad_s", "damping_ratio", "dead_time_s"]
    assert quick_result.headline.domain == "frequency domain"
    # The dead time stated first is the better of its two estimates, with the dwells' shared timing error.
    chosen = min((e for e in quick_result.dead_time_estimates.values() if e is not None), key=lambda e: e.stderr_s)
    assert quick_result.parameters["dead_time_s"].stderr == chosen.stderr_s


def test_a_servo_with_play_is_stated_by_its_selected_model_everywhere(backlash_identified, capsys):
    result, out, servo = backlash_identified
    names = _check_every_view(result, out, capsys)
    assert names == ["gain", "natural_frequency_rad_s", "damping_ratio", "dead_time_s", "backlash_rad"]
    p = result.parameters
    for name, true in (("gain", servo.gain), ("natural_frequency_rad_s", 37.0), ("backlash_rad", 0.004)):
        assert p[name].holds(true), (name, p[name], true)
        assert abs(p[name].value - true) < 0.03 * true
    # The transfer function fitted to the dwells is kept beside it, under its own name, and is not right.
    assert abs(result.model.gain - servo.gain) > 0.05 * servo.gain
    report = (out / "report.html").read_text()
    assert "a describing function" in report and "not its linear part" in report


def test_a_result_written_before_the_headline_still_loads():
    """result.json from before issue 30 (the backlash twin identified by that code): its `model` was the
    frequency-domain fit; loaded now, the fit is kept and the headline is the selected model."""
    data = json.loads((STORED / "result.json").read_text())
    assert "frequency_domain_model" not in data and "parameters" not in data["model"]
    old = IdentificationResult.load(STORED)
    assert old.model.gain == pytest.approx(data["model"]["gain"], rel=1e-12)
    assert old.servo_model.selected.structure == "backlash"
    assert old.headline.domain == "time domain"
    assert old.parameters["gain"].value == data["model"]["time_domain"]["candidates"][2]["gain"]
    # Written again, it is the new form and loads back to itself.
    summary = old.summary()
    assert summary["model"]["gain"] == old.parameters["gain"].value
    assert summary["frequency_domain_model"]["gain"] == pytest.approx(data["model"]["gain"], rel=1e-12)
