"""The result of identifying a campaign, and the dead-time bookkeeping it reports.

A data object below the runner (which makes it) and the report (which draws
it): nothing here imports either, so a notebook, a test or the report can
hold, save and look at a result without the stage that produced it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, Mapping

import numpy as np

from .._io import atomic_path, write_json_atomic
from ..angle.pivot import pivot_motion
from ..angle.view import ObliqueView
from ..camera.exposure import ExposureEstimate
from ..markers.track import Track
from ..results import jsonable
from ..sysid import FrequencyResponse, SineFit, StepAnalysis, TransferFunctionFit, bandwidth_rad_s
from ..sysid.linearity import AmplitudeCheck
from ..sysid.heave import HeaveModel, HeaveRow
from ..sysid.modes import ModeFit
from ..sysid.servo_fit import fit_percent
from ..sysid.servo_select import ServoModelSelection
from ..sysid.servo_sim import NONLINEAR_PARAMETER
from ..sysid.dead_time import DeadTimeEstimate, dead_time_estimates
from ..sysid.step import unit_step_function
from ..sysid.sweep_result import SweepResponse
from ..sysid.pass_result import PassSineFit
from .headline import SOURCE_KEYS, TIME_DOMAIN_KEY, Headline, chosen_dead_time, headline
from .manifest import Campaign, TestSpec
from .recorded_input import recorded_input_entry, recorded_input_fields

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes

__all__ = ["IdentificationResult", "input_start", "input_start_stderr", "package_version"]


def input_start(test: TestSpec, track: Track) -> float | None:
    """A test's input start (s): its manifest ``t0_s``, else the LED's switch in its track; None without either."""
    # A t0 typed in the manifest wins: the user knows something the LED does not.
    return test.t0_s if test.t0_s is not None else track.t0_s



def input_start_stderr(test: TestSpec, track: Track) -> float | None:
    """Standard uncertainty of :func:`input_start` (s): the LED's, or 0 for a t0 typed in the manifest."""
    return track.t0_uncertainty_s if test.t0_s is None else 0.0



def _fit_part(model: dict) -> dict:
    """The model's own summary from result.json's ``model``, which also holds the chosen dead time.

    :meth:`IdentificationResult.summary` replaces the fit's ``dead_time_s`` (and its
    stderr and interval) by the chosen estimate's and keeps the fit's under
    ``dead_time_from_phase_s``: undone here.
    """
    own = {"dead_time_from_phase_s", "dead_time_from_phase_stderr_s", "dead_time_source", "structure", "fixed",
           "candidates", "time_domain", "domain", "parameters", "describes", *NONLINEAR_PARAMETER.values()}
    fit = {k: v for k, v in model.items() if k not in own}
    for part in ("stderr", "ci95"):
        if isinstance(fit.get(part), dict):
            fit[part] = {k: v for k, v in fit[part].items() if k not in own}
    fit["dead_time_s"] = model.get("dead_time_from_phase_s")
    fit["dead_time_stderr_s"] = (model.get("stderr") or {}).get("dead_time_s")
    return fit


def _loaded_campaign(data: dict, tests: list[TestSpec], path: Path, load_campaign) -> Campaign:
    """The campaign a saved result describes; settings from its manifest when that is still there."""
    manifest = Path(data.get("campaign") or "")
    base = None
    if manifest.is_file():
        try:
            base = load_campaign(manifest, check_videos=False)
        except Exception:  # a manifest changed since: the result's own description stands
            base = None
    skipped = tuple((s["label"], s["reason"]) for s in data.get("skipped", []))
    if base is not None:
        return replace(base, tests=tuple(tests), skipped=skipped)
    return Campaign(path=manifest if data.get("campaign") else path, lead="", trail="", led=None, camera=None,
                    exposure_s=None, input_units=data.get("input_units", ""), settle_s=math.nan,
                    tests=tuple(tests), skipped=skipped, extra=tuple(data.get("extra_markers", ())))


@dataclass(frozen=True)
class IdentificationResult:
    """Everything one identification produced.

    Frozen: a changed result is a new one (:func:`dataclasses.replace`). Its lists are
    kept as tuples and its dicts of tracks and fits as read-only mappings.

    Attributes
    ----------
    campaign : Campaign
    tracks : read-only mapping of label → Track
    sine_fits : read-only mapping of label → SineFit
    frequency_response : FrequencyResponse
    model : TransferFunctionFit
        The fitted model: the order asked ((0, 2) by default, the paper's eq. 6), fitted to
        magnitude and phase with a dead time when every dwell's phase is known ("complex",
        what ``fit="auto"`` picks then), else to the magnitudes alone ("magnitude", as the
        paper does).
    step : StepAnalysis or None
        The step test, with the dead time fitted against the model.
    step_label : str or None
    warnings : tuple of str
    exposure : ExposureEstimate or None
        The camera's exposure: given, or estimated from the LED's switches.
    shared_t0_stderr_s : float
        The part of the dwells' t0 uncertainty they may share (see
        :func:`shared_t0_stderr`), added to the phase dead time's.
    modes : tuple of ModeFit
        The blade's structural modes seen in its heave after the step (see
        :func:`servoscope.campaign.blade.blade_modes`); empty when none rings.
    amplitude_checks : tuple of AmplitudeCheck
        Each frequency measured at several input amplitudes, its gains compared
        (:func:`~servoscope.sysid.gain_against_amplitude`); empty otherwise.
    servo_model : ServoModelSelection or None
        The time-domain models fitted to the whole traces (``identify(nonlinear=...)``,
        :mod:`servoscope.campaign.joint`); None without.
    predicted_step_fit_percent : float or None
        The step's fit by the frequency-domain model, fitted without it (2nd order only).
    heave_response : tuple of HeaveRow
        Each dwell's heave at its input frequency (:func:`servoscope.campaign.blade.heave_response`);
        empty when no dwell shows any (a rigid blade).
    bending_response : tuple of HeaveRow
        Each extra marker's bending at each dwell's input frequency
        (:func:`servoscope.campaign.blade.bending_response`); empty with two markers.
    heave_model : HeaveModel or None
        The flapping frequency response fitted (heave over pitch as a mode,
        :func:`servoscope.campaign.blade.heave_model`); its mode is also in ``modes``.
    view : ObliqueView or None
        The camera's view of the blade's plane as the markers' separation tells it
        (:func:`servoscope.pipeline.plane_view.pooled_view`): of the image's positions
        without a plane, of the plane's with one (a check of the plane); None with too
        few frames.
    plane : dict or None
        The plane the angles were measured in (its summary: file, view angle, reprojection
        error, angle-gain uncertainty), ``{"source": "self-calibrated (stickers' shapes)"}`` after
        ``self_calibrate_plane``; None: the image.
    sweeps : mapping of label → SweepResponse
        Each frequency sweep's spectral response with coherence (:mod:`servoscope.campaign.sweeps`);
        its points with coherence ≥ 0.6 are in `frequency_response` beside the dwells'.
    rotor : dict or None
        A turning rotor's campaign (``[rotor]``, :mod:`servoscope.campaign.rotor`): its blades, rev/s
        and passes per test, each blade's pitch offset from blade 0 pooled over the dwells with its
        interval; its tracks' samples are the passes. None for a static blade.
    """

    campaign: Campaign
    tracks: Mapping[str, Track]
    sine_fits: Mapping[str, SineFit]
    frequency_response: FrequencyResponse
    model: TransferFunctionFit
    step: StepAnalysis | None = None
    step_label: str | None = None
    warnings: tuple[str, ...] = ()
    exposure: ExposureEstimate | None = None
    shared_t0_stderr_s: float = 0.0
    amplitude_checks: tuple[AmplitudeCheck, ...] = ()
    modes: tuple[ModeFit, ...] = ()
    servo_model: ServoModelSelection | None = None
    predicted_step_fit_percent: float | None = None
    heave_response: tuple[HeaveRow, ...] = ()
    bending_response: tuple[HeaveRow, ...] = ()
    heave_model: HeaveModel | None = None
    view: ObliqueView | None = None
    plane: dict | None = None
    sweeps: Mapping[str, SweepResponse] = field(default_factory=dict)
    rotor: dict | None = None

    def __post_init__(self) -> None:
        # Lists given (the runner's, a notebook's) kept as tuples, dicts as read-only views of a copy.
        for name in ("warnings", "amplitude_checks", "modes", "heave_response", "bending_response"):
            object.__setattr__(self, name, tuple(getattr(self, name)))
        for name in ("tracks", "sine_fits", "sweeps"):
            object.__setattr__(self, name, MappingProxyType(dict(getattr(self, name))))

    @property
    def transfer_function(self):
        """The identified model as a python-control TransferFunction (without the delay)."""
        return self.model.transfer_function

    @cached_property
    def headline(self) -> Headline:
        """The model this result states first (:func:`servoscope.campaign.headline.headline`): the selected
        time-domain model when it is nonlinear, else the transfer function with its better dead time.

        Made once: the result is frozen, and every view (tables, report, result.json) reads it.
        """
        return headline(self)

    @property
    def parameters(self):
        """The headline's parameters (:class:`~servoscope.parameters.Parameters`): what every view shows first."""
        return self.headline.parameters

    @property
    def dead_time_s(self) -> float | None:
        """The headline's dead time: the more precise of the step test's (LED off → blade moving, fitted
        against the model) and the dwells' phases' (complex fit), or the selected nonlinear model's; None
        without any. Its stderr and interval are the same estimate's."""
        p = self.parameters.get("dead_time_s")
        return None if p is None else p.value

    @property
    def bandwidth_rad_s(self) -> float:
        """The headline model's −3 dB bandwidth, rad/s (the selected nonlinear model's linear part's)."""
        if self.headline.domain == "time domain":
            return bandwidth_rad_s(self.servo_model.selected.linear_transfer_function)
        return self.model.bandwidth_rad_s

    @property
    def dead_time_source(self) -> str | None:
        """Where :attr:`dead_time_s` comes from: "step test", "frequency response (phase)" or the selected
        nonlinear model ("backlash model (fitted to the whole traces)")."""
        return self.headline.dead_time_source

    @property
    def dead_time_estimates(self) -> dict[str, DeadTimeEstimate | None]:
        """The dead time from the dwells' phases and from the step, each with its interval
        (:func:`servoscope.sysid.dead_time.dead_time_estimates`)."""
        return dead_time_estimates(self.model, self.step, self.shared_t0_stderr_s)

    @property
    def dead_time_stderr_s(self) -> float | None:
        """Standard error of :attr:`dead_time_s`, from the same estimate."""
        p = self.parameters.get("dead_time_s")
        return None if p is None else p.stderr

    def summary(self) -> dict:
        """The content of ``result.json``: plain types only."""
        head = self.headline
        estimates = self.dead_time_estimates
        frequency_domain = self._frequency_domain_summary(estimates)
        extra: dict[str, Any] = {}
        if head.domain == "time domain":
            model = self._time_domain_summary(head)
            extra["frequency_domain_model"] = {
                **frequency_domain, "describes": (
                    f"the dwells' fundamentals at their input amplitudes: a describing function of the "
                    f"{head.structure} servo, not its linear part (see model)")}
            source_key = TIME_DOMAIN_KEY
        else:
            model = {**frequency_domain, **self._structure_summary(frequency_domain), "domain": head.domain}
            source_key = SOURCE_KEYS.get(head.dead_time_source or "")
        model["parameters"] = head.parameters.summary()
        dead_time = {k: None if e is None else e.summary() for k, e in estimates.items()}
        if source_key == TIME_DOMAIN_KEY and "dead_time_s" in head.parameters:
            p = head.parameters["dead_time_s"]
            dead_time[TIME_DOMAIN_KEY] = {"value_s": p.value, "stderr_s": p.stderr, "ci95_s": list(p.ci95),
                                          "shared_t0_stderr_s": None}
        tests = [self._test_summary(test) for test in self.campaign.tests]
        return jsonable(
            {
                "servoscope_version": package_version(),
                "campaign": str(self.campaign.path),
                "input_units": self.campaign.input_units,
                "output_units": "rad",
                "model": model,
                "bandwidth_rad_s": model.get("bandwidth_rad_s"),
                "bandwidth_hz": None if model.get("bandwidth_rad_s") is None else model["bandwidth_rad_s"] / (2 * math.pi),
                "dead_time_s": self.dead_time_s,
                "dead_time": {**dead_time, "source": source_key},
                **extra,
                "exposure": None if self.exposure is None else self.exposure.summary(),
                **({"gain_against_amplitude": [c.summary() for c in self.amplitude_checks]}
                   if self.amplitude_checks else {}),
                **({"modes": [m.summary() for m in self.modes]} if self.modes else {}),
                **({"heave_response": [r.summary() for r in self.heave_response]} if self.heave_response else {}),
                **({"bending_response": [r.summary() for r in self.bending_response]}
                   if self.bending_response else {}),
                **({"heave_model": self.heave_model.summary()} if self.heave_model is not None else {}),
                **({"view": self.view.summary()} if self.view is not None else {}),
                **({"plane": self.plane} if self.plane is not None else {}),
                **({"extra_markers": list(self.campaign.extra)} if self.campaign.extra else {}),
                "frequency_response": self.frequency_response.summary(),
                **({"sweeps": {k: v.summary() for k, v in self.sweeps.items()}} if self.sweeps else {}),
                **({"rotor": self.rotor} if self.rotor is not None else {}),
                "step": None if self.step is None else {"label": self.step_label, **self.step.summary(),
                                                        **self._step_fits()},
                "tests": tests,
                "skipped": [{"label": label, "reason": reason} for label, reason in self.campaign.skipped],
                "warnings": list(self.warnings),
            }
        )

    def _test_summary(self, test: TestSpec) -> dict:
        """One test's entry in result.json's ``tests``."""
        track = self.tracks[test.label]
        entry = {
            "label": test.label,
            "video": test.video.name,
            "kind": test.kind,
            "frequency_hz": test.frequency_hz,
            "amplitude": test.amplitude,
            "frames": track.n_frames,
            "valid_frames": track.n_valid,
            "t0_s": input_start(test, track),
            "t0_uncertainty_s": input_start_stderr(test, track),
            "warnings": list(track.warnings),
        }
        if test.kind == "sweep":  # a recorded input's file, band and samples too
            entry.update(from_hz=test.from_hz, to_hz=test.to_hz, duration_s=test.duration_s, shape=test.shape,
                         **(recorded_input_entry(test) if test.recorded else {}))
        pivot = pivot_motion(track.lead_xy_px, track.trail_xy_px, track.valid)
        entry["pivot_motion_px"] = None if pivot is None else pivot.rms_px
        if track.reference_angle_rad is not None:
            # How much the airframe's reference line turned in this video (taken off the angle).
            entry["reference_motion_rad"] = track.reference_motion()
        fit = self.sine_fits.get(test.label)
        if fit is not None:
            entry["sine_fit"] = jsonable(fit.summary())
            entry["warnings"] += list(fit.warnings)
        return entry

    def _frequency_domain_summary(self, estimates: dict) -> dict:
        """The transfer-function fit's summary with the dead time its result states (the better estimate).

        The fit's own delay (from the phases) stays as ``dead_time_from_phase_s``; ``dead_time_s``,
        its stderr and interval are the chosen estimate's (one name, one estimator).
        """
        model = dict(jsonable(self.model.summary()))
        source, chosen = chosen_dead_time(estimates)
        phase = estimates["phase"]
        model["dead_time_from_phase_s"] = model.get("dead_time_s")
        model["dead_time_from_phase_stderr_s"] = None if phase is None else phase.stderr_s
        model["dead_time_s"] = None if chosen is None else chosen.value_s
        model["dead_time_source"] = source
        model["dead_time_stderr_s"] = None if chosen is None else chosen.stderr_s
        if chosen is not None and isinstance(model.get("ci95"), dict):
            model["ci95"] = {**model["ci95"], "dead_time_s": list(chosen.ci95_s)}
        return model

    def _time_domain_summary(self, head: Headline) -> dict:
        """result.json's ``model`` when the headline is the selected nonlinear model: its parameters
        under the names the transfer function's use, the candidates and the time-domain fits."""
        sel = self.servo_model.selected
        p = head.parameters
        return {"domain": head.domain, "structure": sel.structure, "order": [0, 2], "mode": "time domain",
                "equation": head.equation, **{k: v.value for k, v in p.items()},
                **{f"{k}_stderr": p[k].stderr for k in ("gain", "damping_ratio")},
                "natural_frequency_stderr_rad_s": p["natural_frequency_rad_s"].stderr,
                "dead_time_stderr_s": p["dead_time_s"].stderr, "dead_time_source": head.dead_time_source,
                "params": {k: v.value for k, v in p.items()}, "stderr": {k: v.stderr for k, v in p.items()},
                "ci95": {k: list(v.ci95) for k, v in p.items()}, "fixed": sorted(sel.fixed), "tied": dict(sel.tied),
                **{k: v for k, v in self._structure_summary({}).items() if k in ("candidates", "time_domain")},
                "bandwidth_rad_s": self.bandwidth_rad_s}

    def _structure_summary(self, model: dict) -> dict:
        """result.json's ``model`` additions: the structure, its parameter beside the linear ones, the candidates.

        With a time-domain fit (``identify --nonlinear``) the selected structure's own
        parameter sits in ``model``, ``model.stderr`` and ``model.ci95``; ``model.time_domain``
        holds every candidate's whole fit (its linear part too) and the cross-validation.
        """
        held = [k for k, v in (model.get("held") or {}).items() if isinstance(v, dict) and "fixed" in v]
        if self.servo_model is None:
            return {"structure": "linear", "fixed": held}
        sel = self.servo_model.selected
        out: dict[str, Any] = {"structure": sel.structure,
                               "fixed": sorted(set(held) | set(sel.fixed)),
                               "candidates": [{"structure": c.structure, "aic": c.aic, "bic": c.bic, "J": c.J,
                                               "step_fit_percent": c.step_fit_percent} for c in self.servo_model.candidates],
                               "time_domain": self.servo_model.summary()}
        name = sel.nonlinear_parameter
        if name is not None:
            out[name] = sel.params[name]
            out["stderr"] = {**(model.get("stderr") or {}), name: sel.stderr[name]}
            out["ci95"] = {**(model.get("ci95") or {}), name: list(sel.ci95[name])}
        return out

    def _step_fits(self) -> dict:
        """The step's fit (percent) by the selected time-domain model, and as predicted from the dwells alone."""
        if self.servo_model is not None:
            cv = self.servo_model.cross_validation.get("dwells_to_step") or {}
            return {"fit_percent": self.servo_model.selected.step_fit_percent,
                    "predicted_fit_percent": cv.get("fit_percent")}
        fit = None
        residual = None if self.step is None else self.step.residual
        if residual is not None:
            # The step analysis's own fit of the model's shape (its dead time and level fitted to the step).
            y = self.step.y[self.step.time_s >= self.step.t0_s]
            ok = np.isfinite(y) & np.isfinite(residual)
            value = fit_percent(y[ok], y[ok] - residual[ok]) if ok.any() else math.nan
            fit = value if math.isfinite(value) else None
        return {"fit_percent": fit, "predicted_fit_percent": self.predicted_step_fit_percent}

    def write_tables(self, out_dir: str | Path) -> dict[str, Path]:
        """Write tracks/<label>.csv and frequency_response.csv, each whole or not at all.

        Returns
        -------
        dict of name → path written (``"tracks"``: the folder)
        """
        out = Path(out_dir)
        (out / "tracks").mkdir(parents=True, exist_ok=True)
        for label, track in self.tracks.items():
            with atomic_path(out / "tracks" / f"{label}.csv") as tmp:
                track.to_csv(tmp)
        paths = {"tracks": out / "tracks", "frequency_response": out / "frequency_response.csv"}
        with atomic_path(paths["frequency_response"]) as tmp:
            self.frequency_response.to_csv(tmp)
        return paths

    def write_summary(self, out_dir: str | Path) -> Path:
        """Write result.json (:meth:`summary`); written last, its presence says a run finished."""
        path = Path(out_dir) / "result.json"
        path.parent.mkdir(parents=True, exist_ok=True)
        write_json_atomic(path, self.summary())
        return path

    def write(self, out_dir: str | Path) -> dict[str, Path]:
        """Write the result's data: tracks/<label>.csv, frequency_response.csv, then result.json.

        The HTML report and its figures are the report stage's:
        :func:`servoscope.write_report` writes these files and the report.

        Returns
        -------
        dict of name → path written
        """
        paths = self.write_tables(out_dir)
        paths["result"] = self.write_summary(out_dir)
        return paths

    @classmethod
    def load(cls, path: str | Path) -> "IdentificationResult":
        """Read a result back from what :meth:`write` (or ``servoscope identify``) wrote.

        Parameters
        ----------
        path : path-like
            The result's ``result.json``, or the folder holding it (with its ``tracks/``).

        Returns
        -------
        IdentificationResult
            Its :meth:`summary` equals the file's (floats to the last bit or two: the model
            is rebuilt from its parameters), its tracks are the CSVs' and its model is a
            working python-control transfer function. The campaign is the one result.json
            describes (its tests, units and the videos left out); when its manifest is
            still where the result says, the markers' colours and the camera come from it.
            Not in the files, so not back: the bootstrap's samples, the order comparison,
            each dwell's covariance, the stickers' second moments, the step's prediction
            curve (rebuilt from the model only where it is a plain rational function).

        Raises
        ------
        ServoscopeError
            When the file is missing, not JSON, or not a servoscope result.
        """
        import json

        from ..errors import ServoscopeError
        from .manifest import load_campaign

        path = Path(path)
        if path.is_dir():
            path = path / "result.json"
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise ServoscopeError(f"{path}: no such result (give the result.json that servoscope identify wrote)") from None
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ServoscopeError(f"{path}: not a servoscope result.json ({exc})") from None
        if not isinstance(data, dict) or not {"model", "frequency_response", "tests"} <= set(data):
            raise ServoscopeError(f"{path}: not a servoscope result.json (no model, frequency_response or tests)")
        folder = path.parent
        tests, tracks, fits = [], {}, {}
        for entry in data["tests"]:
            label = entry["label"]
            csv = folder / "tracks" / f"{label}.csv"
            if not csv.exists():
                raise ServoscopeError(f"{csv}: missing; a result is read with its tracks/ folder beside result.json")
            track = Track.from_csv(csv, video=entry["video"])
            sf = entry.get("sine_fit")
            fit_warnings = [] if sf is None else sf.get("warnings", [])  # the test's warnings hold its fit's too
            more = {}
            if track.extra_xy_px is not None and data.get("extra_markers"):
                more["extra_colours"] = tuple(data["extra_markers"])  # the table holds their columns, not colours
            track = replace(track, t0_s=entry.get("t0_s"), t0_uncertainty_s=entry.get("t0_uncertainty_s"),
                            warnings=tuple(w for w in entry.get("warnings", []) if w not in fit_warnings), **more)
            tracks[label] = track
            tests.append(TestSpec(video=Path(entry["video"]), kind=entry["kind"], amplitude=entry["amplitude"],
                                  frequency_hz=entry.get("frequency_hz"), label=label,
                                  **{k: entry[k] for k in ("from_hz", "to_hz", "duration_s", "shape") if k in entry},
                                  **recorded_input_fields(entry, path)))
            if sf is not None:
                lo, hi = sf["window_s"]
                inside = track.valid & (track.angle_time_s >= lo) & (track.angle_time_s <= hi)
                kind = PassSineFit if "rotor" in sf else SineFit  # a turning rotor's dwell: its passes' fit
                fits[label] = kind.from_summary(sf, time_s=track.angle_time_s[inside], y=track.angle_rad[inside])
        campaign = _loaded_campaign(data, tests, path, load_campaign)
        fr = FrequencyResponse.from_summary(data["frequency_response"])
        # Since issue 30 a nonlinear headline is `model` and the transfer function sits beside it.
        model = TransferFunctionFit.from_summary(_fit_part(data.get("frequency_domain_model") or data["model"]), data=fr)
        step = None
        if data.get("step") is not None:
            summary = dict(data["step"])
            label = summary.pop("label")
            track = tracks[label]
            unit_step = None
            td = data["model"].get("time_domain")
            shape = model.transfer_function
            if summary.get("model_source", "frequency-domain model") != "frequency-domain model" and td is not None:
                shape = ServoModelSelection.from_summary(td).selected.linear_transfer_function
            if summary.get("dead_time_s") is not None and track.n_frames > 1:
                # The model's step shape, as analyse_step made it for the fit (same span and step).
                t = track.angle_time_s[track.valid]
                unit_step = unit_step_function(shape, float(t[-1] - summary["t0_s"]) + 1.0,
                                               float(np.median(np.diff(t))))
            step = StepAnalysis.from_summary(summary, time_s=track.angle_time_s, y=track.angle_rad,
                                             unit_step=unit_step)
        exposure = None if data.get("exposure") is None else ExposureEstimate.from_summary(data["exposure"])
        shared = (data.get("dead_time", {}).get("phase") or {}).get("shared_t0_stderr_s") or 0.0
        checks = [AmplitudeCheck.from_summary(c) for c in data.get("gain_against_amplitude", [])]
        modes = [ModeFit.from_summary(m) for m in data.get("modes", [])]
        td = data["model"].get("time_domain")
        selection = None if td is None else ServoModelSelection.from_summary(td)
        predicted = None if data.get("step") is None else data["step"].get("predicted_fit_percent")
        return cls(
            campaign=campaign, tracks=tracks, sine_fits=fits, frequency_response=fr, model=model, step=step,
            step_label=None if step is None else data["step"]["label"], warnings=tuple(data.get("warnings", [])),
            exposure=exposure, shared_t0_stderr_s=float(shared), amplitude_checks=checks, modes=modes,
            servo_model=selection, predicted_step_fit_percent=predicted if selection is None else None,
            heave_response=[HeaveRow.from_summary(r) for r in data.get("heave_response", [])],
            bending_response=[HeaveRow.from_summary(r) for r in data.get("bending_response", [])],
            heave_model=None if data.get("heave_model") is None else HeaveModel.from_summary(data["heave_model"]),
            view=None if data.get("view") is None else ObliqueView.from_summary(data["view"]),
            plane=data.get("plane"), rotor=data.get("rotor"),
            sweeps={k: SweepResponse.from_summary(v) for k, v in (data.get("sweeps") or {}).items()})

    def plot(self, ax: Axes | None = None, *, phase_ax: Axes | None = None) -> list[Any]:
        """The Bode plot: the dwells' gains (±1 standard error) and the fitted model's.

        Parameters
        ----------
        ax : matplotlib.axes.Axes, optional
            Axes for the gains in dB against ω in rad/s (a new figure's when None).
        phase_ax : matplotlib.axes.Axes, optional
            Axes for the phases in degrees (measured, and the model's with its dead time).

        Returns
        -------
        list
            The artists, as :meth:`TransferFunctionFit.plot` returns them: the measured
            points', then the model's gain line and, with `phase_ax`, its phase line.
        """
        model = self.model if self.model.data is not None else replace(self.model, data=self.frequency_response)
        return model.plot(ax, phase_ax=phase_ax)

    def _repr_html_(self) -> str:
        # The headline's table (FitResult's), under the model's equation: the numbers the report
        # and `identify` show first.
        head = self.headline
        return f"<p>{head.equation}</p>" + head._repr_html_()


def package_version() -> str:
    """servoscope's version, as written into result.json."""
    from .. import __version__

    return __version__

