"""Report: figures (matplotlib) and the self-contained HTML page."""

from .figures import bode_figure, dwell_figure, overlay_figure, step_figure
from .html import ReportSection, render_html

__all__ = ["ReportSection", "bode_figure", "dwell_figure", "overlay_figure", "render_html", "step_figure"]
