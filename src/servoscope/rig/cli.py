"""The ``servoscope plan`` and ``servoscope drive`` commands.

They are plain :class:`click.Command` objects; the main group registers them
with ``cli.add_command(plan)`` and ``cli.add_command(drive)``. Bad input raises
:class:`~servoscope.errors.ServoscopeError`, which the main entry point turns
into ``servoscope: error: …`` and exit status 2.
"""

from __future__ import annotations

from pathlib import Path

import click

from ..defaults import LEAD_COLOUR, LED_COLOUR, MIN_DWELL_S, SETTLE_S, TRAIL_COLOUR
from .chirp import DEFAULT_NOISE_DEG
from .protocols import PROTOCOLS

__all__ = ["plan", "drive"]


@click.command("plan")
@click.option("--fps", type=float, required=True, help="Camera frame rate, frames/s.")
@click.option("--from", "from_hz", type=float, help="Lowest dwell frequency, Hz (sine dwells; required without --sweep).")
@click.option("--to", "to_hz", type=float, help="Highest dwell frequency, Hz (sine dwells; required without --sweep).")
@click.option("--points", default=14, show_default=True, type=int, help="Number of log-spaced frequencies.")
@click.option("--sweep", "sweep_text", metavar="F0:F1",
              help="Instead of sine dwells, one frequency sweep (chirp) from F0 to F1 Hz, e.g. 0.5:20; needs --duration.")
@click.option("--duration", "duration_s", type=float,
              help="Sweep duration, s (rounded up to a whole number of cycles, so the command ends at 0).")
@click.option("--sweep-shape", type=click.Choice(["log", "linear"]), default="log", show_default=True,
              help="Sweep shape: log (equal time per octave) or linear.")
@click.option("--noise-deg", type=float, default=DEFAULT_NOISE_DEG, show_default=True,
              help="Per-frame angle noise of the track, degrees: sets the sweep's expected coherence "
                   "(`servoscope track` prints the measured one).")
@click.option("--record-seconds", "record_s", type=float,
              help="Longest recording the camera makes, s: a sweep whose lead-in, sweep and tail exceed it is refused.")
@click.option("--amplitude", default=0.1, show_default=True, type=float, help="Sine or sweep amplitude, input units.")
@click.option("--amplitudes", "amplitudes_text", metavar="A,B,…",
              help="Amplitude as a test axis: dwells at every frequency for each amplitude (e.g. 0.05,0.1,0.2); "
                   "identify compares each frequency's gains (the linearity check).")
@click.option("--periods", default=8.0, show_default=True, type=float, help="Periods per dwell after settling.")
@click.option("--min-seconds", default=MIN_DWELL_S, show_default=True, type=float, help="Shortest input duration, s.")
@click.option("--settle", "settle_s", default=SETTLE_S, show_default=True, type=float,
              help="Settling time after the input starts, s (also [analysis] settle_s).")
@click.option("--update-hz", default=50.0, show_default=True, type=float,
              help="Command update rate: the servo's PWM rate, Hz.")
@click.option("--step/--no-step", default=True, show_default=True, help="End with a step test.")
@click.option("--step-amplitude", default=0.5, show_default=True, type=float, help="Step size, input units.")
@click.option("--step-seconds", default=3.0, show_default=True, type=float, help="Step duration, s.")
@click.option("--lead-in", "lead_in_s", default=1.0, show_default=True, type=float,
              help="Servo centred, LED lit, camera rolling before the input starts, s.")
@click.option("--tail", "tail_s", default=0.5, show_default=True, type=float,
              help="Servo centred after the input before the camera stops, s.")
@click.option("--rest", "rest_s", default=2.0, show_default=True, type=float, help="Wait between dwells, s.")
@click.option("--lead", default=LEAD_COLOUR, show_default=True, help="Leading-edge marker colour.")
@click.option("--trail", default=TRAIL_COLOUR, show_default=True, help="Trailing-edge marker colour.")
@click.option("--led", default=LED_COLOUR, show_default=True, help="LED colour.")
@click.option("--units", default="normalized", show_default=True, help="Label of the input's units.")
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), default=Path("plan.toml"),
              show_default=True, help="Plan file to write.")
@click.option("--rotor-hz", "rotor_hz", type=float,
              help="A turning rotor, rev/s: its blades' pitch is read once a revolution each, so the dwells stay "
                   "below the passes' Nyquist frequency (blades × rev/s / 2); --to defaults to 70 % of it.")
@click.option("--blades", "n_blades", type=int, help="Blades on the rotor (with --rotor-hz; default 2).")
@click.option("--blade-colours", "blade_colours", help="Each blade's sticker colours, blade 0 first, as "
              "LEAD/TRAIL,LEAD/TRAIL (with --rotor-hz; default the twin's: red/green, blue/magenta, cyan/orange).")
def plan(fps: float, from_hz: float, to_hz: float, points: int, amplitude: float, periods: float,
         min_seconds: float, settle_s: float, update_hz: float, step: bool, step_amplitude: float,
         step_seconds: float, lead_in_s: float, tail_s: float, rest_s: float, lead: str, trail: str,
         led: str, units: str, out: Path, amplitudes_text: str | None, sweep_text: str | None,
         duration_s: float | None, sweep_shape: str, noise_deg: float, record_s: float | None,
         rotor_hz: float | None = None, n_blades: int | None = None, blade_colours: str | None = None) -> None:
    """Plan the tests and write a campaign.toml without videos.

    Log-spaced sine dwells (--from, --to, --points), or one frequency sweep
    (--sweep F0:F1 --duration S), then a step test unless --no-step. For a sweep
    the plan prints the coherence expected at the top frequency for the angle
    noise given (--noise-deg) and warns below 0.6. For a turning rotor (--rotor-hz,
    --blades) the dwells stay below the passes' Nyquist frequency, up to 70 % of it.
    """
    from ..errors import ServoscopeError
    from ..markers.colour import parse_colour
    from .chirp import plan_chirp, sweep_coherence
    from .plan import plan_sweep, write_plan

    amplitudes = None
    if amplitudes_text is not None:
        try:
            amplitudes = [float(a) for a in amplitudes_text.split(",")]
        except ValueError:
            raise ServoscopeError(f"--amplitudes {amplitudes_text!r}: give numbers separated by commas, e.g. "
                                  "0.05,0.1,0.2") from None

    for option, colour in (("--lead", lead), ("--trail", trail), ("--led", led)):
        parse_colour(colour, what=option)
    markers = {"lead": lead, "trail": trail, "led": led}
    if blade_colours is not None and rotor_hz is None:
        raise ServoscopeError("--blade-colours goes with --rotor-hz (a turning rotor's speed, rev/s)")
    if n_blades is not None and rotor_hz is None:
        raise ServoscopeError("--blades goes with --rotor-hz (a turning rotor's speed, rev/s)")
    if rotor_hz is not None and sweep_text is not None:
        raise ServoscopeError("--rotor-hz plans sine dwells below the passes' Nyquist frequency: drop --sweep")
    if rotor_hz is not None:
        from .rotor_plan import plan_rotor_sweep

        if duration_s is not None or record_s is not None:
            raise ServoscopeError("--duration and --record-seconds go with --sweep")
        sweep = plan_rotor_sweep(
            fps, rotor_hz, n_blades, from_hz=from_hz, to_hz=to_hz, points=points,
            amplitude=amplitude, periods=periods, min_seconds=min_seconds, settle_s=settle_s, update_hz=update_hz, step=step,
            step_amplitude=step_amplitude, step_seconds=step_seconds, lead_in_s=lead_in_s, tail_s=tail_s,
            rest_s=rest_s, markers=markers, units=units, amplitudes=amplitudes,
            blades=blade_colours,
        )
    elif sweep_text is not None:
        if from_hz is not None or to_hz is not None or amplitudes is not None:
            raise ServoscopeError("--sweep plans one sweep instead of sine dwells: drop --from, --to and --amplitudes")
        if duration_s is None:
            raise ServoscopeError(f"--sweep {sweep_text}: give its --duration in seconds")
        try:
            sweep_from_hz, sweep_to_hz = (float(v) for v in sweep_text.split(":"))
        except ValueError:
            raise ServoscopeError(f"--sweep {sweep_text!r}: give F0:F1 in Hz, e.g. 0.5:20") from None
        sweep = plan_chirp(
            fps, sweep_from_hz, sweep_to_hz, duration_s, shape=sweep_shape, amplitude=amplitude, noise_deg=noise_deg,
            record_s=record_s, settle_s=settle_s, min_seconds=min_seconds, update_hz=update_hz, step=step,
            step_amplitude=step_amplitude, step_seconds=step_seconds, lead_in_s=lead_in_s, tail_s=tail_s,
            rest_s=rest_s, markers=markers, units=units,
        )
    else:
        if from_hz is None or to_hz is None:
            raise ServoscopeError("give --from and --to (sine dwells) or --sweep F0:F1 --duration S (one sweep)")
        if duration_s is not None or record_s is not None:
            raise ServoscopeError("--duration and --record-seconds go with --sweep")
        sweep = plan_sweep(
            fps, from_hz, to_hz, points=points, amplitude=amplitude, periods=periods, min_seconds=min_seconds,
            settle_s=settle_s, update_hz=update_hz, step=step, step_amplitude=step_amplitude,
            step_seconds=step_seconds, lead_in_s=lead_in_s, tail_s=tail_s, rest_s=rest_s,
            markers=markers, units=units, amplitudes=amplitudes,
        )
    write_plan(sweep, out)
    for i, d in enumerate(sweep.dwells, start=1):
        if d.kind == "sweep":
            what = f"{d.shape} sweep {d.from_hz:g}–{d.to_hz:g} Hz"
        else:
            what = f"{d.frequency_hz:>8g} Hz" if d.kind == "sine" else "    step   "
        click.echo(f"{i:3d} {what}  amplitude {d.amplitude:g}  {d.duration_s:7.2f} s")
    for d in sweep.dwells:
        if d.kind == "sweep":
            click.echo(sweep_coherence(d.amplitude, d.from_hz, d.to_hz, d.duration_s, sweep.fps, shape=d.shape,
                                       noise_deg=noise_deg).summary())
    if sweep.rotor:
        from .rotor_plan import rotor_lines

        for line in rotor_lines(sweep):
            click.echo(line)
    for warning in sweep.warnings:
        click.echo(f"warning: {warning}", err=True)
    minutes = sweep.total_s / 60
    click.echo(f"wrote {out}: {len(sweep.dwells)} tests, {minutes:.1f} min of driving plus camera handling")


@click.command("drive")
@click.argument("plan_file", metavar="PLAN", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--port", required=True, help="Serial port of the servo controller (/dev/ttyACM0, COM3).")
@click.option("--protocol", type=click.Choice(sorted(PROTOCOLS)), default="maestro", show_default=True,
              help="Controller protocol.")
@click.option("--device-number", default=12, show_default=True, type=int,
              help="Maestro device number (maestro-pololu protocol only).")
@click.option("--baud", default=9600, show_default=True, type=int, help="Baud rate, bits/s.")
@click.option("--channel", default=0, show_default=True, type=int, help="Servo channel.")
@click.option("--led-channel", default=5, show_default=True, type=int, help="LED channel (a digital output).")
@click.option("--no-led", is_flag=True, help="No LED on the rig.")
@click.option("--led-active-low", is_flag=True, help="The LED lights when its output is low.")
@click.option("--center-us", default=1500.0, show_default=True, type=float, help="Pulse width at input 0, µs.")
@click.option("--us-per-unit", default=500.0, show_default=True, type=float, help="µs per input unit.")
@click.option("--min-us", default=1000.0, show_default=True, type=float, help="Servo travel limit, µs.")
@click.option("--max-us", default=2000.0, show_default=True, type=float, help="Servo travel limit, µs.")
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path),
              help="Completed campaign.toml [default: campaign.toml beside PLAN].")
@click.option("--log", "log_path", type=click.Path(dir_okay=False, path_type=Path),
              help="Command log CSV [default: drive_log.csv beside the campaign].")
@click.option("--no-prompt", is_flag=True, help="Do not wait for Enter: the camera is started by other means.")
@click.option("--wait", "wait_s", type=float, help="Instead of prompting, wait this long for the camera, s.")
@click.option("--no-realtime", is_flag=True,
              help="Do not ask for real-time scheduling while streaming (asked for by default where allowed).")
def drive(plan_file: Path, port: str, protocol: str, device_number: int, baud: int, channel: int,
          led_channel: int, no_led: bool, led_active_low: bool, center_us: float, us_per_unit: float,
          min_us: float, max_us: float, out: Path | None, log_path: Path | None, no_prompt: bool,
          wait_s: float | None, no_realtime: bool) -> None:
    """Run PLAN on the rig: stream each test to the servo, switch the LED at the input start.

    Each test of the plan (a sine dwell, a frequency sweep or a step) is sent
    as timed commands at the plan's update rate; the LED goes off with the
    first command of each input. Writes the completed campaign.toml and a
    command log.
    """
    from ..errors import ServoscopeError
    from .driver import RigSettings, drive_plan, no_camera_prompt, prompt_camera, wait_camera
    from .plan import read_plan
    from .protocols import get_protocol

    if wait_s is not None and (wait_s < 0 or no_prompt):
        raise ServoscopeError("--wait must be ≥ 0 and cannot go with --no-prompt")
    sweep = read_plan(plan_file)
    out = out if out is not None else plan_file.with_name("campaign.toml")
    camera = no_camera_prompt if no_prompt else wait_camera(wait_s) if wait_s is not None else prompt_camera
    settings = RigSettings(
        channel=channel, led_channel=None if no_led else led_channel, center_us=center_us,
        us_per_unit=us_per_unit, min_us=min_us, max_us=max_us, led_active_low=led_active_low,
    )
    try:
        result = drive_plan(
            sweep, port, settings=settings, protocol=get_protocol(protocol, device_number=device_number),
            camera=camera, campaign_path=out, log_path=log_path, baud=baud,
            report=lambda line: click.echo(line, err=True), realtime=not no_realtime,
        )
    except KeyboardInterrupt:
        click.echo("stopped: servo back at centre, LED on; no campaign written", err=True)
        raise
    click.echo(f"wrote {result.campaign} and {result.log}; latest command {result.max_late_ms:.2f} ms behind schedule")
