"""Drive the servo and the LED through a campaign plan, and log every command.

For each test of a :class:`~servoscope.rig.plan.SweepPlan`:

1. servo at centre, LED on; the camera hook asks for the camera to be started;
2. ``lead_in_s`` with the LED lit, so the video sees it before the input;
3. at t0, one write carries *LED off* and the first input command; then the
   input (a sine, a step, or a sweep's chirp: :meth:`Dwell.input_at
   <servoscope.rig.plan.Dwell.input_at>`) is streamed at ``update_hz`` on an absolute schedule
   ``t0 + k/update_hz`` (sleep until each instant: no accumulated drift);
4. the command returns to centre at the end of the input, ``tail_s`` later
   the camera hook asks for the camera to be stopped, the LED goes back on;
5. ``rest_s`` before the next test.

Any exception, Ctrl-C included, sends centre and LED on, closes the port and
is re-raised. Every command is logged to CSV (``dwell, time_s, channel,
target_qus, command``), ``time_s`` relative to that dwell's t0.
"""

from __future__ import annotations

import csv
import gc
import math
import os
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable, Protocol as _TypingProtocol

import numpy as np

from ..errors import ServoscopeError
from .plan import Dwell, SweepPlan, default_video_name, plan_to_toml
from .protocols import QUARTER_US_PER_US, ServoProtocol, get_protocol
from .._io import write_text_atomic

__all__ = [
    "RigSettings",
    "CameraHook",
    "prompt_camera",
    "wait_camera",
    "no_camera_prompt",
    "check_limits",
    "open_port",
    "drive_plan",
    "DriveResult",
    "LOG_COLUMNS",
]

#: Columns of the command log.
LOG_COLUMNS = ("dwell", "time_s", "channel", "target_qus", "command")

#: ``hook(event, index, dwell, video)``: event is ``"start"`` or ``"stop"``,
#: index is 1-based. It returns once the camera is running (or stopped).
CameraHook = Callable[[str, int, Dwell, str], None]


class _Link(_TypingProtocol):
    """The part of :class:`serial.Serial` the driver uses."""

    def write(self, data: bytes) -> int | None: ...
    def flush(self) -> None: ...
    def close(self) -> None: ...


@dataclass(frozen=True)
class RigSettings:
    """How input units map to the servo, and where the LED is.

    Attributes
    ----------
    channel : int
        Controller channel of the servo.
    led_channel : int or None
        Controller channel of the LED (a digital output), or None for no LED.
    center_us : float
        Pulse width at input 0, µs.
    us_per_unit : float
        Pulse width change per input unit, µs (command = center_us + us_per_unit·u).
    min_us, max_us : float
        The servo's travel limits, µs; a plan that would pass them is refused.
    led_active_low : bool
        The LED lights when the output is low (wired to sink current).
    """

    channel: int = 0
    led_channel: int | None = 5
    center_us: float = 1500.0
    us_per_unit: float = 500.0
    min_us: float = 1000.0
    max_us: float = 2000.0
    led_active_low: bool = False

    def command_us(self, u: float) -> float:
        """Pulse width for input ``u``, µs."""
        return self.center_us + self.us_per_unit * u

    def target_qus(self, u: float) -> int:
        """Controller target for input ``u``, quarter-µs (rounded to the nearest)."""
        return int(round(QUARTER_US_PER_US * self.command_us(u)))


@dataclass(frozen=True)
class DriveResult:
    """What :func:`drive_plan` did.

    Attributes
    ----------
    campaign : Path
        The completed ``campaign.toml``.
    log : Path
        The command log (CSV).
    plan : SweepPlan
        The plan with videos and per-dwell ``max_late_ms`` filled in.
    max_late_ms : float
        The latest any input command was written behind its schedule, ms.
    """

    campaign: Path
    log: Path
    plan: SweepPlan
    max_late_ms: float


def _what(dwell: Dwell) -> str:
    """``2 Hz sine``, ``log sweep 0.5–20 Hz`` or ``step``."""
    if dwell.kind == "sine":
        return f"{dwell.frequency_hz:g} Hz sine"
    if dwell.kind == "sweep":
        return f"{dwell.shape or 'log'} sweep {dwell.from_hz:g}–{dwell.to_hz:g} Hz"
    return "step"


def _describe(index: int, n: int, dwell: Dwell, video: str) -> str:
    what = f"step of {dwell.amplitude:g}" if dwell.kind == "step" else _what(dwell)
    return f"dwell {index}/{n} ({what}, {dwell.duration_s:.3g} s; save as {video})"


def prompt_camera(event: str, index: int, dwell: Dwell, video: str) -> None:
    """Default camera hook: ask on the terminal and wait for Enter."""
    try:
        if event == "start":
            input(f"start the camera for dwell {index} ({video}), then press Enter ")
        else:
            input(f"stop the camera ({video}), then press Enter ")
    except EOFError:
        raise ServoscopeError("no terminal to prompt on for the camera: use --no-prompt or --wait S") from None


def wait_camera(seconds: float) -> CameraHook:
    """A camera hook that waits ``seconds`` (s) instead of prompting (camera started by other means)."""

    def hook(event: str, index: int, dwell: Dwell, video: str) -> None:
        if seconds > 0:
            time.sleep(seconds)

    return hook


def no_camera_prompt(event: str, index: int, dwell: Dwell, video: str) -> None:
    """A camera hook that returns at once."""


def check_limits(plan: SweepPlan, settings: RigSettings, protocol: ServoProtocol) -> None:
    """Refuse settings or a plan that would drive the servo past its limits.

    Called before the port is opened, so nothing moves.

    Raises
    ------
    ServoscopeError
        Naming the option or the test at fault.
    """
    protocol.check_channel(settings.channel, "channel")
    if settings.led_channel is not None:
        protocol.check_channel(settings.led_channel, "led-channel")
        if settings.led_channel == settings.channel:
            raise ServoscopeError(f"--led-channel {settings.led_channel} is the servo's --channel")
    if not (math.isfinite(settings.min_us) and math.isfinite(settings.max_us)) or not 0 < settings.min_us < settings.max_us:
        raise ServoscopeError(f"--min-us {settings.min_us:g} / --max-us {settings.max_us:g}: need 0 < min < max")
    if settings.max_us * QUARTER_US_PER_US > protocol.max_target_qus:
        raise ServoscopeError(
            f"--max-us {settings.max_us:g}: above what {protocol.name} can encode "
            f"({protocol.max_target_qus / QUARTER_US_PER_US:g} µs)"
        )
    if not settings.min_us <= settings.center_us <= settings.max_us:
        raise ServoscopeError(
            f"--center-us {settings.center_us:g} is outside --min-us {settings.min_us:g} … --max-us {settings.max_us:g}"
        )
    if not math.isfinite(settings.us_per_unit) or settings.us_per_unit == 0:
        raise ServoscopeError(f"--us-per-unit {settings.us_per_unit:g}: must be a non-zero number")
    for i, dwell in enumerate(plan.dwells, start=1):
        extremes = [dwell.amplitude, -dwell.amplitude] if dwell.kind in ("sine", "sweep") else [dwell.amplitude]
        for u in extremes:
            us = settings.command_us(u)
            what = _what(dwell)
            if us > settings.max_us:
                raise ServoscopeError(
                    f"test {i} ({what}, amplitude {dwell.amplitude:g}) would drive the servo to {us:g} µs, "
                    f"past --max-us {settings.max_us:g}"
                )
            if us < settings.min_us:
                raise ServoscopeError(
                    f"test {i} ({what}, amplitude {dwell.amplitude:g}) would drive the servo to {us:g} µs, "
                    f"past --min-us {settings.min_us:g}"
                )


def open_port(port: str, baud: int = 9600) -> Any:
    """Open a serial port for the controller.

    Parameters
    ----------
    port : str
        Device path (``/dev/ttyACM0``) or name (``COM3``).
    baud : int
        Baud rate, bits/s (ignored by the Maestro's USB command port).

    Returns
    -------
    serial.Serial

    Raises
    ------
    ServoscopeError
        If the port does not exist or cannot be opened.
    """
    import serial  # deferred: only the rig needs pyserial

    if os.name == "posix" and "/" in port and not os.path.exists(port):
        raise ServoscopeError(f"--port {port}: no such device (is the controller plugged in?)")
    try:
        # write_timeout: a stalled controller raises instead of hanging with the servo mid-stroke.
        link = serial.Serial(port, baudrate=baud, timeout=0.1, write_timeout=1.0,
                             exclusive=True if os.name == "posix" else None)
    except (serial.SerialException, OSError, ValueError) as exc:
        raise ServoscopeError(f"--port {port}: cannot open ({exc})") from None
    return link


class _CommandLog:
    """Commands as sent, kept with absolute perf_counter times and written relative to each t0."""

    def __init__(self, path: Path, protocol: ServoProtocol) -> None:
        self.path = path
        self.protocol = protocol
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            self._file = path.open("w", newline="", encoding="utf-8")
        except OSError as exc:
            raise ServoscopeError(f"--log {path}: cannot write ({exc.strerror or exc})") from None
        self._csv = csv.writer(self._file)
        self._csv.writerow(LOG_COLUMNS)
        self._rows: list[tuple[str, float, int, int | None, bytes]] = []

    def add(self, dwell: str, time_abs_s: float, channel: int, target_qus: int | None, command: bytes) -> None:
        """Queue a row; ``target_qus`` None for commands that set no target (speed, acceleration)."""
        self._rows.append((dwell, time_abs_s, channel, target_qus, command))

    def flush(self, origin_s: float) -> None:
        """Write the pending rows with times relative to ``origin_s`` (a perf_counter time, s)."""
        for dwell, t_abs, channel, target, command in self._rows:
            self._csv.writerow([dwell, f"{t_abs - origin_s:.6f}", channel, "" if target is None else target,
                                command.hex(" ")])
        self._rows.clear()
        self._file.flush()

    def close(self, origin_s: float) -> None:
        self.flush(origin_s)
        self._file.close()


class _Rig:
    """A port, a protocol and the settings: sends commands and logs them."""

    def __init__(self, link: _Link, protocol: ServoProtocol, settings: RigSettings, log: _CommandLog) -> None:
        self.link, self.protocol, self.settings, self.log = link, protocol, settings, log
        self.dwell = "setup"
        self.t0_s: float | None = None  # perf_counter time of the current dwell's t0, once reached
        self.realtime = True  # ask for real-time priority while streaming (best effort)

    def servo_bytes(self, target_qus: int) -> bytes:
        return self.protocol.set_target(self.settings.channel, target_qus)

    def led_target_qus(self, lit: bool) -> int:
        return self.protocol.output_level_qus(high=lit != self.settings.led_active_low)

    def send(self, items: list[tuple[int, int | None, bytes]]) -> float:
        """Write ``(channel, target_qus, bytes)`` items in one write; returns the send time (perf_counter, s)."""
        t_s = time.perf_counter()
        self.link.write(b"".join(b for _, _, b in items))
        for channel, target, command in items:
            self.log.add(self.dwell, t_s, channel, target, command)
        return t_s

    def rest_items(self) -> list[tuple[int, int, bytes]]:
        """Centre the servo and light the LED."""
        centre = self.settings.target_qus(0.0)
        items = [(self.settings.channel, centre, self.servo_bytes(centre))]
        if self.settings.led_channel is not None:
            led = self.led_target_qus(True)
            items.append((self.settings.led_channel, led, self.protocol.set_target(self.settings.led_channel, led)))
        return items


def _sleep_until(deadline_s: float) -> None:
    """Sleep until ``time.perf_counter() ≥ deadline_s`` (absolute, s)."""
    while True:
        remaining_s = deadline_s - time.perf_counter()
        if remaining_s <= 0:
            return
        time.sleep(remaining_s)


class _RealtimePriority:
    """Best-effort real-time scheduling (Linux SCHED_FIFO) of the calling thread, restored on exit.

    Under CPU load an ordinary thread can be preempted for several ms, which
    shows up as late commands; a low real-time priority avoids that. The loop
    sleeps between commands, so it cannot starve the machine. Without the
    privilege (CAP_SYS_NICE or an rtprio limit) nothing changes.
    """

    PRIORITY = 10  # low among real-time priorities (1…99): above every ordinary process, below the kernel's

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled and hasattr(os, "sched_setscheduler")
        self.active = False

    def __enter__(self) -> "_RealtimePriority":
        if self.enabled:
            try:
                self._old = (os.sched_getscheduler(0), os.sched_getparam(0))
                os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(self.PRIORITY))
                self.active = True
            except (OSError, AttributeError):
                self.active = False
        return self

    def __exit__(self, *exc: object) -> None:
        if self.active:
            try:
                os.sched_setscheduler(0, self._old[0], self._old[1])
            except OSError:
                pass
            self.active = False


def _run_input(rig: _Rig, dwell: Dwell, update_hz: float) -> tuple[float, float]:
    """Stream one dwell's input from t0 until it is back at centre.

    Returns
    -------
    t0_s : float
        perf_counter time of the t0 write, s.
    max_late_s : float
        Latest write behind its scheduled instant, s.
    """
    settings = rig.settings
    n_updates = math.ceil(dwell.duration_s * update_hz - 1e-9)
    # Precompute every command so that nothing but a write follows each wake-up.
    # Sample k is the input at t0 + k/update_hz (a sine, a step, or the sweep's chirp);
    # the last one (k = n_updates, at or after the input's end) is 0, i.e. centre.
    inputs = np.atleast_1d(dwell.input_at(np.arange(n_updates + 1) / update_hz))
    targets = [settings.target_qus(float(u)) for u in inputs]
    frames = [rig.servo_bytes(q) for q in targets]
    first: list[tuple[int, int, bytes]] = []
    if settings.led_channel is not None:
        off = rig.led_target_qus(False)
        first.append((settings.led_channel, off, rig.protocol.set_target(settings.led_channel, off)))
    first.append((settings.channel, targets[0], frames[0]))

    gc_was_enabled = gc.isenabled()
    gc.disable()  # a collection mid-dwell is a multi-ms hiccup in the schedule
    try:
        with _RealtimePriority(rig.realtime):
            t0_s = rig.send(first)  # LED off and the first input command: the same instant
            rig.t0_s = t0_s
            max_late_s = 0.0
            k = 1
            while k <= n_updates:
                deadline_s = t0_s + k / update_hz
                _sleep_until(deadline_s)
                late_s = time.perf_counter() - deadline_s
                if late_s >= 1.0 / update_hz:
                    # More than a period behind (the machine stalled): send what is due
                    # now rather than a burst of stale commands; the schedule stays absolute.
                    k = min(n_updates, k + int(late_s * update_hz))
                    deadline_s = t0_s + k / update_hz
                    late_s = time.perf_counter() - deadline_s
                rig.send([(settings.channel, targets[k], frames[k])])
                max_late_s = max(max_late_s, late_s)
                k += 1
    finally:
        if gc_was_enabled:
            gc.enable()
    return t0_s, max_late_s


def drive_plan(
    plan: SweepPlan,
    port: str | _Link,
    *,
    settings: RigSettings = RigSettings(),
    protocol: str | ServoProtocol = "maestro",
    camera: CameraHook = prompt_camera,
    campaign_path: str | Path = "campaign.toml",
    log_path: str | Path | None = None,
    baud: int = 9600,
    report: Callable[[str], None] | None = None,
    realtime: bool = True,
) -> DriveResult:
    """Run a plan on the rig and write the completed campaign.

    Parameters
    ----------
    plan : SweepPlan
        From :func:`~servoscope.rig.plan.read_plan` or :func:`~servoscope.rig.plan.plan_sweep`.
    port : str or serial-like
        Serial device of the controller, or an open object with ``write``,
        ``flush`` and ``close`` (it is closed at the end).
    settings : RigSettings
        Channels, centre, scale and travel limits.
    protocol : str or ServoProtocol
        ``"maestro"`` (compact protocol) or another :data:`~servoscope.rig.protocols.PROTOCOLS` entry.
    camera : CameraHook
        Called before each test's lead-in (``"start"``) and after its tail
        (``"stop"``); it returns when the camera is running or stopped.
    campaign_path : path-like
        Where to write the completed ``campaign.toml``.
    log_path : path-like, optional
        Command log (CSV); default ``drive_log.csv`` beside the campaign.
    baud : int
        Baud rate, bits/s.
    report : callable, optional
        Called with one line of progress per test.
    realtime : bool
        While streaming, ask for real-time scheduling (Linux SCHED_FIFO,
        priority 10) if the process may; without the privilege nothing changes.

    Returns
    -------
    DriveResult

    Raises
    ------
    ServoscopeError
        For settings or a plan past the servo's limits (before the port is
        opened), a port that cannot be opened, or a write that fails.
    KeyboardInterrupt
        Re-raised after the servo is centred, the LED lit and the port closed.
    """
    if isinstance(protocol, str):
        protocol = get_protocol(protocol)
    check_limits(plan, settings, protocol)  # before anything is opened or moves
    campaign_path = Path(campaign_path)
    log_path = Path(log_path) if log_path is not None else campaign_path.with_name("drive_log.csv")
    n_steps = sum(d.kind == "step" for d in plan.dwells)
    videos = [d.video or default_video_name(i, d, n_steps) for i, d in enumerate(plan.dwells, start=1)]
    if len(set(videos)) != len(videos):
        raise ServoscopeError("the plan names the same video twice")

    link = open_port(port, baud) if isinstance(port, str) else port
    try:
        log = _CommandLog(log_path, protocol)
    except BaseException:
        link.close()
        raise
    rig = _Rig(link, protocol, settings, log)
    rig.realtime = realtime
    start_s = time.perf_counter()
    origin_s = start_s  # time origin of the rows not yet written
    late_ms: list[float] = []
    try:
        setup = protocol.setup(settings.channel)
        if setup:
            rig.send([(settings.channel, None, setup)])
        rig.send(rig.rest_items())
        for i, (dwell, video) in enumerate(zip(plan.dwells, videos), start=1):
            rig.dwell, rig.t0_s = str(i), None
            if i > 1 and plan.rest_s > 0:
                time.sleep(plan.rest_s)
            rig.send(rig.rest_items())
            camera("start", i, dwell, video)
            _sleep_until(time.perf_counter() + plan.lead_in_s)
            t0_s, max_late_s = _run_input(rig, dwell, plan.update_hz)
            origin_s = t0_s
            late_ms.append(max_late_s * 1e3)
            _sleep_until(time.perf_counter() + plan.tail_s)
            camera("stop", i, dwell, video)
            rig.send(rig.rest_items())  # LED back on only once the camera has stopped
            log.flush(t0_s)
            if report is not None:
                report(f"{_describe(i, len(plan.dwells), dwell, video)}: done, latest command {max_late_s * 1e3:.2f} ms behind schedule")
    except BaseException as exc:
        # Ctrl-C or any failure: leave the rig safe (centre, LED on) before re-raising.
        # Log rows of an interrupted dwell relative to its t0, or to the stop if t0 was not reached.
        origin_s = rig.t0_s if rig.t0_s is not None else time.perf_counter()
        try:
            rig.dwell = "stop"
            rig.send(rig.rest_items())
            link.flush()
        except BaseException:  # a failing port, or a second Ctrl-C: still close, then raise the first
            pass
        _close(link, log, origin_s)
        if _is_serial_error(exc):
            raise ServoscopeError(f"--port {getattr(link, 'port', port)}: write failed ({exc})") from None
        raise
    _close(link, log, origin_s)

    done = replace(plan, dwells=tuple(
        replace(d, video=v, max_late_ms=round(m, 3)) for d, v, m in zip(plan.dwells, videos, late_ms)
    ), drive={
        "protocol": protocol.name, "channel": settings.channel,
        "led_channel": -1 if settings.led_channel is None else settings.led_channel,
        "center_us": float(settings.center_us), "us_per_unit": float(settings.us_per_unit),
        "log": os.path.relpath(log_path.resolve(), campaign_path.resolve().parent),
    })
    try:
        campaign_path.parent.mkdir(parents=True, exist_ok=True)
        write_text_atomic(campaign_path, plan_to_toml(done))
    except OSError as exc:
        raise ServoscopeError(f"{campaign_path}: cannot write ({exc.strerror or exc})") from None
    return DriveResult(campaign_path, log_path, done, max(late_ms, default=0.0))


def _is_serial_error(exc: BaseException) -> bool:
    try:
        import serial
    except ImportError:  # pragma: no cover
        return False
    return isinstance(exc, serial.SerialException)


def _close(link: _Link, log: _CommandLog, origin_s: float) -> None:
    try:
        link.close()
    finally:
        log.close(origin_s)
