"""What several test folders share: paths, a tiny video, a manifest, the kernels' synthetic frame.

The suite mirrors ``src/servoscope/`` (one folder per stage, package-wide checks at the top);
``tests/`` is on ``sys.path`` (pytest puts the root conftest's folder there), so any test
imports these as ``from support import ...``.
"""

from __future__ import annotations

from pathlib import Path

import math

import av
import numpy as np

from servoscope.markers import kernels as K
from servoscope.video.writer import rgb_to_yuv420p
from servoscope.simulate.presets import get_preset
from servoscope.simulate.servo import InputSignal, ServoModel
from servoscope.sysid.servo_sim import ServoTrace

#: The repository's root, its sources and the tests' own data.
ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src" / "servoscope"
DATA = Path(__file__).resolve().parent / "data"
#: The read-only shared folder beside the checkout (real calibration photos); absent in a clone elsewhere.
CHESSBOARD = (ROOT / ".." / "shared" / "data" / "opencv-chessboard").resolve()


def tiny_video(path: Path, frames: int = 3) -> Path:
    with av.open(str(path), "w") as out:
        stream = out.add_stream("mpeg4", rate=25)
        stream.width, stream.height, stream.pix_fmt = 64, 48, "yuv420p"
        for i in range(frames):
            img = np.full((48, 64, 3), 40 * i, np.uint8)
            for packet in stream.encode(av.VideoFrame.from_ndarray(img, format="rgb24")):
                out.mux(packet)
        for packet in stream.encode():
            out.mux(packet)
    return path


GOOD = """
[markers]
lead = "#d62728"
trail = "green"
led = "#ffd400"
[[tests]]
video = "a.mp4"
kind = "sine"
frequency_hz = 1.0
amplitude = 0.1
[[tests]]
video = "b.mp4"
label = "stepper"
kind = "step"
amplitude = 0.5
"""


def mraw_in_high_bits(cih: Path, folder: Path) -> Path:
    """A packed 12-bit MRAW saved again as Photron may: its samples in the high bits of 16-bit words
    ("Color Bit : 16", "EffectiveBit Side : Higher"), levels 16x the packed file's; the new CIH's path."""
    from servoscope.video.native import iter_native_frames

    words = np.stack([f.gray for f in iter_native_frames(cih)]).astype(np.uint16) << 4
    (folder / "high.mraw").write_bytes(words.astype("<u2").tobytes())
    text = Path(cih).read_text().replace("Color Bit : 12", "Color Bit : 16").replace(
        "EffectiveBit Side : Lower", "EffectiveBit Side : Higher")
    assert "Color Bit : 16" in text and "Side : Higher" in text, "not a packed 12-bit MRAW's CIH"
    (folder / "high.cih").write_text(text)
    return folder / "high.cih"


def kernel_frame(seed: int = 0, h: int = 96, w: int = 128) -> np.ndarray:
    """A synthetic yuv420p frame: textured grey background, a red and a green disk (anti-aliased), noise."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w] + 0.5
    rgb = np.empty((h, w, 3))
    rgb[:] = (90.0, 95.0, 100.0)
    rgb[: h // 3] = (150.0, 170.0, 200.0)  # a "sky" band
    for (cx, cy, r, col) in ((85.3, 40.7, 9.0, (214, 39, 40)), (30.6, 52.2, 8.0, (44, 160, 44))):
        cov = np.clip(r + 0.5 - np.hypot(xx - cx, yy - cy), 0.0, 1.0)[..., None]
        rgb = cov * np.asarray(col, float) + (1 - cov) * rgb
    rgb += rng.normal(0, 1.5, rgb.shape)
    return rgb_to_yuv420p(np.clip(rgb, 0, 255).round().astype(np.uint8))


def kernel_params(i420: np.ndarray) -> np.ndarray:
    from servoscope.markers.colour import ycbcr_bt601 as _bt601

    rows = []
    for rgb, (x0, y0, x1, y1), r in (((214, 39, 40), (60, 15, 115, 70), 11.0), ((44, 160, 44), (5, 25, 60, 80), 10.0)):
        y, u, v = _bt601(rgb)
        sat = np.hypot(u - 128, v - 128)
        p = np.zeros(K.NP)
        p[[K.P.X0, K.P.Y0, K.P.X1, K.P.Y1]] = (x0, y0, x1, y1)
        p[[K.P.YM, K.P.UM, K.P.VM]] = (y, u, v)
        p[[K.P.DIR_U, K.P.DIR_V]] = ((u - 128) / sat, (v - 128) / sat)
        p[K.P.COS_TOL] = np.cos(np.radians(15))
        p[K.P.SAT_MIN] = 0.45 * sat
        p[K.P.AGREE] = 0.25
        p[K.P.RADIUS] = r
        p[K.P.RING] = 4.0
        p[K.P.W_Y] = 1.0
        p[K.P.ITER] = 2
        p[K.P.ENABLED] = 1
        p[K.P.VAR_Y] = p[K.P.VAR_C] = 2.25
        p[K.P.ALPHA_LO], p[K.P.ALPHA_HI] = 0.0, 1.0
        p[K.P.MIN_DEN] = 100.0
        rows.append(p)
    return np.array(rows)


def run_kernel(engine, i420, params, led, row_off=0, row_step=1):
    h = i420.shape[0] * 2 // 3
    y = i420[:h][row_off::row_step]
    u, v = i420[h:].reshape(2, h // 2, -1)
    out = np.zeros((params.shape[0], K.NQ))
    led_out = np.zeros(K.LED_NQ)
    K.track_frame(engine, y, u, v, row_off, row_step, params, led, out, led_out)
    return out, led_out


# The time-domain servo models' tests (tests/sysid/test_servo_*.py): the twin's servo, simulated without rendering.
SERVO = get_preset("quick").servo  #: the quick preset's servo (the paper's)
_K, _WN, _ZETA, _TAU = SERVO.gain, SERVO.natural_frequency_rad_s, SERVO.damping_ratio, 0.085
SERVO_LINEAR = {"gain": _K, "natural_frequency_rad_s": _WN, "damping_ratio": _ZETA, "dead_time_s": _TAU}
#: Each structure: the twin's option and the fitted parameter's true value (the rate limit in the
#: output's units: the twin limits the reference, in input units per second, so times K).
SERVO_STRUCTURES = {"rate_limit": ({"rate_limit_per_s": 4.0}, "rate_limit_rad_s", 4.0 * _K),
                    "backlash": ({"backlash": 0.004}, "backlash_rad", 0.004),
                    "quantization": ({"input_quantization": 0.02}, "quantization_step", 0.02)}


def servo_trace(kind, amplitude, frequency_hz, t, y, noise=3e-5, exposure_s=0.0, t0=0.3) -> ServoTrace:
    """A test's trace for the time-domain fits (a dwell's steady window from 0.3 s after its start)."""
    window = (t0 + 0.3, float(t[-1])) if kind == "sine" else None
    return ServoTrace(f"{kind}_{frequency_hz}_{amplitude}", kind, amplitude, frequency_hz, t0, t, y, noise,
                      exposure_s, window)


def servo_campaign(servo: ServoModel, seed: int, fps: float = 100.0, noise: float = 3e-5):
    """The quick preset's tests (4 frequencies at 2 amplitudes and a step) simulated by the twin, with noise.

    Returns the traces and each dwell's measured (gain, phase_deg, coherence), by label.
    """
    rng = np.random.default_rng(seed)
    traces, response = [], {}
    for f in (1.0, 2.29, 5.24, 12.0):
        for a in (0.05, 0.2):
            t = np.arange(0.0, 0.3 + 0.3 + max(1.0, 2.0 / f), 1.0 / fps) + rng.uniform(0, 1.0 / fps)
            y = servo.response(InputSignal("sine", a, f, 0.3), t) + noise * rng.standard_normal(t.size) + 0.02
            tr = servo_trace("sine", a, f, t, y, noise)
            traces.append(tr)
    t = np.arange(0.0, 1.0, 1.0 / fps)
    traces.append(servo_trace("step", 0.5, None, t, servo.response(InputSignal("step", 0.5, None, 0.3), t)
                              + noise * rng.standard_normal(t.size) - 0.01, noise))
    for tr in traces:
        if tr.kind == "sine":
            # The measured fundamental, by the same regression the model's goes through (a linear oracle).
            lo, hi = tr.window_s
            inside = (tr.time_s >= lo) & (tr.time_s <= hi)
            w = 2 * math.pi * tr.frequency_hz * (tr.time_s[inside] - tr.t0_s)
            a, b, _ = np.linalg.lstsq(np.column_stack([np.sin(w), np.cos(w), np.ones_like(w)]),
                                      tr.angle_rad[inside], rcond=None)[0]
            response[tr.label] = (math.hypot(a, b) / tr.amplitude, math.degrees(math.atan2(b, a)), 1.0)
    return traces, response


def cli(capsys, *args) -> tuple[int, str, str]:
    """``servoscope ARGS`` in this process: (exit status, stdout, stderr); earlier output discarded."""
    from servoscope.cli import main

    capsys.readouterr()
    try:
        main([str(a) for a in args])
        code = 0
    except SystemExit as exc:
        code = int(exc.code or 0)
    out = capsys.readouterr()
    return code, out.out, out.err


def run_cli(*args, cwd=None) -> "subprocess.CompletedProcess[str]":
    """``python -m servoscope ARGS`` in this process, as the command-line tests ran it in a child.

    Starting an interpreter that imports servoscope costs ~2.5 s of CPU a call; the command's own
    entry point (``servoscope.cli.main``: its exit codes and one-line errors) runs here instead, with
    stdout and stderr captured, Python's default warning filters (a warning is printed to stderr, as
    the child printed it, not raised or kept by pytest) and ``cwd`` as the working folder.
    Returns what ``subprocess.run(..., capture_output=True, text=True)`` returned.
    """
    import contextlib
    import io
    import subprocess
    import warnings

    from servoscope.cli import main

    out, err = io.StringIO(), io.StringIO()

    def show(message, category, filename, lineno, file=None, line=None):
        err.write(warnings.formatwarning(message, category, filename, lineno, line))

    argv = [str(a) for a in args]
    with contextlib.ExitStack() as stack:
        stack.enter_context(warnings.catch_warnings())
        warnings.resetwarnings()  # the interpreter's defaults, as in a child started without -W
        for action, category, module in (("ignore", ResourceWarning, ""), ("ignore", ImportWarning, ""),
                                         ("ignore", PendingDeprecationWarning, ""),
                                         ("ignore", DeprecationWarning, ""),
                                         ("default", DeprecationWarning, "__main__")):
            warnings.filterwarnings(action, category=category, module=module)
        warnings.showwarning = show
        if cwd is not None:
            stack.enter_context(contextlib.chdir(cwd))
        stack.enter_context(contextlib.redirect_stdout(out))
        stack.enter_context(contextlib.redirect_stderr(err))
        try:
            main(argv)
            code = 0
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
            if not isinstance(exc.code, (int, type(None))):
                err.write(f"{exc.code}\n")
    return subprocess.CompletedProcess(["servoscope", *argv], code, out.getvalue(), err.getvalue())


# result.json's flat name for each parameter's standard error (the transfer function's, kept).
FLAT_STDERR = {"gain": "gain_stderr", "natural_frequency_rad_s": "natural_frequency_stderr_rad_s",
               "damping_ratio": "damping_ratio_stderr", "dead_time_s": "dead_time_stderr_s"}


def _views(result, out: Path, capsys) -> tuple[dict, str, str, str]:
    import html
    import json

    from servoscope.cli_tables import print_model

    data = json.loads((out / "result.json").read_text())
    report = html.unescape((out / "report.html").read_text())
    capsys.readouterr()
    print_model(result)
    table = capsys.readouterr().out
    notebook = html.unescape(result._repr_html_())
    return data, report, table, notebook


def check_every_view(result, out: Path, capsys) -> list[str]:
    """Every headline parameter the same in result.json, report.html, ``identify``'s table and the notebook view
    (issue 30): result.json's ``model.parameters`` is the oracle, each text holds its cells; returns the names."""
    data, report, table, notebook = _views(result, out, capsys)
    head = result.headline
    model = data["model"]
    stored = model["parameters"]
    assert list(stored) == list(head.parameters)
    from servoscope.parameters import Parameter

    for name, entry in stored.items():
        p = Parameter.from_summary(name, entry)
        assert p == head.parameters[name]  # result.json holds the headline's parameter whole
        # result.json's older fields say the same.
        assert model[name] == p.value and model["ci95"][name] == list(p.ci95)
        flat = FLAT_STDERR.get(name)
        assert (model[flat] if flat in model else model["stderr"][name]) == p.stderr
        cells = [head.label(name) + p.held_text(), *p.cells()]
        row = "<td>" + "</td><td>".join(cells) + "</td>"
        assert row in report, (name, row)
        assert row in notebook, (name, row)
        # The terminal table may wrap a long label: the row's first line holds its start and every number.
        lines = [ln for ln in table.splitlines() if ln.startswith("│ " + cells[0][:14])]
        assert lines and all(c in lines[0] for c in cells[1:]), (name, cells, lines)
    # The headline's dead time is the one result.json states at the top level.
    if "dead_time_s" in stored:
        assert data["dead_time_s"] == stored["dead_time_s"]["value"]
    return list(stored)
