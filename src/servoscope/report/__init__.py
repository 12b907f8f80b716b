"""Report: figures (matplotlib), the self-contained HTML page, and the output folder."""

from .figures import bode_figure, dwell_figure, overlay_figure, step_figure
from .html import ReportSection, render_html
from .write import write_report

__all__ = ["ReportSection", "bode_figure", "dwell_figure", "overlay_figure", "render_html", "step_figure",
           "write_report"]
