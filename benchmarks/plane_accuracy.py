"""The blade's plane end to end on twin footage: oblique views, with and without a board photo.

Run:  .venv/bin/python benchmarks/plane_accuracy.py [--out DIR] [--quick] [--more]

For each scenario (the ``quick`` preset, seed 0, a view ``(yaw, tilt)`` in degrees and a codec)
the twin renders the campaign (with ``board.png``, a 9x6 chessboard photographed in the blade's
plane through the same view and lens), then the commands run as a user runs them:

    servoscope plane board.png --board 9x6 --square <truth's board square_mm> --calibration camera.json --out plane.json
    servoscope identify campaign.toml --out res_image          # without the plane
    (add  plane = "plane.json"  to campaign.toml's [camera] table)
    servoscope identify campaign.toml --out res_plane          # with it

and result.json is compared with truth.json: K, ωn, ζ (relative error, %), the dead time (ms),
whether each 95 % interval (``model.ci95``) holds the truth, and the per-frame angle error against
the renderer's (truth.json's tests, in the plane) over every valid frame of every test, one
constant offset removed (RMS, degrees), read from the track CSVs ``identify`` writes. The ratio
is that RMS over the square-on camera's (same codec and settings, no plane). Deterministic
(fixed seeds). ``--quick``: raw only, square-on and 30° yaw. ``--more``: also square stickers,
480x384 and other sticker colours (raw and H.264 at a 30° view).

Prints one JSON line per scenario, then the table that docs/accuracy.md ("Oblique views and the
blade's plane") holds.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from servoscope.simulate import simulate_campaign

__all__ = ["SEED", "VIEWS", "angle_errors_deg", "main", "run_scenario"]

SEED = 0
#: (yaw, tilt) in degrees: square-on, then about 10°, 20° and 30° off square (view angle arccos(cos·cos)).
VIEWS = ((0.0, 0.0), (10.0, 0.0), (15.0, 13.0), (30.0, 0.0), (0.0, 30.0), (-25.0, 17.0))
CODECS = ("raw", "h264")
PARAMS = ("gain", "natural_frequency_rad_s", "damping_ratio", "dead_time_s")


def cli(*args: object, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """``servoscope ARGS`` as a user runs it (this interpreter's servoscope); raises on a non-zero exit."""
    proc = subprocess.run([sys.executable, "-m", "servoscope", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, timeout=1800)
    if proc.returncode != 0:
        raise RuntimeError(f"servoscope {' '.join(map(str, args))}: exit {proc.returncode}: {proc.stderr.strip()}")
    return proc


def add_plane(toml: Path, plane: str = "plane.json") -> None:
    """Add ``plane = "plane.json"`` to campaign.toml's [camera] table (what a user types in)."""
    text = toml.read_text()
    if re.search(r"^plane\s*=", text, flags=re.M):
        return
    toml.write_text(re.sub(r"^\[camera\]\n", f'[camera]\nplane = "{plane}"\n', text, count=1, flags=re.M))


def _track_angles(track_csv: Path) -> tuple[np.ndarray, np.ndarray]:
    """(angle_rad, valid) per frame from a track CSV written by ``identify``."""
    with track_csv.open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    angle = np.array([float(r["angle_rad"]) if r["angle_rad"] not in ("", "nan") else math.nan for r in rows])
    valid = np.array([r["valid"] in ("1", "True", "true") for r in rows]) & np.isfinite(angle)
    return angle, valid


def angle_errors_deg(result_dir: Path, truth: dict) -> np.ndarray:
    """Per-frame angle errors (deg) over every valid frame of every test, one constant offset removed.

    The measured angle differs from the plane's by one constant (the stickers' line is not the
    chord, and the rectified frame's rotation is arbitrary): the mean difference over the whole
    campaign is taken off (one constant, not one per test).
    """
    errs = []
    for test in truth["tests"]:
        angle, valid = _track_angles(result_dir / "tracks" / (Path(test["video"]).stem + ".csv"))
        true = np.asarray(test["angle_rad"], dtype=np.float64)
        errs.append(np.angle(np.exp(1j * (angle - true)))[valid])
    e = np.concatenate(errs)
    return np.degrees(e - np.mean(e))


def _model_row(result_dir: Path, truth: dict) -> dict:
    res = json.loads((result_dir / "result.json").read_text())
    model, true = res["model"], truth["model"]
    row = {}
    for name in PARAMS:
        value = model[name] if name != "dead_time_s" else res.get("dead_time_s", model.get("dead_time_s"))
        low, high = model["ci95"].get(name, (math.nan, math.nan)) if model.get("ci95") else (math.nan, math.nan)
        if value is None:
            row[name] = {"value": None, "error": None, "holds": False}
            continue
        err = (1e3 * (value - true[name])) if name == "dead_time_s" else 100.0 * (value / true[name] - 1.0)
        row[name] = {"value": value, "error": err, "ci95": [low, high],
                     "holds": bool(low is not None and high is not None and low <= true[name] <= high)}
    row["plane"] = res.get("plane")
    row["view_in_result"] = res.get("view")
    row["warnings"] = res.get("warnings", [])
    return row


def run_scenario(out: Path, name: str, view: tuple[float, float], codec: str, seed: int = SEED, **overrides) -> dict:
    """Render one campaign, run the commands with and without the plane, compare with truth."""
    slug = "".join(ch if ch.isalnum() else "_" for ch in name)
    t_start = time.perf_counter()
    toml = simulate_campaign(out / slug, preset="quick", seed=seed, codec=codec, view_yaw_deg=view[0],
                             view_tilt_deg=view[1], **overrides)
    folder = toml.parent
    truth = json.loads((folder / "truth.json").read_text())
    t_render = time.perf_counter() - t_start
    off_square = math.degrees(math.acos(math.cos(math.radians(view[0])) * math.cos(math.radians(view[1]))))
    row: dict = {"scenario": name, "view": list(view), "codec": codec, "view_angle_deg": off_square,
                 "render_s": round(t_render, 1)}
    cli("identify", toml, "--out", folder / "res_image", "--quiet")
    row["image"] = _model_row(folder / "res_image", truth)
    row["image_angle_rms_deg"] = float(np.sqrt(np.mean(angle_errors_deg(folder / "res_image", truth) ** 2)))
    if "board" in truth:
        cli("plane", folder / "board.png", "--board", "9x6", "--square", truth["board"]["square_mm"],
            "--calibration", folder / "camera.json", "--out", folder / "plane.json")
        add_plane(toml)
        cli("identify", toml, "--out", folder / "res_plane", "--quiet")
        row["plane"] = _model_row(folder / "res_plane", truth)
        row["plane_angle_rms_deg"] = float(np.sqrt(np.mean(angle_errors_deg(folder / "res_plane", truth) ** 2)))
        p = json.loads((folder / "plane.json").read_text())
        row["plane_json"] = {k: p[k] for k in ("view_angle_deg", "rms_px", "angle_gain_std")}
    row["total_s"] = round(time.perf_counter() - t_start, 1)
    return row


def _fmt(x: float | None, f: str) -> str:
    return "—" if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, f)


def table(rows: list[dict]) -> str:
    """The markdown table of docs/accuracy.md: errors with and without the plane, intervals, angle RMS ratio."""
    base = {(r["codec"], r.get("settings", "")): r["image_angle_rms_deg"] for r in rows if r["view"] == [0.0, 0.0]}
    head = ("| view (yaw, tilt) | off square | codec | K error, image | K error, plane | ωn error, plane | "
            "ζ error, plane | dead time error, plane (ms) | 95 % intervals holding the truth (plane) | "
            "angle RMS, plane (°) | ÷ square-on |")
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for r in rows:
        ref = base.get((r["codec"], r.get("settings", "")))
        m = r.get("plane") or r["image"]
        angle = r.get("plane_angle_rms_deg", r["image_angle_rms_deg"])
        holds = [n for n in PARAMS if m[n]["holds"]]
        said = "all" if len(holds) == len(PARAMS) else ("all but " + ", ".join(
            {"gain": "K", "natural_frequency_rad_s": "ωn", "damping_ratio": "ζ", "dead_time_s": "dead time"}[n]
            for n in PARAMS if n not in holds))
        # Square-on rows have no plane: their image numbers, in parentheses.
        def plane_or_dash(v, f, bare=bool(r.get("plane"))):
            return _fmt(v, f) if bare else "(" + _fmt(v, f) + ")"

        lines.append(
            f"| ({r['view'][0]:g}°, {r['view'][1]:g}°){(' ' + r['settings']) if r.get('settings') else ''} "
            f"| {r['view_angle_deg']:.1f}° | {r['codec']} "
            f"| {_fmt(r['image']['gain']['error'], '+.2f')} % "
            f"| {plane_or_dash(m['gain']['error'], '+.3f')} % "
            f"| {plane_or_dash(m['natural_frequency_rad_s']['error'], '+.3f')} % "
            f"| {plane_or_dash(m['damping_ratio']['error'], '+.3f')} % "
            f"| {plane_or_dash(m['dead_time_s']['error'], '+.2f')} "
            f"| {said if r.get('plane') else '(' + said + ')'} "
            f"| {angle:.4f} | {_fmt(angle / ref if ref else None, '.2f')} |")
    return "\n".join(lines)


def scenarios(quick: bool, more: bool) -> list[tuple[str, tuple[float, float], str, dict]]:
    out = []
    codecs = ("raw",) if quick else CODECS
    views = ((0.0, 0.0), (30.0, 0.0)) if quick else VIEWS
    for codec in codecs:
        for view in views:
            out.append((f"{codec} yaw {view[0]:g} tilt {view[1]:g}", view, codec, {}))
    if more:
        extra = {"square stickers": {"sticker_shape": "square"},
                 "480x384": {"width": 480, "height": 384},
                 "blue/orange stickers": {"lead_colour": "#1f77b4", "trail_colour": "#ff7f0e"}}
        for label, kw in extra.items():
            for codec in CODECS:
                for view in ((0.0, 0.0), (-25.0, 17.0)):
                    out.append((f"{label} {codec} yaw {view[0]:g} tilt {view[1]:g}", view, codec,
                                {"settings": label, **kw}))
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, help="Folder for the rendered footage (default: a temporary one).")
    parser.add_argument("--quick", action="store_true", help="Raw only, square-on and 30° yaw.")
    parser.add_argument("--more", action="store_true", help="Also square stickers, 480x384 and other colours.")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or Path(tmp)
        out.mkdir(parents=True, exist_ok=True)
        start = time.perf_counter()
        rows = []
        for name, view, codec, kw in scenarios(args.quick, args.more):
            kw = dict(kw)
            settings = kw.pop("settings", "")
            row = run_scenario(out, name, view, codec, **kw)
            row["settings"] = settings
            rows.append(row)
            print(json.dumps(row, default=float), flush=True)
        print(table(rows))
        print(f"# {time.perf_counter() - start:.0f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
