"""The twin's ``campaign.toml``: the simulated campaign as a :class:`~servoscope.campaign.manifest.Campaign`.

Written by :meth:`Campaign.save <servoscope.campaign.manifest.Campaign.save>` as a real
campaign's would be: what the operator knows (the calibration, the shutter time and
timestamp when the preset says them, a rolling shutter's readout), the markers, and
one test per recording.
"""

from __future__ import annotations

from dataclasses import replace
from fractions import Fraction
from pathlib import Path

from ..campaign.manifest import Campaign, TestSpec
from ..campaign.recorded_input import peak_command, read_input_file
from ..campaign.toml_io import test_entries
from ..campaign.sections import default_labels
from ..defaults import REFERENCE_COLOURS, SETTLE_S
from ..video.frame_source import frame_source
from ..video.sequence_writer import MRAW_NAME
from .presets import CampaignPreset
from .scene import Scene

__all__ = ["TWIN_HEADER", "twin_campaign"]

#: The first line of the twin's campaign.toml.
TWIN_HEADER = "# Simulated campaign written by servoscope.simulate (the true answer is in truth.json).\n"


def _recording(p: CampaignPreset, folder: Path, name: str, frames_fps: Fraction | None) -> tuple[Path, bool]:
    """A test's recording: the video, or the frame source (an image sequence or MRAW) with its options."""
    if frames_fps is None:
        return folder / name, False
    frames = folder / name / (f"{MRAW_NAME}.cih" if p.frames_format == "mraw" else "*.tif")
    return Path(frame_source(frames, fps=float(frames_fps), bits=p.bit_depth if p.monochrome else None)), True


def twin_campaign(p: CampaignPreset, scene: Scene, tests: list[dict], path: Path,
                  frames_fps: Fraction | None = None) -> Campaign:
    """The campaign the twin writes to ``path`` (``campaign.toml``, beside ``camera.json`` and the recordings).

    Parameters
    ----------
    p : CampaignPreset
    scene : Scene
        What was filmed (the markers' colours, the extra stickers).
    tests : list of dict
        Each recording's ``video`` (name in the folder), ``kind``, ``frequency_hz`` (sines), ``from_hz``,
        ``to_hz``, ``duration_s`` and ``shape`` (sweeps), ``input`` (a piloted sweep's file in the folder,
        which gives its samples and amplitude) and ``amplitude``.
    path : Path
        The manifest file.
    frames_fps : Fraction, optional
        The frame rate of recordings saved as frames (``p.frames_format``); None for videos.
    """
    path = Path(path).resolve()
    folder = path.parent
    specs = []
    for t in tests:
        video, frames = _recording(p, folder, t["video"], frames_fps)
        sweep = ({"from_hz": float(t["from_hz"]), "to_hz": float(t["to_hz"]), "duration_s": float(t["duration_s"]),
                  "shape": t["shape"]} if t["kind"] == "sweep" and not t.get("input") else {})
        amplitude = float(t["amplitude"])
        if t.get("input"):  # a piloted sweep: its recorded input, with no band (the file's own spectrum gives it)
            time_s, command = read_input_file(folder / t["input"])
            sweep = {"input_file": folder / t["input"], "input_time_s": time_s, "input_command": command}
            amplitude = peak_command(command)
        specs.append(TestSpec(video, t["kind"], amplitude,
                              float(t["frequency_hz"]) if t["kind"] == "sine" else None, frames=frames, **sweep))
    # Monochrome footage: every marker (and the LED) told by brightness.
    lead, trail, led = (("bright",) * 3 if p.monochrome else (scene.lead_colour, scene.trail_colour, scene.led_colour))
    campaign = Campaign(
        path=path, lead=lead, trail=trail, led=led, camera=None, camera_file=folder / "camera.json",
        # The shutter time is a camera setting the operator knows; the LED's
        # partly lit frame gives the input's start only if it is known.
        exposure_s=float(p.exposure_s) if p.exposure_s > 0 and p.manifest_exposure else None,
        timestamp=p.timestamp_at, readout_s=float(p.readout_s), input_units=p.input_units, settle_s=SETTLE_S,
        reference=tuple(REFERENCE_COLOURS) if p.reference_stickers else None,
        extra=tuple(c for c, _ in scene.extra_stickers), tests=tuple(specs),
    )
    labels = default_labels(test_entries(campaign), folder)  # each test's label as the file gives it
    return replace(campaign, tests=tuple(replace(t, label=label) for t, label in zip(campaign.tests, labels)))
