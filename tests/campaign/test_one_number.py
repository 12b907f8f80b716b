"""One number, one answer (issue 30): the report, ``identify``'s table, the notebook view and result.json
state every headline parameter the same way (for a servo with play: tests/campaign/test_joint.py, whose
rendered campaign it shares).

The oracle for each view is the headline's own :class:`~servoscope.parameters.Parameter` as result.json
stores it (``model.parameters``): the same value, standard error and interval, written by the one
formatter (:meth:`Parameter.cells`) in every text.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from servoscope.campaign.result import IdentificationResult

from support import check_every_view

STORED = Path(__file__).resolve().parents[1] / "data" / "result_before_issue30"


def test_a_linear_servos_numbers_agree_everywhere(quick_result, tmp_path, capsys):
    from servoscope.report import write_report

    write_report(quick_result, tmp_path / "out")
    names = check_every_view(quick_result, tmp_path / "out", capsys)
    assert names == ["gain", "natural_frequency_rad_s", "damping_ratio", "dead_time_s"]
    assert quick_result.headline.domain == "frequency domain"
    # The dead time stated first is the better of its two estimates, with the dwells' shared timing error.
    chosen = min((e for e in quick_result.dead_time_estimates.values() if e is not None), key=lambda e: e.stderr_s)
    assert quick_result.parameters["dead_time_s"].stderr == chosen.stderr_s


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
