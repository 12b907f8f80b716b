"""The self-contained HTML report: every figure embedded, no network needed."""

from __future__ import annotations

import base64
import html
import io
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from .._io import atomic_path

__all__ = ["ReportSection", "figure_png_base64", "render_html"]

_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:2rem auto;max-width:1000px;color:#222;line-height:1.45}
h1{font-size:1.6rem;margin-bottom:.2rem} h2{font-size:1.2rem;margin-top:2rem;border-bottom:1px solid #ddd;padding-bottom:.2rem}
table{border-collapse:collapse;margin:.6rem 0;font-size:.9rem} td,th{border:1px solid #ddd;padding:.25rem .6rem;text-align:right}
th{background:#f4f4f4} td:first-child,th:first-child{text-align:left}
.warn{background:#fff4e5;border-left:4px solid #f0a020;padding:.4rem .8rem;margin:.3rem 0}
.ok{color:#1a7f37} .bad{color:#b42318} figure{margin:1rem 0} img{max-width:100%;height:auto}
figcaption{font-size:.85rem;color:#555} .muted{color:#666;font-size:.85rem}
.thumbs{display:flex;flex-wrap:wrap;gap:.5rem} .thumb{width:230px;margin:0}
.thumb img{width:230px;border:1px solid #ddd;cursor:zoom-in}
.thumb:target{position:fixed;inset:0;background:rgba(0,0,0,.75);display:flex;align-items:center;justify-content:center;z-index:10;width:auto}
.thumb:target img{width:auto;max-width:95vw;max-height:90vh;background:#fff;cursor:default}
.thumb .close{display:none} .thumb:target .close{display:block;position:fixed;top:1rem;right:1.5rem;color:#fff;font-size:2rem;text-decoration:none}
.thumb:target figcaption{display:none}
"""


@dataclass
class ReportSection:
    """A titled part of the report: text, tables and figures in order."""

    title: str
    html_parts: list[str] = field(default_factory=list)
    figures_dir: Path | None = None

    def text(self, text: str) -> "ReportSection":
        self.html_parts.append(f"<p>{html.escape(text)}</p>")
        return self

    def table(self, header: list[str], rows: list[list[object]]) -> "ReportSection":
        head = "".join(f"<th>{html.escape(str(h))}</th>" for h in header)
        body = "".join("<tr>" + "".join(f"<td>{html.escape(_fmt(c))}</td>" for c in row) + "</tr>" for row in rows)
        self.html_parts.append(f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>")
        return self

    def figure(self, fig: Figure, caption: str, alt: str, name: str | None = None) -> "ReportSection":
        data = self._encode(fig, name)
        self.html_parts.append(
            f'<figure><img alt="{html.escape(alt)}" src="data:image/png;base64,{data}">'
            f"<figcaption>{html.escape(caption)}</figcaption></figure>"
        )
        return self

    def thumbnails(self, items: list[tuple[Figure, str, str]]) -> "ReportSection":
        """Small figures that enlarge on click (CSS :target, no script); items are (figure, caption, name)."""
        cells = []
        for fig, caption, name in items:
            data = self._encode(fig, name)
            anchor = html.escape(name)
            cells.append(
                f'<figure class="thumb" id="{anchor}"><a href="#{anchor}"><img alt="{html.escape(caption)}" '
                f'src="data:image/png;base64,{data}"></a><a class="close" href="#_" title="close">×</a>'
                f"<figcaption>{html.escape(caption)}</figcaption></figure>"
            )
        self.html_parts.append('<div class="thumbs">' + "".join(cells) + "</div>")
        return self

    def _encode(self, fig: Figure, name: str | None) -> str:
        if self.figures_dir is not None and name:
            # The same figures as files, for papers and slides: PNG and SVG. The page's image is the
            # file's pixels shrunk, not drawn a third time (drawing is most of a report's time).
            self.figures_dir.mkdir(parents=True, exist_ok=True)
            pixels = _drawn(fig, FILE_DPI)
            with atomic_path(self.figures_dir / f"{name}.png") as tmp:
                tmp.write_bytes(_png(pixels))
            # No date and fixed element ids: the same result gives the same bytes.
            import matplotlib

            with matplotlib.rc_context({"svg.hashsalt": "servoscope"}):
                with atomic_path(self.figures_dir / f"{name}.svg") as tmp:
                    fig.savefig(tmp, metadata={"Date": None})
            import matplotlib.pyplot as plt

            plt.close(fig)
            return _page_png_base64(pixels)
        return figure_png_base64(fig)

    def warnings(self, items: list[str]) -> "ReportSection":
        for item in items:
            self.html_parts.append(f'<div class="warn">{html.escape(item)}</div>')
        return self


def _fmt(value: object) -> str:
    if value is None:
        return "—"
    if isinstance(value, float):
        if value != value:  # NaN
            return "—"
        return f"{value:.6g}"
    return str(value)


#: Resolution of the figure files (PNG) and of the page's images, dots per inch.
FILE_DPI = 150
PAGE_DPI = 110
#: zlib level of the report's PNGs. Level 1 writes a 7.5×6.2 in figure's page image in 38 ms against
#: level 6's (PIL's default) 99 ms, and its 150 dpi file in 148 ms against 183 ms, for 19–33 % more bytes:
#: a report of 20 figures is written ~2 s sooner for ~1 MB more.
PNG_COMPRESS_LEVEL = 1


def _drawn(fig: Figure, dpi: int) -> np.ndarray:
    """The figure drawn as ``savefig`` draws it (its facecolor, layout engine and ``dpi``): RGB, or RGBA where
    something is not opaque; uint8, shape (height, width, channels)."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="rgba", dpi=dpi)
    # The canvas's size at that dpi, asked of the canvas at that dpi as savefig sets it: its rounding is its
    # own (4.1 in at 110 dpi is 451 px, where int(4.1 * 110) is 450).
    original = fig.dpi
    fig.dpi = dpi
    try:
        width, height = fig.canvas.get_width_height(physical=True)
    finally:
        fig.dpi = original
    rgba = np.frombuffer(buffer.getbuffer(), dtype=np.uint8).reshape(height, width, 4)
    # An opaque figure (the report's: white) written without its alpha channel: a quarter fewer bytes to compress.
    return np.ascontiguousarray(rgba[..., :3]) if rgba[..., 3].min() == 255 else rgba


def _png(pixels: np.ndarray) -> bytes:
    from PIL import Image

    out = io.BytesIO()
    Image.fromarray(pixels).save(out, format="png", compress_level=PNG_COMPRESS_LEVEL)
    return out.getvalue()


def _page_png_base64(pixels: np.ndarray) -> str:
    """A figure file's pixels at the page's resolution (pixel-area averaging), as a base64-encoded PNG.

    From the file's own pixels, not drawn again: the page and the file show the same picture. Area
    averaging is OpenCV's choice for shrinking; it is a third of PIL's Lanczos's time on a report's figures.
    """
    import cv2

    scale = PAGE_DPI / FILE_DPI
    height, width = pixels.shape[:2]
    small = cv2.resize(pixels, (max(1, round(width * scale)), max(1, round(height * scale))),
                       interpolation=cv2.INTER_AREA)
    return base64.b64encode(_png(small)).decode("ascii")


def figure_png_base64(fig: Figure, dpi: int = PAGE_DPI) -> str:
    """PNG bytes of a figure, base64-encoded for a data: URL; closes the figure."""
    import matplotlib.pyplot as plt

    pixels = _drawn(fig, dpi)
    plt.close(fig)
    return base64.b64encode(_png(pixels)).decode("ascii")


def render_html(title: str, subtitle: str, sections: list[ReportSection]) -> str:
    """The whole page as one string."""
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>{html.escape(title)}</title><style>{_CSS}</style></head><body>",
        f"<h1>{html.escape(title)}</h1><p class=\"muted\">{html.escape(subtitle)}</p>",
    ]
    for section in sections:
        parts.append(f"<section><h2>{html.escape(section.title)}</h2>")
        parts.extend(section.html_parts)
        parts.append("</section>")
    parts.append("</body></html>")
    return "\n".join(parts)

