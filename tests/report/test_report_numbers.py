"""Values shown to the precision their uncertainty supports (GUM §7.2.6)."""

from __future__ import annotations

from decimal import Decimal

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from servoscope.numbers import format_interval, format_value, format_with_uncertainty


@pytest.mark.parametrize(
    "value, err, expected",
    [
        (0.229664, 0.000317651, ("0.22966", "0.00032")),
        (84.95158, 0.0171, ("84.952", "0.017")),
        (36.9184, 0.0533592, ("36.918", "0.053")),
        (-609.474, 0.241425, ("-609.47", "0.24")),
        (1234.6, 56.0, ("1235", "56")),
    ],
)
def test_examples(value, err, expected):
    assert format_with_uncertainty(value, err) == expected


@pytest.mark.parametrize("err", [None, 0.0, float("nan"), float("inf")])
def test_no_usable_uncertainty_falls_back(err):
    value_text, err_text = format_with_uncertainty(0.229664, err)
    assert value_text == "0.229664"
    assert err_text == format_value(err, 2)


@settings(max_examples=300, deadline=None)
@given(st.floats(-1e5, 1e5, allow_nan=False), st.floats(1e-8, 1e4, allow_nan=False))
def test_two_significant_digits_and_matching_decimals(value, err):
    value_text, err_text = format_with_uncertainty(value, err)
    err_decimals = len(err_text.split(".")[1]) if "." in err_text else 0
    value_decimals = len(value_text.split(".")[1]) if "." in value_text else 0
    assert value_decimals == err_decimals
    # Two significant digits of the uncertainty below 10 (above, its integer digits are kept).
    if err < 9.95:
        assert len(Decimal(err_text).normalize().as_tuple().digits) <= 2
    assert float(err_text) == pytest.approx(err, rel=0.06)
    # The value is the true one rounded at that place.
    assert abs(float(value_text) - value) <= 0.5 * 10.0 ** (-value_decimals) * (1 + 1e-9) + 1e-12 * abs(value)


def test_interval_at_the_uncertainty_decimals():
    assert format_interval(0.2290087, 0.2303199, 0.000317651) == "[0.22901, 0.23032]"
    assert format_interval(0.2290087, 0.2303199) == "[0.22901, 0.23032]"
    assert format_interval(float("nan"), 1.0, 0.1) == "—"


def test_figure_files_are_the_same_bytes_every_time(tmp_path):
    """SVGs carry no date and no random ids: the same result writes the same files."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from servoscope.report.html import ReportSection

    files = []
    for run in ("a", "b"):
        fig, ax = plt.subplots()
        ax.plot([0, 1, 2], [1, 3, 2], label="x")
        ax.legend()
        section = ReportSection("s", figures_dir=tmp_path / run)
        section.figure(fig, "caption", "alt", name="fig")
        files.append((tmp_path / run / "fig.svg").read_bytes())
    assert b"<dc:date>" not in files[0]
    assert files[0] == files[1]


@pytest.mark.parametrize("facecolor, size_in, size_px", [("white", (5.3, 3.1), (465, 795)),
                                                         ("none", (5.3, 3.1), (465, 795)),
                                                         ("white", (3.26, 2.26), (339, 489))])
def test_figure_file_and_page_image_are_what_savefig_draws(tmp_path, facecolor, size_in, size_px):
    """The figure's PNG file holds the pixels ``savefig`` draws at the file's resolution (RGB where the figure is
    opaque, RGBA where it is not), and the page's image is that picture shrunk to the page's resolution by
    OpenCV's area averaging, not drawn again; without a figures folder, the page's image is what ``savefig``
    draws at the page's resolution. 3.26 × 2.26 in at 150 dpi is 489 × 339 px on the canvas, where
    int(3.26 · 150) is 488: the size is the canvas's, not recomputed."""
    import base64
    import io
    import re

    import cv2
    import matplotlib
    import numpy as np
    from PIL import Image

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from servoscope.report.html import FILE_DPI, PAGE_DPI, ReportSection

    def figure():
        fig, ax = plt.subplots(figsize=size_in, facecolor=facecolor)
        ax.plot(np.linspace(0, 1, 50), np.sin(np.linspace(0, 9, 50)), label="sine")
        ax.set_title("a title")
        ax.legend()
        return fig

    expected_io = io.BytesIO()
    drawn = figure()
    drawn.savefig(expected_io, format="png", dpi=FILE_DPI)
    plt.close(drawn)
    expected = np.asarray(Image.open(expected_io).convert("RGBA"))
    section = ReportSection("s", figures_dir=tmp_path)
    section.figure(figure(), "caption", "alt", name="fig")
    written = Image.open(tmp_path / "fig.png")
    assert written.mode == ("RGB" if facecolor == "white" else "RGBA")
    pixels = np.asarray(written.convert("RGBA"))
    assert pixels.shape == expected.shape == (*size_px, 4)
    assert np.array_equal(pixels, expected)
    page = re.search(r"base64,([A-Za-z0-9+/=]+)", "".join(section.html_parts)).group(1)
    page_pixels = np.asarray(Image.open(io.BytesIO(base64.b64decode(page))))
    scale = PAGE_DPI / FILE_DPI
    size = (round(expected.shape[1] * scale), round(expected.shape[0] * scale))
    shrunk = cv2.resize(np.asarray(written), size, interpolation=cv2.INTER_AREA)
    assert np.array_equal(page_pixels, shrunk)
    # No figures folder: the page's image drawn once at the page's resolution, savefig's pixels.
    page_io = io.BytesIO()
    drawn = figure()
    drawn.savefig(page_io, format="png", dpi=PAGE_DPI)
    plt.close(drawn)
    alone = ReportSection("s")
    alone.figure(figure(), "caption", "alt")
    page = re.search(r"base64,([A-Za-z0-9+/=]+)", "".join(alone.html_parts)).group(1)
    assert np.array_equal(np.asarray(Image.open(io.BytesIO(base64.b64decode(page))).convert("RGBA")),
                          np.asarray(Image.open(page_io).convert("RGBA")))
