"""servoscope.results: the one JSON/array/pandas/HTML helper every result object uses."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from servoscope.results import html_rows, html_table, import_pandas, jsonable, readonly
from servoscope.sysid import fit_sine


def test_jsonable_round_trips_through_json():
    value = {
        1: np.float32(0.5),
        "arr": np.array([[1.0, np.nan], [np.inf, -2.0]]),
        "ints": (np.int64(3), 4, np.uint8(7)),
        "flags": [np.bool_(True), False],
        "path": Path("/tmp/x.json"),
        "nested": {"none": None, "neg_inf": -np.inf, "s": "text"},
    }
    out = jsonable(value)
    expected = {
        "1": 0.5,
        "arr": [[1.0, None], [None, -2.0]],
        "ints": [3, 4, 7],
        "flags": [True, False],
        "path": "/tmp/x.json",
        "nested": {"none": None, "neg_inf": None, "s": "text"},
    }
    assert out == expected
    # The exact plain types, not NumPy's (json would refuse np.int64 and np.bool_).
    assert type(out["ints"][0]) is int and type(out["flags"][0]) is bool
    assert type(out["arr"][0][0]) is float
    # json.dumps with allow_nan=False accepts it, and loads gives the same back.
    assert json.loads(json.dumps(out, allow_nan=False)) == expected


def test_jsonable_keeps_bools_bools_and_finite_floats_exact():
    assert jsonable(np.bool_(False)) is False
    assert jsonable(True) is True
    x = 0.1 + 0.2
    assert jsonable(np.float64(x)) == x  # no rounding
    assert jsonable(float("nan")) is None


def test_readonly_is_a_float_copy_that_refuses_writes():
    src = [1, 2, 3]
    arr = readonly(src)
    assert arr.dtype == np.float64
    np.testing.assert_array_equal(arr, [1.0, 2.0, 3.0])
    with pytest.raises(ValueError):
        arr[0] = 5.0
    base = np.array([1.0, 2.0])
    ro = readonly(base)
    base[0] = 9.0  # a copy: the caller's array stays theirs
    assert ro[0] == 1.0


def test_html_table_has_a_row_per_key_in_order():
    out = html_table({"a": 1, "b": None, "c": [1, 2]}, "Thing")
    assert out == (
        "<table><caption>Thing</caption><tr><td>a</td><td>1</td></tr>"
        "<tr><td>b</td><td>None</td></tr><tr><td>c</td><td>[1, 2]</td></tr></table>"
    )


def test_html_rows_has_a_header_and_a_row_per_item():
    out = html_rows(("a", "b"), [[1, "x"], (2.5, None)], caption="Cap")
    assert out == (
        "<table><caption>Cap</caption><tr><th>a</th><th>b</th></tr>"
        "<tr><td>1</td><td>x</td></tr><tr><td>2.5</td><td>None</td></tr></table>"
    )
    assert html_rows(["c"], []) == "<table><tr><th>c</th></tr></table>"


def test_a_result_summary_round_trips_through_json():
    t = np.arange(0.0, 2.0, 1 / 240)
    y = 0.3 + 0.2 * np.sin(2 * math.pi * 3.0 * t + 0.4)
    fit = fit_sine(t, y, 3.0)
    s = fit.summary()
    assert json.loads(json.dumps(s, allow_nan=False)) == s
    assert s["amplitude"] == pytest.approx(0.2, rel=1e-9)
    assert fit._repr_html_() == html_table(s, "SineFit")


def test_import_pandas_gives_pandas():
    import pandas as pd  # a test dependency (pyproject's test extra)

    assert import_pandas() is pd


def test_to_pandas_without_pandas_says_how_to_install_it(monkeypatch):
    t = np.arange(0.0, 2.0, 1 / 240)
    fit = fit_sine(t, np.sin(2 * math.pi * 3.0 * t), 3.0)
    monkeypatch.setitem(sys.modules, "pandas", None)  # `import pandas` raises ImportError
    with pytest.raises(ImportError, match="pip install pandas"):
        fit.to_pandas()
