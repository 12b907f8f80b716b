"""The test rig: plan sine dwells or a frequency sweep, drive the servo and the LED, record a campaign.

``servoscope plan`` writes a campaign.toml without videos plus a ``[plan]``
table (:mod:`servoscope.rig.plan`); ``servoscope drive`` streams each test to
a servo controller over a serial port (:mod:`servoscope.rig.driver`, byte
encodings in :mod:`servoscope.rig.protocols`), switches the LED off at the
input start and writes the completed campaign.toml.
"""

from __future__ import annotations

from .driver import CameraHook, DriveResult, RigSettings, check_limits, drive_plan, open_port
from .chirp import plan_chirp, sweep_coherence
from .plan import Dwell, SweepPlan, frequency_warnings, plan_sweep, plan_to_toml, read_plan, write_plan
from .protocols import PROTOCOLS, MaestroCompact, MaestroPololu, ServoProtocol, get_protocol

__all__ = [
    "CameraHook",
    "DriveResult",
    "Dwell",
    "MaestroCompact",
    "MaestroPololu",
    "PROTOCOLS",
    "RigSettings",
    "ServoProtocol",
    "SweepPlan",
    "check_limits",
    "drive_plan",
    "frequency_warnings",
    "get_protocol",
    "open_port",
    "plan_chirp",
    "plan_sweep",
    "plan_to_toml",
    "read_plan",
    "sweep_coherence",
    "write_plan",
]
