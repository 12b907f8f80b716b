"""The ``servoscope`` command: a thin layer over the Python API.

Exit codes: 0 done; 2 bad input (one line on stderr, ``servoscope: error: …``);
1 an internal error.
"""

from __future__ import annotations

import json
import math
import os
import sys
from pathlib import Path

import click

from .defaults import LEAD_COLOUR, LED_COLOUR, TIMESTAMP, TIMESTAMPS, TRAIL_COLOUR
from .cli_options import (CampaignProgress, check_out_dir, footage_to_read, frame_source_options, parse_held,
                          parse_order, parse_ties, progress_enabled)
from .errors import ServoscopeError

__all__ = ["main", "cli"]


class _LazyGroup(click.Group):
    """A command group whose rarely used commands are imported only when run or listed.

    click's documented lazy-loading pattern: ``servoscope track`` should not
    pay the import of the rig driver or the benchmark on every start.
    """

    #: command name → "module:attribute" (relative to this package)
    lazy = {"plan": ".rig.cli:plan", "drive": ".rig.cli:drive", "bench": ".bench:bench"}

    def list_commands(self, ctx):
        return sorted(set(super().list_commands(ctx)) | set(self.lazy))

    def get_command(self, ctx, name):
        if name in self.lazy:
            import importlib

            module, attr = self.lazy[name].split(":")
            return getattr(importlib.import_module(module, __package__), attr)
        return super().get_command(ctx, name)


@click.group(cls=_LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="servoscope", prog_name="servoscope")
def cli() -> None:
    """Measure an actuator's transfer function from video of two coloured markers."""


@cli.command()
@click.argument("outdir", type=click.Path(file_okay=False, path_type=Path))
@click.option("--preset", default="paper", show_default=True, help="Campaign preset: paper, quick, paper-flap (a flapping blade), paper-bend (the same blade bending, seen by two more stickers), paper-nonlinear (the paper's puzzle: linkage play), paper-sweep (one 12 s logarithmic sweep, 0.5–15 Hz), paper-rotor (a two-bladed rotor turning at 20 rev/s, filmed side-on at 4,000 frames/s, docs/twin.md).")
@click.option("--seed", default=0, show_default=True, type=int, help="Random seed: same seed, same footage.")
@click.option("--codec", type=click.Choice(["h264", "hevc", "mpeg2", "raw"]),
              help="Video codec (preset's: h264; hevc: phones' H.265; mpeg2: HDV's, the paper's camera).")
@click.option("--bit-rate", type=click.IntRange(min=100_000), help="H.264 or MPEG-2 bit rate, bit/s (preset's: 20000000, a camcorder's; HDV: 25000000).")
@click.option("--fps", type=click.FloatRange(min=1.0), help="Frame rate, frames/s (preset's: 100).")
@click.option("--exposure", "exposure_s", type=click.FloatRange(min=0.0, min_open=True),
              help="Exposure time, s (preset's: one frame interval).")
@click.option("--readout", "readout_s", type=click.FloatRange(min=0.0),
              help="Rolling-shutter readout time, s, < the frame interval (preset's: 0, a global shutter).")
@click.option("--gop", type=click.IntRange(min=1),
              help="Frames from one I-frame to the next (codec's default: 250 for h264, 15 for mpeg2).")
@click.option("--flicker-hz", type=click.FloatRange(min=0.0), help="Lamp flicker frequency, Hz (mains lamps: 100 or 120).")
@click.option("--flicker-depth", type=click.FloatRange(min=0.0, max=1.0, max_open=True),
              help="Lamp flicker depth: light 1 + depth·sin(2π f t) (preset's: 0, steady lamps).")
@click.option("--flicker-phase", "flicker_phase_rad", type=float,
              help="The lamps' phase at t = 0, rad (preset's: drawn from the seed).")
@click.option("--shake", "shake_px", type=click.FloatRange(min=0.0),
              help="Camera shake, RMS px per axis of a smooth translation of the picture (preset's: 0).")
@click.option("--shake-frames", "shake_smooth_frames", type=click.FloatRange(min=0.0, min_open=True),
              help="Correlation length of the shake, frames (preset's: 5).")
@click.option("--t0-phase", "t0_frame_phase", type=click.FloatRange(min=0.0, max=1.0, max_open=True),
              help="The input's start as a fraction of its frame interval, the same in every test "
                   "(preset's: drawn per test).")
@click.option("--no-manifest-exposure", "manifest_exposure", flag_value=False, default=None,
              help="Leave exposure_s out of campaign.toml (a user who does not know the shutter).")
@click.option("--motion-blur", flag_value=True, default=None,
              help="Render the exposure's real motion blur (global shutter only).")
@click.option("--timestamp-at", type=click.Choice(TIMESTAMPS),
              help=f"Which instant of the exposure a frame's timestamp marks (preset's: {TIMESTAMP}).")
@click.option("--sticker-shape", type=click.Choice(["disc", "square", "strip"]), help="Sticker shape (preset's: disc).")
@click.option("--sticker-aspect", type=click.FloatRange(min=0.0, min_open=True),
              help="Sticker length along the chord / width (preset's: 1; a strip's: 4).")
@click.option("--frames", "frames_format", type=click.Choice(["tiff16"]),
              help="Write each test as a folder of frames instead of a video (tiff16: 16-bit RGB TIFFs, as "
                   "high-speed cameras save); campaign.toml then gives frames and fps.")
@click.option("--view-yaw", "view_yaw_deg", type=float,
              help="An oblique camera: turned about the blade plane's vertical axis, degrees, under 80 "
                   "(positive: to the blade's right; preset's: 0, square-on). Writes board.png too.")
@click.option("--view-tilt", "view_tilt_deg", type=float,
              help="Then turned about its horizontal axis, degrees, under 80 (positive: up, looking down; "
                   "preset's: 0).")
def simulate(outdir: Path, preset: str, seed: int, codec: str | None, bit_rate: int | None, fps: float | None,
             exposure_s: float | None, readout_s: float | None, gop: int | None, **camera_options) -> None:
    """Render a campaign with a known answer (the digital twin) into OUTDIR.

    The real-camera options (flicker, shake, blur, ...) are described in docs/twin.md.
    """
    from .simulate import simulate_campaign

    given = {"codec": codec, "bit_rate": bit_rate, "fps": fps, "exposure_s": exposure_s, "readout_s": readout_s,
             "gop": gop, **camera_options}
    from .simulate.rotor_campaign import ROTOR_PRESETS

    if fps is not None and exposure_s is None and preset not in ROTOR_PRESETS:
        # The preset's exposure is one interval of its own frame rate; keep it one interval of this one.
        # (A rotor's preset keeps its short shutter: a whole frame interval would blur a tip passing at
        # 38 m/s over tens of pixels.)
        given["exposure_s"] = 1.0 / fps
    from ._io import staged_folder

    with staged_folder(outdir, last=("campaign.toml",)) as stage:  # whole or not at all
        manifest = simulate_campaign(stage, preset=preset, seed=seed, **{k: v for k, v in given.items() if v is not None})
    click.echo(f"wrote {outdir / manifest.name}")


@cli.command()
@click.argument("video", type=click.Path(path_type=Path))
@click.option("--lead", default=LEAD_COLOUR, show_default=True,
              help="Leading-edge marker colour (#rrggbb, CSS name, auto); '#rrggbb@x,y' pins it to the blob at "
                   "pixel (x, y) of the first frame.")
@click.option("--trail", default=TRAIL_COLOUR, show_default=True, help="Trailing-edge marker colour (@x,y pins it).")
@click.option("--led", default=LED_COLOUR, show_default=True, help="LED colour (COLOUR@x,y or bright@x,y pins it by position); 'none' when there is no LED.")
@click.option("--calibration", type=click.Path(path_type=Path), help="camera.json for undistorting centroids.")
@click.option("--exposure", "exposure_s", type=float,
              help="Exposure (shutter) time in seconds, for the LED's sub-frame timing; leave out when not known "
                   "(t0 is then only dated to within the frames' gap).")
@click.option("--readout", "readout_s", type=float, default=0.0, show_default=True,
              help="Rolling-shutter readout time in seconds (top to bottom row); 0 = global shutter.")
@click.option("--timestamp", type=click.Choice(TIMESTAMPS), default=TIMESTAMP, show_default=True,
              help="Which point of its exposure a frame's timestamp marks.")
@click.option("--out", "out_csv", type=click.Path(dir_okay=False, path_type=Path), help="Track CSV to write [default: VIDEO.track.csv].")
@click.option("--deinterlace", type=click.Choice(["none", "fields", "fields-bff"]), default="none", show_default=True,
              help="Split interlaced frames into fields (double rate; 'fields' = top field first).")
@click.option("--overlay", type=click.Path(dir_okay=False, path_type=Path),
              help="Also write the footage with the centroids, joining line and angle drawn (.mp4 or .mov).")
@click.option("--reference", metavar="COLOUR,COLOUR",
              help="Two stickers on the airframe: the angle is measured against the line joining them "
                   "(takes out camera roll and shake, a phone's stabilisation, the airframe's rocking).")
@click.option("--extra", "extra", metavar="COLOUR", multiple=True,
              help="Another sticker on the blade (repeat for more), each its own colour: the track gets each "
                   "marker's bending across the lead–trail line.")
@click.option("--plane", "plane_json", type=click.Path(dir_okay=False, path_type=Path),
              help="plane.json (servoscope plane): angles, separation, heave and bending measured in the blade's "
                   "plane, true for a camera that is not square-on.")
@click.option("--self-calibrate-plane", is_flag=True,
              help="Without a plane: correct the angles for the camera's view as the stickers tell it "
                   "(stickers' shapes and sizes: foreshortening and perspective; round or square stickers of one size).")
@frame_source_options
def track(video: Path, lead: str, trail: str, led: str, calibration: Path | None, exposure_s: float | None,
          readout_s: float, timestamp: str, out_csv: Path | None, deinterlace: str, overlay: Path | None,
          reference: str | None, extra: tuple[str, ...], plane_json: Path | None, self_calibrate_plane: bool,
          **source) -> None:
    """Track the two markers through VIDEO and write the per-frame angles.

    VIDEO is a video file, a folder or quoted glob of TIFF/PNG/JPEG frames
    (with --fps), or a Photron .mraw/.cihx or Phantom .cine file.
    """
    video, name, default_csv = footage_to_read(video, **source)
    from ._io import staged_files
    from .camera import CameraModel
    from .markers import TrackerSettings, parse_colour
    from .pipeline import track_video
    from .markers.selection import parse_marker_spec
    from .cli_plane import load_plane_option, track_in_view
    from .cli_track_checks import refuse_too_few_valid

    lead, lead_near = parse_marker_spec(lead, what="--lead")
    trail, trail_near = parse_marker_spec(trail, what="--trail")
    for spec, what in ((lead, "--lead"), (trail, "--trail")):
        parse_colour(spec, what=what)
    led_spec, led_near = (None, None) if led.lower() == "none" else parse_marker_spec(led, what="--led")
    if led_spec:
        parse_colour(led_spec, what="--led")
    reference_pair = None
    if reference is not None:
        parts = [c.strip() for c in reference.split(",")]
        if len(parts) != 2 or parts[0].lower() == parts[1].lower():
            raise ServoscopeError(f"--reference {reference!r}: give two different colours, e.g. "
                                  "--reference '#e377c2,#17becf'")
        for part in parts:
            if parse_colour(part, what="--reference") == "auto":
                raise ServoscopeError("--reference: give the airframe stickers' colours, not auto")
        reference_pair = (parts[0], parts[1])
    camera = CameraModel.load(calibration) if calibration else None
    plane = load_plane_option(plane_json, self_calibrate_plane)
    if self_calibrate_plane and overlay is not None:
        raise ServoscopeError("--overlay with --self-calibrate-plane: the corrected positions are not the picture's; "
                              "draw the overlay from a track without the correction")
    if exposure_s is not None and not exposure_s > 0:
        raise ServoscopeError(f"{video}: --exposure must be > 0 (s), got {exposure_s}; leave it out when not known")
    if not (math.isfinite(readout_s) and readout_s >= 0):
        raise ServoscopeError(f"--readout must be a time >= 0 in seconds, got {readout_s}")
    if overlay is not None and overlay.suffix.lower() not in (".mp4", ".mov"):
        raise ServoscopeError(f"--overlay {overlay}: must end in .mp4 or .mov")
    if overlay is not None and overlay.resolve() == Path(str(video)).resolve():
        raise ServoscopeError(f"--overlay {overlay}: would overwrite the footage itself; choose another file")
    settings = TrackerSettings(lead, trail, led_spec, camera, exposure_s,
                               deinterlace=None if deinterlace == "none" else deinterlace, readout_s=readout_s,
                               lead_near=lead_near, trail_near=trail_near, led_near=led_near, timestamp=timestamp,
                               reference=reference_pair, extra=tuple(extra), plane=plane)
    result = track_video(video, settings)
    refuse_too_few_valid(str(video), result)  # a handful of rows is no measurement: an error, no CSV
    result = track_in_view(name, result, self_calibrate_plane, settings.camera, plane)
    from .video.reader import probe_video

    note = probe_video(video).conversion_note()
    if note:
        click.echo(f"{name}: {note}")
    if out_csv is None:
        out_csv = default_csv
    out_csv.parent.mkdir(parents=True, exist_ok=True)
    if overlay is not None:
        overlay.parent.mkdir(parents=True, exist_ok=True)
    with staged_files(out_csv, overlay) as (tmp_csv, tmp_overlay):  # both written, or neither
        result.to_csv(tmp_csv)
        if overlay is not None:
            from .pipeline.overlay import write_overlay

            write_overlay(video, result, tmp_overlay, camera=camera, plane=plane)
    from .cli_tables import print_track_counts

    print_track_counts(name, result, out_csv)
    _say_frame_of_reference_and_shutter(name, result, exposure_s)
    for w in result.warnings:
        click.echo(f"warning: {w}", err=True)
    if overlay is not None:
        click.echo(f"wrote {overlay}")


def _say_frame_of_reference_and_shutter(name: str, result, exposure_s: float | None) -> None:
    """The track's lines beyond the counts: the reference line's turn (or a moving pitch axis), the shutter."""
    if result.reference_angle_rad is None:
        from .angle.pivot import axis_moved

        pivot = axis_moved(result)
        if pivot is not None:
            click.echo(f"warning: the blade's pitch axis moved by {pivot.rms_px:.2f} px RMS in the picture (camera "
                       "shake or roll, or the airframe rocking): a turn of the camera or the airframe is read as pitch; "
                       "film two stickers on the airframe and give them with --reference", err=True)
    elif (motion := result.reference_motion()) is not None:
        click.echo(f"{name}: the reference line turned by {math.degrees(motion['peak_to_peak']):.3f}° peak to peak "
                   f"({math.degrees(motion['rms']):.3f}° RMS); taken off the angle")
    if exposure_s is None:
        # The camera stage's reading of this video's shutter (a campaign pools every video's).
        from .camera.exposure import blur_evidence

        click.echo(f"{name}: exposure: {blur_evidence(result).describe()}")


@cli.command()
@click.argument("footage", type=click.Path(path_type=Path))
@click.option("--json", "as_json", is_flag=True, help="Print the description as JSON.")
@frame_source_options
def info(footage: Path, as_json: bool, **source) -> None:
    """Say what servoscope reads from FOOTAGE: format, size, frames, frame rate and where it came from, bit depth."""
    from .video.info import describe_footage, format_description

    path, _, _ = footage_to_read(footage, **source)
    described = describe_footage(path)
    if as_json:
        import json

        click.echo(json.dumps(described, indent=2))
    else:
        click.echo(format_description(described))


@cli.command()
@click.argument("video", type=click.Path(path_type=Path))
@click.option("--frame", "frame_index", default=0, show_default=True, type=int, help="Frame to look at (0-based).")
@click.option("--out", "out_png", type=click.Path(dir_okay=False, path_type=Path), help="Picture with the candidates numbered (PNG).")
@frame_source_options
def markers(video: Path, frame_index: int, out_png: Path | None, **source) -> None:
    """List the coloured blobs (on monochrome footage: the bright ones) in a frame of VIDEO, to choose the markers."""
    video, name, _ = footage_to_read(video, **source)
    import cv2

    from .cli_tables import print_candidates
    from .markers.candidates import draw_candidates
    from .video import iter_frames

    if frame_index < 0:
        raise ServoscopeError(f"--frame must be ≥ 0, got {frame_index}")
    chosen = None
    for frame in iter_frames(video):
        if frame.index == frame_index:
            chosen = frame
            break
    if chosen is None:
        raise ServoscopeError(f"{video}: has no frame {frame_index}")
    found = print_candidates(f"{name}, frame {frame_index} (t = {chosen.time_s:.3f} s)", chosen.rgb)
    if out_png is not None:
        from ._io import atomic_path

        out_png.parent.mkdir(parents=True, exist_ok=True)
        picture = draw_candidates(chosen.rgb, found)
        with atomic_path(out_png) as tmp:
            if not cv2.imwrite(str(tmp), cv2.cvtColor(picture, cv2.COLOR_RGB2BGR)):
                raise ServoscopeError(f"{out_png}: cannot write the picture")
        click.echo(f"wrote {out_png}")


@cli.command()
@click.argument("campaign", type=click.Path(path_type=Path))
@click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path), required=True, help="Folder for result.json, report.html, tracks/.")
@click.option("--fit", "fit_mode", type=click.Choice(["auto", "magnitude", "complex"]), default="auto", show_default=True,
              help="magnitude: |G| only (the paper's); complex: magnitude and phase with a dead time; auto: complex when every dwell's input start is known.")
@click.option("--order", "order_text", default="2", show_default=True,
              help="Model order: NA (denominator degree, no zeros), NB,NA (nb < na ≤ 4), or 'auto' (chosen from the data).")
@click.option("--bootstrap", default=0, show_default=True, type=click.IntRange(min=0),
              help="Also give 95 %% intervals from this many bootstrap resamplings of the dwells.")
@click.option("--keep-going", is_flag=True, help="Leave out videos that cannot be read or tracked (with a warning) and identify from the rest.")
@click.option("--workers", default=0, show_default=True, type=click.IntRange(min=0),
              help="Videos tracked in parallel by a local Dask cluster of this many processes; 0 = one per core; 1 = in this process, no Dask.")
@click.option("--scheduler", help="Send the tracking to an existing Dask cluster (tcp://HOST:PORT); videos must be on a path the workers share.")
@click.option("--force", is_flag=True, help="Track again even where a cached track exists (tracks are cached in OUT/.cache).")
@click.option("--quiet", is_flag=True, help="No progress bar.")
@click.option("--json", "as_json", is_flag=True, help="Print result.json to stdout.")
@click.option("--fix", "fix_text", multiple=True, metavar="NAME=VALUE",
              help="Hold a model parameter at a value (e.g. damping_ratio=0.8); repeatable.")
@click.option("--bound", "bound_text", multiple=True, metavar="NAME=LOW:HIGH",
              help="Keep a model parameter within limits (e.g. natural_frequency_rad_s=20:80); repeatable.")
@click.option("--tie", "tie_text", multiple=True, metavar="NAME=EXPR",
              help="Compute a parameter from others in the time-domain fits, as lmfit's expr (e.g. "
                   "rate_limit_rad_s=4*gain); needs --nonlinear; repeatable.")
@click.option("--nonlinear", type=click.Choice(["none", "auto", "linear", "rate_limit", "backlash", "quantization",
                                                "saturation"]), default="none", show_default=True,
              help="Also fit models to the dwells' and the step's whole traces: linear, one nonlinear structure beside "
                   "it, or auto (every structure, selected by BIC). none: the frequency-domain fit alone.")
@click.option("--self-calibrate-plane", is_flag=True,
              help="Without [camera] plane: correct the angles for the camera's view as the stickers tell "
                   "them (shapes and sizes: round or square stickers of one size), the gain's interval widened by its "
                   "uncertainty.")
@click.option("--beside", "beside", type=click.Path(path_type=Path), metavar="STATIC_OUT/result.json",
              help="A turning rotor's campaign: the same servo's static identification (the result.json, or its "
                   "folder, that identify wrote for a campaign without [rotor]); the report's \"Under rotation\" "
                   "shows both frequency responses and K, ωn, ζ, τ static against rotating with their differences.")
def identify(campaign: Path, out_dir: Path, fit_mode: str, order_text: str, bootstrap: int, keep_going: bool,
             workers: int, scheduler: str | None, force: bool, quiet: bool, as_json: bool, fix_text: tuple[str, ...],
             bound_text: tuple[str, ...], tie_text: tuple[str, ...], nonlinear: str, self_calibrate_plane: bool,
             beside: Path | None) -> None:
    """Identify the transfer function from a CAMPAIGN manifest (campaign.toml)."""
    from .campaign import identify as run_identify
    from .campaign import load_campaign, track_campaign
    from .campaign.runner import checked_holds
    from .cli_tables import print_model
    from .report import write_report

    order = parse_order(order_text)
    fix, bounds = parse_held(fix_text, bound_text)
    ties = parse_ties(tie_text)
    manifest = load_campaign(campaign, keep_going=keep_going)  # validates everything before --out is touched
    checked_holds(manifest, order, nonlinear, fix, bounds, ties)  # identify's own check, before any tracking
    if self_calibrate_plane and manifest.plane is not None:
        raise ServoscopeError(f"{campaign}: [camera] plane is given: --self-calibrate-plane is for footage without a "
                              "plane; leave one of them out")
    static = None
    if beside is not None:  # read and checked before any tracking
        from .campaign.compare import load_static_result

        if manifest.rotor is None:
            raise ServoscopeError(f"{campaign}: --beside compares a turning rotor's campaign (one with [rotor]) with "
                                  "a static one; this campaign has no [rotor]")
        static = load_static_result(beside)
    check_out_dir(out_dir, manifest)
    from ._io import staged_folder

    failures: dict[str, str] = {}
    # Built aside and moved into place whole (the track cache, .cache, is written in place and kept).
    with staged_folder(out_dir, keep=(".cache",), last=("result.json",)) as stage:
        tracks, rotor_progress = None, None
        with CampaignProgress(progress_enabled(quiet), manifest.tests) as progress:
            if manifest.rotor is None:
                tracks = track_campaign(
                    manifest, keep_going=keep_going, failures=failures, progress=progress, on_done=progress.done,
                    workers=None if workers == 0 else workers, scheduler=scheduler, cache_dir=out_dir / ".cache",
                    force=force,
                )
            else:  # a turning rotor's videos are read pass by pass inside identify
                rotor_progress = progress
                result = run_identify(manifest, fit=fit_mode, order=order, bootstrap=bootstrap, keep_going=keep_going,
                                      fix=fix or None, bounds=bounds or None, nonlinear=nonlinear, ties=ties or None,
                                      self_calibrate_plane=self_calibrate_plane, progress=rotor_progress)
        if failures:
            manifest = manifest.without(failures)
        if rotor_progress is None:
            result = run_identify(manifest, tracks=tracks, fit=fit_mode, order=order, bootstrap=bootstrap,
                                  keep_going=keep_going, fix=fix or None, bounds=bounds or None, nonlinear=nonlinear,
                                  ties=ties or None, self_calibrate_plane=self_calibrate_plane)
        if static is not None:
            from .campaign.compare import with_static_comparison

            result = with_static_comparison(result, static, static_path=beside)
        write_report(result, stage)
    if as_json:
        click.echo(json.dumps(result.summary(), indent=2))
    elif not quiet:
        print_model(result)
        if static is not None:
            from .campaign.compare import ResultComparison

            compared = ResultComparison.from_summary(result.rotor["beside_static"])
            click.echo(f"beside the static campaign ({compared.static_path}), rotating − static:")
            for line in compared.describe():
                click.echo(f"  {line}")
        click.echo(f"report: {out_dir / 'report.html'}")


@cli.command()
@click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path), default=Path("demo-out"), show_default=True)
@click.option("--preset", default="paper", show_default=True)
@click.option("--seed", default=0, show_default=True, type=int)
@click.option("--quiet", is_flag=True)
def demo(out_dir: Path, preset: str, seed: int, quiet: bool) -> None:
    """Simulate the paper's campaign, identify it, and compare with the truth."""
    from .campaign import identify as run_identify
    from .campaign import load_campaign
    from .cli_tables import print_model
    from ._io import staged_folder
    from .report import write_report
    from .simulate import simulate_campaign

    click.echo(f"rendering the '{preset}' campaign (digital twin) into {out_dir / 'campaign'} …")
    # Each folder whole or not at all: the campaign is in place before it is read (result.json names it).
    with staged_folder(out_dir / "campaign", last=("campaign.toml",)) as stage:
        manifest_path = out_dir / "campaign" / simulate_campaign(stage, preset=preset, seed=seed).name
    manifest = load_campaign(manifest_path)
    click.echo(f"tracking {len(manifest.tests)} videos and identifying …")
    with staged_folder(out_dir / "result", last=("result.json",)) as stage:
        with CampaignProgress(progress_enabled(quiet), manifest.tests) as progress:
            result = run_identify(manifest, progress=progress)
        write_report(result, stage)
    truth = json.loads((manifest_path.parent / "truth.json").read_text())
    print_model(result, truth)
    click.echo(f"report: {out_dir / 'result' / 'report.html'}")
    click.echo(f"result: {out_dir / 'result' / 'result.json'}")


@cli.command()
@click.argument("inputs", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("--board", required=True, help="Inner corners of the chessboard, COLSxROWS, e.g. 9x6.")
@click.option("--square", "square_size", default=1.0, show_default=True, type=float, help="Square size (any unit).")
@click.option("--out", "out_json", required=True, type=click.Path(dir_okay=False, path_type=Path), help="camera.json to write.")
def calibrate(inputs: tuple[Path, ...], board: str, square_size: float, out_json: Path) -> None:
    """Calibrate the camera from chessboard photos or videos (INPUTS)."""
    from .camera.calibrate import calibrate as run_calibrate
    from .camera.calibrate import parse_board

    result = run_calibrate(list(inputs), parse_board(board), square_size=square_size)
    out_json.parent.mkdir(parents=True, exist_ok=True)
    result.save(out_json)
    click.echo(f"{len(result.views_used)} views used, RMS reprojection error {result.rms_reprojection_error_px:.3f} px; wrote {out_json}")
    for name, reason in result.skipped:
        click.echo(f"skipped {name}: {reason}", err=True)


@cli.command()
@click.argument("inputs", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("--board", required=True, help="Inner corners of the chessboard, COLSxROWS, e.g. 9x6.")
@click.option("--square", "square_mm", required=True, type=float, help="Side of one square, mm.")
@click.option("--calibration", type=click.Path(dir_okay=False, path_type=Path), help="camera.json: corners undistorted, view angle from the board's pose.")
@click.option("--out", "out_json", required=True, type=click.Path(dir_okay=False, path_type=Path), help="plane.json to write.")
def plane(inputs: tuple[Path, ...], board: str, square_mm: float, calibration: Path | None, out_json: Path) -> None:
    """Calibrate the blade's plane from photos or videos of a chessboard held flat against it (INPUTS)."""
    from .camera.model import CameraModel
    from .camera.plane import calibrate_plane

    camera = None if calibration is None else CameraModel.load(calibration)
    result = calibrate_plane(list(inputs), board, square_mm=square_mm, camera=camera)
    out_json.parent.mkdir(parents=True, exist_ok=True)
    result.save(out_json)
    click.echo("\n".join([*result.describe(), f"wrote {out_json}"]))
    for name, reason in result.skipped:
        click.echo(f"skipped {name}: {reason}", err=True)


def main(argv: list[str] | None = None) -> None:
    """Entry point: runs the command and maps errors to exit codes."""
    try:
        cli.main(args=argv, prog_name="servoscope", standalone_mode=False)
    except ServoscopeError as exc:
        click.echo(f"servoscope: error: {exc}", err=True)
        sys.exit(2)
    except click.exceptions.Abort:
        click.echo("servoscope: interrupted", err=True)
        sys.exit(130)
    except click.ClickException as exc:
        click.echo(f"servoscope: error: {exc.format_message()}", err=True)
        sys.exit(2)
    except KeyboardInterrupt:
        click.echo("servoscope: interrupted", err=True)
        sys.exit(130)
    except Exception as exc:  # an internal error: say so in one line, traceback on request
        if os.environ.get("SERVOSCOPE_DEBUG"):
            raise
        click.echo(f"servoscope: internal error: {type(exc).__name__}: {exc} (set SERVOSCOPE_DEBUG=1 for the traceback)", err=True)
        sys.exit(1)
    sys.exit(0)
