"""The command line's options and their checks: progress bar, frame-source options, held parameters, order, --out.

Helpers of :mod:`servoscope.cli`'s commands, which stay there.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import click

from .errors import ServoscopeError

__all__ = ["CampaignProgress", "check_out_dir", "footage_to_read", "frame_source_options", "parse_held", "parse_order",
           "parse_ties", "progress_enabled"]


def progress_enabled(quiet: bool) -> bool:
    """A progress bar unless ``--quiet`` or stderr is not a terminal."""
    return not quiet and sys.stderr.isatty()


class CampaignProgress:
    """A rich progress bar over a campaign's videos (videos done, frames/s, time left), or nothing."""

    def __init__(self, enabled: bool, tests):
        self.enabled = enabled
        self.tests = list(tests)
        self._bar = None
        self._frames: dict[str, int] = {}
        self._start = 0.0

    def __enter__(self):
        if self.enabled:
            import time

            from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

            self._bar = Progress(
                TextColumn("{task.description}"), BarColumn(), TextColumn("{task.completed}/{task.total} videos"),
                TimeRemainingColumn(), transient=True,
            )
            self._bar.__enter__()
            self._task = self._bar.add_task("tracking", total=len(self.tests))
            self._start = time.perf_counter()
        return self

    def __call__(self, label: str, frames_done: int, index: int) -> None:
        if self._bar is not None:
            import time

            self._frames[label] = frames_done
            total = sum(self._frames.values())
            rate = total / max(time.perf_counter() - self._start, 1e-9)
            self._bar.update(self._task, description=f"tracking {label}: {total} frames, {rate:.0f} frames/s")

    def done(self, label: str, status: str) -> None:
        if self._bar is not None:
            self._bar.advance(self._task)

    def __exit__(self, *exc):
        if self._bar is not None:
            self._bar.__exit__(*exc)
        return False


def frame_source_options(command):
    """--fps, --start, --timestamps, --bayer and --bits: what an image sequence or a raw file is read with."""
    for option in reversed([
        click.option("--fps", type=float, help="Frame rate of an image sequence (frames/s); overrides a raw file's header."),
        click.option("--start", "start_s", type=float, default=0.0, show_default=True,
                     help="Time of an image sequence's first frame, s."),
        click.option("--timestamps", type=click.Path(dir_okay=False, path_type=Path),
                     help="Text file with each frame's time (s), one per line, instead of --fps."),
        click.option("--bayer", type=click.Choice(["RGGB", "BGGR", "GRBG", "GBRG"], case_sensitive=False),
                     help="Bayer pattern of raw (undemosaiced) frames."),
        click.option("--bits", type=click.IntRange(1, 16),
                     help="The samples' real bit depth where the files do not say it (12-bit frames in 16-bit TIFFs)."),
    ]):
        command = option(command)
    return command


def footage_to_read(video: Path, *, fps: float | None, start_s: float, timestamps: Path | None, bayer: str | None,
             bits: int | None = None):
    """What to read for VIDEO with the frame-source options: (path or source string, name, default CSV path)."""
    from .video.frame_source import frame_source, is_frame_source, source_name

    given = fps is not None or start_s or timestamps is not None or bayer is not None or bits is not None
    if not is_frame_source(video):
        if given:
            raise ServoscopeError(f"{video}: --fps, --start, --timestamps, --bayer and --bits are for image sequences and "
                                  "raw files; a video's frame times come from its own timestamps")
        return video, video.name, video.with_name(video.stem + ".track.csv")
    if fps is not None and not (math.isfinite(fps) and fps > 0):
        raise ServoscopeError(f"{video}: --fps must be > 0 frames/s, got {fps}")
    source = frame_source(video, fps=fps, start_s=start_s, timestamps=None if timestamps is None else timestamps.resolve(),
                          bayer=None if bayer is None else bayer.upper(), bits=bits)
    name = source_name(source)
    import glob

    # Beside the folder of a sequence (the glob's last plain folder), beside a raw file.
    plain = [part for part in Path(str(video)).parts if not glob.has_magic(part)]
    return source, name, Path(*plain or ["."]).parent / f"{name}.track.csv"


def parse_held(fix_text: tuple[str, ...], bound_text: tuple[str, ...]
                ) -> tuple[dict[str, float], dict[str, tuple[float, float]]]:
    """``--fix NAME=VALUE`` and ``--bound NAME=LOW:HIGH`` as dicts; one clear error for anything else."""
    fix: dict[str, float] = {}
    bounds: dict[str, tuple[float, float]] = {}
    for text in fix_text:
        name, _, value = text.partition("=")
        try:
            fix[name.strip()] = float(value)
        except ValueError:
            raise ServoscopeError(f"--fix {text!r}: give NAME=VALUE, e.g. --fix damping_ratio=0.8") from None
    for text in bound_text:
        name, _, limits = text.partition("=")
        low, _, high = limits.partition(":")
        try:
            bounds[name.strip()] = (float(low), float(high))
        except ValueError:
            raise ServoscopeError(f"--bound {text!r}: give NAME=LOW:HIGH, e.g. --bound natural_frequency_rad_s=20:80") \
                from None
    return fix, bounds


def parse_order(text: str):
    """'auto', 'NA' or 'NB,NA' → "auto" or (nb, na), checked."""
    text = text.strip().lower()
    if text == "auto":
        return "auto"
    try:
        parts = [int(p) for p in text.replace(" ", "").split(",")]
    except ValueError:
        parts = []
    if len(parts) == 1:
        parts = [0, parts[0]]
    if len(parts) != 2 or not (0 <= parts[0] < parts[1] <= 4):
        raise ServoscopeError(f"--order {text!r}: use 'auto', NA (1–4) or NB,NA with 0 ≤ NB < NA ≤ 4")
    return tuple(parts)


def check_out_dir(out_dir: Path, manifest) -> None:
    """Refuse an --out whose outputs would overwrite an input."""
    inputs = {t.video.resolve() for t in manifest.tests} | {manifest.path.resolve()}
    out = out_dir.resolve()
    names = ["result.json", "report.html", "frequency_response.csv"] + [f"tracks/{t.label}.csv" for t in manifest.tests]
    for name in names:
        if (out / name).resolve() in inputs:
            raise ServoscopeError(f"--out {out_dir}: writing {name} there would overwrite an input; choose another folder")
    if out.exists() and not out.is_dir():
        raise ServoscopeError(f"--out {out_dir}: exists and is not a folder")


def parse_ties(tie_text: tuple[str, ...]) -> dict[str, str]:
    """``--tie NAME=EXPR`` as a dict; one clear error for anything else."""
    ties = {}
    for text in tie_text:
        name, _, expression = text.partition("=")
        if not name.strip() or not expression.strip():
            raise ServoscopeError(f"--tie {text!r}: give NAME=EXPR, e.g. --tie rate_limit_rad_s=4*gain")
        ties[name.strip()] = expression.strip()
    return ties
