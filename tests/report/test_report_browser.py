"""The HTML report in a real browser: Debian's chromium, headless.

Three looks at the report that ``servoscope.write_report()`` produces:

1. the DOM after loading, from a copy of the page with a small probe script
   first in ``<head>``: it records script errors, failed resource loads and
   ``console.error`` calls, and on ``load`` writes, into the DOM, how many
   ``<img>`` there are and which did not decode (``naturalWidth == 0``);
2. the unmodified page with chromium's console logging on: no ``CONSOLE``
   line may appear (the report has no scripts, so any message is a fault);
3. a screenshot of the unmodified page, which must not be blank.

A page with a broken image and a failing script is put through the same
checks first, so that a check that cannot fail is noticed.
"""

from __future__ import annotations

import html
import html.parser
import json
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from servoscope.report import write_report

CHROMIUM = shutil.which("chromium")
pytestmark = pytest.mark.skipif(
    CHROMIUM is None, reason="Debian's chromium is not on PATH (CI installs it: apt-get install chromium)"
)

_PROBE = """<script>
window.__servoscopeErrors = [];
window.addEventListener("error", function (e) {
  var what = e.message || (e.target && e.target.tagName ? "failed to load <" + e.target.tagName.toLowerCase() + ">" : "error");
  window.__servoscopeErrors.push(what);
}, true);
(function () {
  var original = console.error;
  console.error = function () {
    window.__servoscopeErrors.push("console.error: " + Array.prototype.join.call(arguments, " "));
    return original.apply(console, arguments);
  };
})();
window.addEventListener("load", function () {
  var images = Array.prototype.slice.call(document.images);
  var result = {
    images: images.length,
    undecoded: images.filter(function (i) { return !(i.complete && i.naturalWidth > 0); })
                    .map(function (i) { return i.alt || i.src.slice(0, 40); }),
    errors: window.__servoscopeErrors
  };
  var pre = document.createElement("pre");
  pre.id = "servoscope-probe";
  pre.textContent = JSON.stringify(result);
  document.body.appendChild(pre);
});
</script>"""


def _chromium(page: Path, profile: Path, *extra: str) -> subprocess.CompletedProcess:
    args = [
        CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync",
        f"--user-data-dir={profile}",
        # Lets the page finish loading (and its load handlers run) before the dump or screenshot.
        "--virtual-time-budget=10000",
        *extra, page.as_uri(),
    ]
    return subprocess.run(args, capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL)


def _probe(page: Path, tmp_path: Path) -> dict:
    probed = tmp_path / f"probed-{page.name}"
    text = page.read_text(encoding="utf-8")
    probed.write_text(re.sub(r"<head[^>]*>", lambda m: m.group(0) + _PROBE, text, count=1), encoding="utf-8")
    proc = _chromium(probed, tmp_path / "profile-dom", "--dump-dom")
    assert proc.returncode == 0, proc.stderr[-3000:]
    found = re.search(r'<pre id="servoscope-probe">(.*?)</pre>', proc.stdout, re.S)
    assert found, f"the page's load event never ran:\n{proc.stdout[:2000]}\n{proc.stderr[-2000:]}"
    return json.loads(html.unescape(found.group(1)))


def _console_lines(page: Path, tmp_path: Path) -> list[str]:
    proc = _chromium(page, tmp_path / "profile-log", "--enable-logging=stderr", "--v=0", "--dump-dom")
    assert proc.returncode == 0, proc.stderr[-3000:]
    return [line for line in proc.stderr.splitlines() if ":CONSOLE" in line]


def _screenshot(page: Path, tmp_path: Path) -> np.ndarray:
    import cv2

    png = tmp_path / f"{page.stem}.png"
    proc = _chromium(page, tmp_path / "profile-shot", f"--screenshot={png}", "--window-size=1100,1600",
                     "--hide-scrollbars")
    assert proc.returncode == 0 and png.exists(), proc.stderr[-3000:]
    img = cv2.imread(str(png), cv2.IMREAD_COLOR)
    assert img is not None, f"{png}: not a readable PNG"
    return img


class _Images(html.parser.HTMLParser):
    def __init__(self):
        super().__init__()
        self.srcs: list[str] = []

    def handle_starttag(self, tag, attrs):
        if tag == "img":
            self.srcs.append(dict(attrs).get("src") or "")


def test_the_checks_catch_a_broken_page(tmp_path):
    bad = tmp_path / "bad.html"
    bad.write_text(
        "<!DOCTYPE html><html><head><title>bad</title></head><body>"
        '<img alt="broken" src="data:image/png;base64,AAAA">'
        "<script>console.error('boom'); notAFunction();</script></body></html>"
    )
    probe = _probe(bad, tmp_path)
    assert probe["undecoded"] == ["broken"]
    assert any("boom" in e for e in probe["errors"]) and any("notAFunction" in e for e in probe["errors"])
    assert len(_console_lines(bad, tmp_path)) >= 2
    blank = tmp_path / "blank.html"
    blank.write_text("<!DOCTYPE html><html><head><title>blank</title></head><body></body></html>")
    assert float(_screenshot(blank, tmp_path).std()) < 1.0


def test_report_renders_in_chromium(quick_result, tmp_path):
    paths = write_report(quick_result, tmp_path / "out")
    report = paths["report"]

    probe = _probe(report, tmp_path)
    assert probe["errors"] == []
    assert probe["images"] >= 1
    assert probe["undecoded"] == [], "images that did not decode"
    # Every image is embedded: the report is one file that can be mailed.
    parser = _Images()
    parser.feed(report.read_text(encoding="utf-8"))
    assert len(parser.srcs) == probe["images"]
    assert all(src.startswith("data:image/") for src in parser.srcs), [s[:40] for s in parser.srcs]

    assert _console_lines(report, tmp_path) == []

    shot = _screenshot(report, tmp_path)
    grey = shot.mean(axis=2)
    assert float(grey.std()) > 10.0, "screenshot looks blank"
    assert (grey < 200).mean() > 0.01, "hardly anything drawn on the page"
