"""servoscope: frequency response and transfer functions of actuators, measured from video.

The public API, in pipeline order::

    from servoscope import simulate_campaign, Campaign, identify, write_report

    manifest = simulate_campaign("twin", preset="quick", seed=1)   # digital twin
    result = identify(Campaign.load(manifest))                      # track → fit → model
    result.model.transfer_function                                  # python-control TF
    write_report(result, "out")                                     # result.json, report.html, CSVs

Names are imported lazily, so ``import servoscope`` stays fast.
"""

from __future__ import annotations

import importlib
from typing import Any

__version__ = "0.1.0"

_EXPORTS = {
    "ServoscopeError": "servoscope.errors",
    "CameraModel": "servoscope.camera",
    "calibrate": "servoscope.camera.calibrate",
    "Track": "servoscope.markers",
    "TrackerSettings": "servoscope.markers",
    "track_video": "servoscope.pipeline",
    "Campaign": "servoscope.campaign",
    "IdentificationResult": "servoscope.campaign",
    "identify": "servoscope.campaign",
    "compare_results": "servoscope.campaign",
    "ResultComparison": "servoscope.campaign",
    "load_campaign": "servoscope.campaign",
    "track_campaign": "servoscope.campaign",
    "write_report": "servoscope.report",
    "fit_sine": "servoscope.sysid",
    "fit_second_order": "servoscope.sysid",
    "FrequencyResponse": "servoscope.sysid",
    "analyse_step": "servoscope.sysid",
    "simulate_campaign": "servoscope.simulate",
    "ServoModel": "servoscope.simulate",
}

__all__ = sorted(_EXPORTS) + ["__version__"]


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'servoscope' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return __all__
