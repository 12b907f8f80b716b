"""Writing ``campaign.toml``: servoscope's one TOML writer, and a Campaign as its tables.

:meth:`Campaign.to_toml <servoscope.campaign.manifest.Campaign.to_toml>` writes what
:func:`~servoscope.campaign.manifest.load_campaign` reads back to an equal campaign;
the rig's plans (``servoscope plan`` / ``drive``) and the twin's campaigns are written
through it. The text is made by hand (tomli_w is not a dependency): tables of scalars,
arrays and inline tables, each table after a blank line, keys in the order given.
"""

from __future__ import annotations

import json
import math
import os
import re
from pathlib import Path
from typing import Any

from .._io import write_text_atomic
from ..defaults import SETTLE_S, TIMESTAMP
from ..errors import ServoscopeError
from ..video.frame_source import parse_frame_source
from .sections import default_labels

# The functions below take a Campaign (servoscope.campaign.manifest, which imports this module): typed Any.
Campaign = Any

__all__ = ["toml_value", "toml_table", "toml_document", "campaign_tables", "campaign_to_toml", "save_campaign",
           "test_entries", "markers_table", "camera_table", "rotor_table"]

_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")


def _key(key: str) -> str:
    return key if _BARE_KEY.fullmatch(key) else json.dumps(key, ensure_ascii=False)


def toml_value(value: Any) -> str:
    """One TOML value: a bool, number, text, array or inline table."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"cannot write {value} to TOML")
        return repr(value)  # shortest round-trip form; valid TOML (e.g. 0.5, 1e-05)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)  # JSON string escapes are valid TOML basic strings
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{_key(k)} = {toml_value(v)}" for k, v in value.items() if v is not None) + "}"
    raise TypeError(f"cannot write {type(value).__name__} to TOML")


def toml_table(header: str, table: dict[str, Any]) -> str:
    """A table's text: its ``header`` line (``[name]`` or ``[[name]]``), then ``key = value`` lines (None left out)."""
    return "\n".join([header] + [f"{_key(k)} = {toml_value(v)}" for k, v in table.items() if v is not None])


def toml_document(tables: list[tuple[str, dict[str, Any]]], header: str = "") -> str:
    """A TOML file's text: ``header`` (comment lines, each ending in a newline), then the tables, a blank line apart."""
    return header + "\n\n".join(toml_table(h, t) for h, t in tables) + "\n"


def _relative(path: Path | str, base: Path) -> str:
    """``path`` as written in a manifest in ``base``: relative to it, with forward slashes."""
    return Path(os.path.relpath(path, base)).as_posix()


def camera_table(c: Campaign) -> dict[str, Any]:
    """``[camera]``: files relative to the manifest; exposure, timestamp and readout only where said."""
    base = c.path.parent
    if c.camera is not None and c.camera_file is None:
        raise ServoscopeError("the campaign's camera model has no file to name in [camera] calibration: save it first")
    return {
        "calibration": None if c.camera_file is None else _relative(c.camera_file, base),
        "exposure_s": None if c.exposure_s is None else float(c.exposure_s),
        "timestamp": c.timestamp if c.timestamp != TIMESTAMP else None,
        "readout_s": float(c.readout_s) if c.readout_s > 0 else None,
        "plane": None if c.plane_file is None else _relative(c.plane_file, base),
    }


def _marker(colour: str, near: tuple[float, float] | None) -> str | dict[str, Any]:
    if near is None:
        return colour
    kind = "brightness" if colour.lower() in ("bright", "dark") else "colour"
    return {kind: colour, "near": [float(near[0]), float(near[1])]}


def markers_table(c: Campaign) -> dict[str, Any]:
    """``[markers]``: each marker's colour (or ``{colour = …, near = [x, y]}`` where pinned), reference, extra."""
    return {
        "lead": _marker(c.lead, c.lead_near),
        "trail": _marker(c.trail, c.trail_near),
        "led": None if c.led is None else _marker(c.led, c.led_near),
        "reference": None if c.reference is None else list(c.reference),
        "extra": list(c.extra) or None,
    }


def rotor_table(c: Campaign) -> dict[str, Any] | None:
    """``[rotor]``: each blade's ``{lead = …, trail = …}``, then the speed, camera distance and tip radius where
    said; None for a static campaign (no table)."""
    r = getattr(c, "rotor", None)
    if r is None:
        return None
    return {"blades": [{"lead": lead, "trail": trail} for lead, trail in r.blades],
            **{k: None if getattr(r, k) is None else float(getattr(r, k))
               for k in ("rev_per_s", "camera_distance_m", "tip_radius_m")}}


def _source(t, base: Path) -> dict[str, Any]:
    """A test's ``video = …``, or ``frames = …`` with its options."""
    if t.video is None:
        return {}
    if not t.frames:
        return {"video": _relative(t.video, base)}
    spec = parse_frame_source(str(t.video))
    return {
        "frames": _relative(spec.path, base),
        "fps": None if spec.fps is None else float(spec.fps),
        "start_s": float(spec.start_s) if spec.start_s else None,
        "timestamps": None if spec.timestamps is None else _relative(spec.timestamps, base),
        "bayer": spec.bayer,
        "bits": None if spec.bits is None else int(spec.bits),
    }


def test_entries(c: Campaign) -> list[dict[str, Any]]:
    """The ``[[tests]]`` tables: a label only where it is not the one the file would give anyway."""
    base = c.path.parent
    entries = [{k: v for k, v in _source(t, base).items() if v is not None} for t in c.tests]
    defaults = default_labels(entries, base)
    out = []
    for t, entry, default in zip(c.tests, entries, defaults):
        out.append({k: v for k, v in {
            **entry, "label": t.label if t.label and t.label != default else None, "kind": t.kind,
            "frequency_hz": None if t.frequency_hz is None else float(t.frequency_hz),
            # A sweep's own keys (None, so left out, for the other kinds).
            **{k: None if getattr(t, k, None) is None else float(getattr(t, k))
               for k in ("from_hz", "to_hz", "duration_s")},
            "shape": getattr(t, "shape", None),
            # A recorded input's file, relative to the manifest written where it can be (as the videos).
            "input": None if getattr(t, "input_file", None) is None else _relative(t.input_file, base),
            "amplitude": float(t.amplitude), "t0_s": None if t.t0_s is None else float(t.t0_s),
        }.items() if v is not None})
    return out


def _model_tables(c: Campaign) -> list[tuple[str, dict[str, Any]]]:
    table = {"fix": dict(c.model_fix) or None,
             "bound": {k: [float(lo), float(hi)] for k, (lo, hi) in c.model_bounds.items()} or None,
             "tie": dict(c.model_ties) or None}
    return [("[model]", table)] if any(v is not None for v in table.values()) else []


def _plan_tables(plan: dict[str, Any]) -> list[tuple[str, dict[str, Any]]]:
    """``[plan]``'s values, then its tables (``[plan.drive]``) and arrays of tables (``[[plan.dwells]]``)."""
    if not plan:
        return []

    def is_tables(v):
        return isinstance(v, list) and v and all(isinstance(e, dict) for e in v)

    out = [("[plan]", {k: v for k, v in plan.items() if not isinstance(v, dict) and not is_tables(v)})]
    for key, value in plan.items():
        if isinstance(value, dict) and value:
            out.append((f"[plan.{_key(key)}]", value))
        elif is_tables(value):
            out += [(f"[[plan.{_key(key)}]]", entry) for entry in value]
    return out


def campaign_tables(c: Campaign) -> list[tuple[str, dict[str, Any]]]:
    """The manifest's tables in the file's order: camera, markers, rotor, input, analysis, model, tests, plan."""
    camera = camera_table(c)
    tables = [("[camera]", camera)] if any(v is not None for v in camera.values()) else []
    tables += [("[markers]", markers_table(c))]
    rotor = rotor_table(c)
    tables += [("[rotor]", rotor)] if rotor is not None else []
    tables += [("[input]", {"units": c.input_units})]
    if c.settle_stated or c.settle_s != SETTLE_S:
        tables.append(("[analysis]", {"settle_s": c.settle_s}))
    tables += _model_tables(c)
    tables += [("[[tests]]", entry) for entry in test_entries(c)]
    return tables + _plan_tables(c.plan)


def campaign_to_toml(c: Campaign, header: str = "") -> str:
    """The campaign's manifest text (see :meth:`Campaign.to_toml`)."""
    return toml_document(campaign_tables(c), header)


def save_campaign(c: Campaign, path: str | Path, header: str = "") -> Path:
    """Write ``c``'s manifest to ``path`` atomically, paths relative to ``path``'s folder; returns ``path``."""
    from dataclasses import replace

    path = Path(path)
    text = campaign_to_toml(replace(c, path=path.resolve()), header)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_text_atomic(path, text)
    except OSError as exc:
        raise ServoscopeError(f"{path}: cannot write ({exc.strerror or exc})") from None
    return path
