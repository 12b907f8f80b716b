"""Marker colour strings against matplotlib's parser (the oracle for hex and CSS names)."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from matplotlib import colors as mcolors

from servoscope.errors import ServoscopeError
from servoscope.markers.colour import parse_colour


@settings(max_examples=300, deadline=None)
@given(st.integers(0, 0xFFFFFF), st.booleans())
def test_hex_matches_matplotlib(value, upper):
    text = f"#{value:06x}"
    text = text.upper() if upper else text
    expected = tuple(c * 255.0 for c in mcolors.to_rgb(text))
    assert parse_colour(text) == pytest.approx(expected, abs=1e-9)


@pytest.mark.parametrize("name", ["red", "orchid", "DarkOrange", " gold "])
def test_css_names(name):
    expected = tuple(c * 255.0 for c in mcolors.to_rgb(mcolors.CSS4_COLORS[name.strip().lower()]))
    assert parse_colour(name) == pytest.approx(expected)


@pytest.mark.parametrize("bad", ["#12345", "#1234567", "#gg0000", "reddish", "", "#"])
def test_not_a_colour(bad):
    with pytest.raises(ServoscopeError, match="is not a colour"):
        parse_colour(bad)
