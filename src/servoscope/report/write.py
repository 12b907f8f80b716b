"""Writing a campaign's output folder: the result's data and the HTML report."""

from __future__ import annotations

from pathlib import Path

from .._io import write_text_atomic
from ..campaign.result import IdentificationResult
from .build import build_report

__all__ = ["write_report"]


def write_report(result: IdentificationResult, out_dir: str | Path) -> dict[str, Path]:
    """Write everything ``servoscope identify`` writes: the data, report.html and its figures.

    tracks/<label>.csv and frequency_response.csv first, then report.html
    (figures/ as PNG and SVG beside it), result.json last: its presence says
    the run finished. Each file is written whole or not at all, so a run
    killed half-way leaves no output that looks complete.

    Parameters
    ----------
    result : IdentificationResult
    out_dir : str or path-like
        Created if missing.

    Returns
    -------
    dict of name → path written
        ``"tracks"``, ``"frequency_response"``, ``"report"``, ``"figures"``, ``"result"``.
    """
    out = Path(out_dir)
    paths = result.write_tables(out)
    paths["report"] = out / "report.html"
    paths["figures"] = out / "figures"
    write_text_atomic(paths["report"], build_report(result, figures_dir=paths["figures"]))
    paths["result"] = result.write_summary(out)
    return paths
