"""`servoscope identify` as a command: monochrome footage end to end (issue 28), and output whole or absent (issue 29).

One module fixture renders the monochrome twin (white dots told by brightness, gray
TIFF sequences) at 8, 12 and 16 bits and runs the command itself, through
``servoscope.cli.main``, on each. Oracles: the twin's truth.json (the model), the
report's own figures, and for the failures the output folder's bytes before and after.
"""

from __future__ import annotations

import contextlib
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from servoscope.cli import main
from servoscope.errors import ServoscopeError
from servoscope.simulate import simulate_campaign

BITS = (8, 12, 16)
#: Small and short: three dwells (a second-order model needs three), no step.
TWIN = dict(width=320, height=256, frames_format="tiff16", monochrome=True, frequencies_hz=(1.5, 4.0, 10.0),
            include_step=False, min_dwell_s=0.6)


def run(*args) -> int:
    """``servoscope ARGS`` in this process: its exit code."""
    with pytest.raises(SystemExit) as stop:
        main([str(a) for a in args])
    return stop.value.code


def identify(campaign: Path, out: Path) -> int:
    return run("identify", campaign, "--out", out, "--workers", 1, "--quiet")


@pytest.fixture(scope="module")
def mono(tmp_path_factory):
    """bits → (campaign.toml, output folder, exit code of `servoscope identify`)."""
    root = tmp_path_factory.mktemp("mono-cli")
    runs = {}
    for bits in BITS:
        toml = simulate_campaign(root / f"twin{bits}", "quick", bits, bit_depth=bits, **TWIN)
        out = root / f"out{bits}"
        runs[bits] = (toml, out, identify(toml, out))
    return runs


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (hidden ones too), by relative path: its bytes."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


# --- Monochrome end to end -------------------------------------------------------------------------------------


@pytest.mark.parametrize("bits", BITS)
def test_identify_command_on_monochrome_footage(mono, bits):
    import tifffile

    toml, out, code = mono[bits]
    assert code == 0
    frame = tifffile.imread(sorted((toml.parent / "dwell_01_1.50Hz").glob("*.tif"))[0])
    # The twin wrote the depth asked for: 8-bit files, or 16-bit words holding 12 or 16 bits.
    assert frame.dtype == (np.uint8 if bits == 8 else np.uint16) and 2 ** (bits - 1) <= frame.max() < 2**bits
    assert f"bits = {bits}" in toml.read_text() and 'lead = "bright"' in toml.read_text()
    truth = json.loads((toml.parent / "truth.json").read_text())["model"]
    model = json.loads((out / "result.json").read_text())["model"]
    for name in ("gain", "natural_frequency_rad_s"):
        assert model[name] == pytest.approx(truth[name], rel=0.02), name
    page = (out / "report.html").read_text(encoding="utf-8")
    assert 'alt="Segmentation"' in page and 'alt="Frame with detected centroids"' in page
    import cv2

    seg = cv2.imread(str(out / "figures" / "segmentation.png"), cv2.IMREAD_GRAYSCALE)
    assert seg is not None and (seg > 200).sum() > 100  # the dots' pixels are painted: something was segmented
    assert not list(out.parent.glob(f"{out.name}.tmp-*"))


@pytest.fixture(scope="module")
def mraw(tmp_path_factory):
    """A Photron camera's campaign: packed 12-bit MRAW files, one folder per dwell, each ``frames.cih`` (the
    same name, as a camera's program saves them), the LED fixed to the stand; (campaign.toml, output, exit code)."""
    root = tmp_path_factory.mktemp("mraw-cli")
    toml = simulate_campaign(root / "twin", "quick", 12, bit_depth=12, led_place="stand",
                             **{**TWIN, "frames_format": "mraw"})
    return toml, root / "out", identify(toml, root / "out")


def test_identify_command_on_a_photron_mraw_with_the_led_on_the_stand(mraw):
    toml, out, code = mraw
    assert code == 0
    result = json.loads((out / "result.json").read_text())
    # Labels from the folders: every recording's file is called frames.cih.
    assert [t["label"] for t in result["tests"]] == ["dwell_01_1.50Hz", "dwell_02_4.00Hz", "dwell_03_10.00Hz"]
    # Every frame valid; each dwell's input start found from the stand's LED (its switch, not a blob on the blade).
    assert all(t["valid_frames"] == t["frames"] and t["t0_s"] is not None for t in result["tests"])
    truth = json.loads((toml.parent / "truth.json").read_text())["model"]
    model = result["model"]
    # Issue 28's targets: K and ωn within 0.3 %, ζ within 1 %, each 95 % interval holding the truth; the
    # dead time (the stand's LED's switches give each dwell's t0) within 0.5 ms. Its interval is not
    # asserted: on these 0.6 s dwells (the 1.5 Hz one warned "transient beyond half the record") the
    # phases put it 0.12 ms off with ±0.12 ms stated, the colour twin's alike (the closing note of #28).
    for name, rel in (("gain", 0.003), ("natural_frequency_rad_s", 0.003), ("damping_ratio", 0.01)):
        assert model[name] == pytest.approx(truth[name], rel=rel), name
        lo, hi = model["ci95"][name]
        assert lo <= truth[name] <= hi, name
    assert abs(model["dead_time_s"] - truth["dead_time_s"]) < 0.5e-3


@pytest.mark.parametrize("which", ["tiff12", "mraw12"])
def test_monochrome_report_renders_in_chromium(mono, mraw, which, tmp_path):
    browser = pytest.importorskip("report.test_report_browser")  # its chromium checks; skips without chromium
    if browser.CHROMIUM is None:
        pytest.skip("Debian's chromium is not on PATH")
    report = (mono[12][1] if which == "tiff12" else mraw[1]) / "report.html"
    probe = browser._probe(report, tmp_path)
    assert probe["errors"] == [] and probe["undecoded"] == [] and probe["images"] >= 3
    assert browser._console_lines(report, tmp_path) == []


def test_track_overlay_and_markers_on_monochrome_footage(mono, tmp_path, capsys):
    toml = mono[12][0]
    frames = toml.parent / "dwell_02_4.00Hz"
    csv, overlay = tmp_path / "t.csv", tmp_path / "t.mp4"
    assert run("track", frames, "--fps", 100, "--bits", 12, "--lead", "bright", "--trail", "bright", "--led", "bright",
               "--exposure", 0.01, "--out", csv, "--overlay", overlay) == 0
    assert csv.stat().st_size > 0 and overlay.stat().st_size > 0
    text = capsys.readouterr().out
    assert "valid (100.0 %)" in text and "t0 = none" not in text  # the 12-bit LED's switch was found
    capsys.readouterr()
    assert run("markers", frames, "--fps", 100, "--bits", 12, "--out", tmp_path / "m.png") == 0
    text = capsys.readouterr().out
    truth = json.loads((toml.parent / "truth.json").read_text())["tests"][1]
    rows = [line for line in text.splitlines() if line.startswith("│") and "bright" in line]
    xy = np.array([[float(v) for v in line.split("│")[4:6]] for line in rows])
    for dot in (truth["lead_xy_px"][0], truth["trail_xy_px"][0]):  # both dots listed, near where the twin drew them
        assert np.min(np.hypot(*(xy - np.asarray(dot)).T)) < 2.0
    assert "bright@x,y" in text and (tmp_path / "m.png").exists()


# --- Whole or absent --------------------------------------------------------------------------------------------


def _boom(*args, **kwargs):
    raise RuntimeError("injected failure")


STAND_IN = "<!DOCTYPE html><html><body>stand-in</body></html>"


def _cheap_report(result, figures_dir):
    """A stand-in for the report's figures and page (seconds of matplotlib), for the stages after them."""
    figures_dir.mkdir(parents=True, exist_ok=True)
    (figures_dir / "stand-in.svg").write_text("<svg/>")
    return STAND_IN


def _fail_at(stage: str, monkeypatch, error=_boom) -> None:
    """Make the writer of ``stage`` raise, everything written before it real."""
    import servoscope.report.html as html
    import servoscope.report.write as write
    from servoscope.campaign import IdentificationResult
    from servoscope.markers import Track
    from servoscope.sysid.frequency_response import FrequencyResponse

    if stage == "tracks":
        real_to_csv, written = Track.to_csv, []

        def second_fails(self, path):  # one track written whole, the next one fails
            if written:
                error()
            written.append(path)
            real_to_csv(self, path)

        monkeypatch.setattr(Track, "to_csv", second_fails)
    elif stage == "frequency_response":
        monkeypatch.setattr(FrequencyResponse, "to_csv", lambda self, path: error())
    elif stage == "figures":
        real = html.atomic_path

        @contextlib.contextmanager
        def third_figure_file_fails(path):  # a figure's PNG and SVG written, the next figure fails
            if len(list(Path(path).parent.iterdir())) >= 2:
                error()
            with real(path) as tmp:
                yield tmp

        monkeypatch.setattr(html, "atomic_path", third_figure_file_fails)
    else:
        monkeypatch.setattr(write, "build_report", _cheap_report)
        if stage == "report.html":
            monkeypatch.setattr(write, "write_text_atomic", lambda path, text: error())
        else:
            monkeypatch.setattr(IdentificationResult, "write_summary", lambda self, out: error())


STAGES = ("tracks", "frequency_response", "figures", "report.html", "result.json")


@pytest.mark.parametrize("stage", STAGES)
def test_a_failure_while_writing_leaves_the_previous_output_byte_identical(mono, tmp_path, monkeypatch, stage):
    toml, finished, _ = mono[8]
    out = tmp_path / "out"
    shutil.copytree(finished, out)  # a finished run, its track cache included (so no tracking here)
    for path in out.rglob("*"):
        if path.is_file() and ".cache" not in path.parts:  # an earlier run's output: not what this run writes
            path.write_bytes(path.read_bytes() + b"\nan earlier run\n")
    (out / "notes.txt").write_text("the user's own file\n")
    before = snapshot(out)
    _fail_at(stage, monkeypatch)
    assert identify(toml, out) == 1
    assert snapshot(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # no temporary folder left beside it


@pytest.mark.parametrize("stage, error, code", [
    ("tracks", RuntimeError, 1),
    ("result.json", RuntimeError, 1),
    ("frequency_response", ServoscopeError, 2),
])
def test_a_failure_leaves_no_new_output_folder(mono, tmp_path, monkeypatch, stage, error, code):
    toml = mono[8][0]
    out = tmp_path / "new" / "out"

    def fail(*args, **kwargs):
        raise error("injected failure")

    _fail_at(stage, monkeypatch, fail)
    assert identify(toml, out) == code
    assert list(tmp_path.iterdir()) == []  # neither the folder nor the parent made for it, nor a temporary one


def test_a_finished_run_replaces_the_previous_one_and_keeps_what_else_is_there(mono, tmp_path, monkeypatch):
    toml, finished, _ = mono[8]
    out = tmp_path / "out"
    shutil.copytree(finished, out)
    (out / "notes.txt").write_text("the user's own file\n")
    (out / "tracks" / "old.csv").write_text("a track of an earlier campaign\n")
    cache = {k: v for k, v in snapshot(out).items() if k.startswith(".cache")}
    monkeypatch.setattr("servoscope.report.write.build_report", _cheap_report)
    assert identify(toml, out) == 0
    after = snapshot(out)
    assert (out / "report.html").read_text() == STAND_IN  # the new run's report
    assert not (out / "figures" / "bode.svg").exists() and (out / "figures" / "stand-in.svg").exists()
    assert not (out / "tracks" / "old.csv").exists()  # tracks/ replaced whole
    assert after["notes.txt"] == b"the user's own file\n" and cache.items() <= after.items()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_track_writes_its_csv_and_overlay_together_or_neither(mono, tmp_path, monkeypatch):
    import servoscope.pipeline.overlay as overlay_module

    frames = mono[12][0].parent / "dwell_01_1.50Hz"
    csv, overlay = tmp_path / "t.csv", tmp_path / "t.mp4"
    csv.write_text("an earlier track\n")

    def half_an_overlay(video, track, out_path, **kwargs):
        Path(out_path).write_bytes(b"half a video")
        raise RuntimeError("injected failure")

    monkeypatch.setattr(overlay_module, "write_overlay", half_an_overlay)
    assert run("track", frames, "--fps", 100, "--bits", 12, "--lead", "bright", "--trail", "bright", "--led", "none",
               "--out", csv, "--overlay", overlay) == 1
    assert csv.read_text() == "an earlier track\n" and sorted(p.name for p in tmp_path.iterdir()) == ["t.csv"]


def test_simulate_command_leaves_no_folder_when_it_fails(tmp_path, monkeypatch):
    from servoscope.video.sequence_writer import TiffSequenceWriter

    real, written = TiffSequenceWriter.write, []

    def third_frame_fails(self, frame, time_s=None):
        if len(written) == 2:
            raise RuntimeError("injected failure")
        written.append(time_s)
        return real(self, frame, time_s)

    monkeypatch.setattr(TiffSequenceWriter, "write", third_frame_fails)
    out = tmp_path / "twin"
    assert run("simulate", out, "--preset", "quick", "--frames", "tiff16") == 1
    assert len(written) == 2 and list(tmp_path.iterdir()) == []
