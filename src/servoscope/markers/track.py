"""A tracked video's per-frame measurements (:class:`Track`): summary, tables, CSV."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import ServoscopeError
from .error_analysis import angle_error_analysis

__all__ = ["Track", "marker_names"]


def marker_names(n_extra: int) -> list[str]:
    """The markers' names in a track's column order: ``lead``, ``trail``, ``extra1`` … ``extra<n_extra>``."""
    return ["lead", "trail", *(f"extra{k + 1}" for k in range(n_extra))]


@dataclass(frozen=True)
class Track:
    """Per-frame measurements of one video.

    Frozen: what a later stage adds (a view's correction, a warning) makes a new
    track (:func:`dataclasses.replace`). Its arrays are not copied and not locked.

    Arrays have one entry per decoded frame. Coordinates are pixels in the
    ideal (undistorted) image when a camera model was given, else in the
    recorded image; with a plane (``TrackerSettings.plane``), the plane's
    rectified pixels (:meth:`~servoscope.camera.plane.Plane.to_rectified`:
    ``plane_mm_per_px`` mm each), the areas and shapes staying the recorded
    image's.

    Attributes
    ----------
    video : str
    frame : ndarray of int
    time_s : ndarray
        Presentation times from the video's PTS.
    lead_xy_px, trail_xy_px : ndarray, shape (n, 2)
        Centroids; NaN where not found.
    lead_area_px, trail_area_px : ndarray
        Soft areas (m00).
    angle_rad : ndarray
        θ = atan2(y_trail − y_lead, x_lead − x_trail), unwrapped; NaN where invalid.
    valid : ndarray of bool
    reason : list of str
        Why a frame is invalid ("" when valid).
    led_level : ndarray
        LED brightness normalised to 1 lit, 0 off; NaN without an LED.
    t0_s : float or None
        LED switch-off time (the input's start), sub-frame.
    t0_uncertainty_s : float or None
    warnings : tuple of str
        (A list given is kept as a tuple.)
    snapshot_rgb : ndarray or None
        One frame, for drawing the detected centroids on it.
    snapshot_index : int
    lead_sigma_px, trail_sigma_px : ndarray
        Standard uncertainty of each centroid coordinate from pixel noise
        (px); NaN where not found.
    angle_sigma_rad : ndarray
        Standard uncertainty of the angle propagated from both centroids'
        (rad); NaN where invalid.
    angle_time_s : ndarray
        When the angle was sampled: ``time_s`` for a global shutter; with a
        rolling shutter, ``time_s + readout_s·y_eff/height``, y_eff the
        markers' rows weighted by their share of the angle's motion (see
        :func:`servoscope.camera.rolling_shutter.angle_row_weights`). Fit the angle against this.
    readout_s : float
        Rolling-shutter readout time the track was corrected for (0: none).
    t0_earliest_s, t0_latest_s : float or None
        The interval the switch can lie in (the unexposed gap when no frame
        was partly lit; see :class:`~servoscope.markers.led_timing.SwitchTime`).
    led_partial_frames : int or None
        Partly lit frames at the switch (0, 1 or 2): evidence of the
        exposure, pooled over a campaign by
        :func:`servoscope.camera.exposure.estimate_exposure`.
    lead_shape_px2, trail_shape_px2 : ndarray, shape (n, 3)
        Each sticker's central second moments (mu20, mu11, mu02) of its soft
        membership, divided by its area (px², the recorded image's pixels);
        NaN where not found. Motion during the exposure stretches them along
        the motion: the evidence of the shutter that
        :func:`servoscope.camera.exposure.blur_evidence` reads.
    reference_angle_rad : ndarray or None
        With reference stickers on the airframe (``TrackerSettings.reference``):
        the angle of the line joining them, less its median (rad; NaN where not
        measured): the picture's own rotation, already taken off ``angle_rad``.
        None without reference stickers.
    intra : ndarray of bool or None
        Frames the codec coded on their own (I-frames; every frame of
        uncompressed video); None when unknown. ``fit_sine`` checks the
        other frames' sine against theirs (the codec check).
    extra_colours : tuple of str
        The extra markers' colours as given (``TrackerSettings.extra``); empty
        with two markers, and then every ``extra_*`` and ``bending_px`` field is None.
    extra_xy_px : ndarray, shape (n, k, 2) or None
        The extra markers' centroids; NaN where not found.
    extra_sigma_px : ndarray, shape (n, k) or None
        Their centroid uncertainty (px).
    bending_px : ndarray, shape (n, 2 + k) or None
        Each marker's (lead, trail, extras) distance across the chord line
        through the lead and trail markers from its place on the blade (the
        median over the track; px, up positive; see
        :func:`servoscope.angle.rigid_motion`); NaN where invalid. The lead's
        and trail's are 0: they define the line.
    plane : str or None
        The plane the positions were measured in (its file's name), or how it was
        found (``"self-calibrated (affine)"``); None: the image.
    plane_mm_per_px : float or None
        Millimetres in the plane per position pixel (None without a plane).
    """

    video: str
    frame: np.ndarray
    time_s: np.ndarray
    lead_xy_px: np.ndarray
    trail_xy_px: np.ndarray
    lead_area_px: np.ndarray
    trail_area_px: np.ndarray
    angle_rad: np.ndarray
    valid: np.ndarray
    reason: list[str]
    led_level: np.ndarray
    t0_s: float | None = None
    t0_uncertainty_s: float | None = None
    warnings: tuple[str, ...] = ()
    snapshot_rgb: np.ndarray | None = None
    snapshot_index: int = 0
    lead_sigma_px: np.ndarray | None = None
    trail_sigma_px: np.ndarray | None = None
    angle_sigma_rad: np.ndarray | None = None
    angle_time_s: np.ndarray | None = None
    readout_s: float = 0.0
    intra: np.ndarray | None = None
    t0_earliest_s: float | None = None
    t0_latest_s: float | None = None
    led_partial_frames: int | None = None
    lead_shape_px2: np.ndarray | None = None
    trail_shape_px2: np.ndarray | None = None
    reference_angle_rad: np.ndarray | None = None
    extra_colours: tuple[str, ...] = ()
    extra_xy_px: np.ndarray | None = None
    extra_sigma_px: np.ndarray | None = None
    bending_px: np.ndarray | None = None
    plane: str | None = None
    plane_mm_per_px: float | None = None

    def __post_init__(self) -> None:
        # Tracks built by older code (or by hand) lack the uncertainty columns.
        n = int(np.asarray(self.frame).size)
        # (Frozen: filled in once, here, through object.__setattr__.)
        for name in ("lead_sigma_px", "trail_sigma_px", "angle_sigma_rad"):
            if getattr(self, name) is None:
                object.__setattr__(self, name, np.full(n, np.nan))
        for name in ("lead_shape_px2", "trail_shape_px2"):
            if getattr(self, name) is None:
                object.__setattr__(self, name, np.full((n, 3), np.nan))
        # A list (JSON's, the cache's) is the same colours, and the same warnings.
        object.__setattr__(self, "extra_colours", tuple(self.extra_colours))
        object.__setattr__(self, "warnings", tuple(self.warnings))
        # ...and the angle's sample times: a global shutter's are the frame times.
        if self.angle_time_s is None:
            object.__setattr__(self, "angle_time_s", np.array(self.time_s, dtype=np.float64))

    @property
    def n_frames(self) -> int:
        """Number of decoded frames (or fields)."""
        return int(self.frame.size)

    @property
    def n_valid(self) -> int:
        """Number of frames with both markers measured."""
        return int(np.count_nonzero(self.valid))

    @property
    def separation_px(self) -> np.ndarray:
        """Distance between the two centroids per frame (px); NaN where invalid."""
        d = np.hypot(*(self.lead_xy_px - self.trail_xy_px).T)
        return np.where(self.valid, d, np.nan)

    def summary(self) -> dict:
        """Plain-typed summary: counts, sticker separation, noise, LED time.

        Keys ``video, frames, valid_frames, t0_s, t0_uncertainty_s, warnings``
        plus ``valid_fraction``, ``mean_separation_px``,
        ``centroid_sigma_px`` (median per-frame centroid uncertainty),
        ``angle_noise_rad`` (the statistical angle error from pixel noise,
        see :func:`servoscope.markers.angle_error_analysis`) and
        ``angle_noise_measured_rad`` (the tracking error measured on the
        markers' rigid-motion null channel, codec errors included; None
        with fewer than 20 valid frames; from the separation's spread when
        the camera shakes), ``camera_shake_px`` (the shake seen, RMS px).
        """
        analysis = angle_error_analysis(self) if self.n_valid else {}
        return {
            "video": self.video,
            "frames": self.n_frames,
            "valid_frames": self.n_valid,
            "valid_fraction": (self.n_valid / self.n_frames) if self.n_frames else 0.0,
            "mean_separation_px": analysis.get("separation_px"),
            # In a plane: its name, and the separation in its millimetres.
            **({} if self.plane is None else {
                "plane": self.plane,
                "mean_separation_mm": None if analysis.get("separation_px") is None or self.plane_mm_per_px is None
                else float(analysis["separation_px"]) * float(self.plane_mm_per_px)}),
            "centroid_sigma_px": analysis.get("centroid_sigma_px"),
            "angle_noise_rad": analysis.get("angle_sigma_rad"),
            "angle_noise_measured_rad": analysis.get("measured_noise_rad"),
            "camera_shake_px": analysis.get("camera_shake_px"),
            "t0_s": self.t0_s,
            "t0_uncertainty_s": self.t0_uncertainty_s,
            # Where t0 can lie, and how many frames at the switch were partly lit (the
            # exposure's evidence: none when the switch fell between two exposures).
            "t0_interval_s": None if self.t0_earliest_s is None else [self.t0_earliest_s, self.t0_latest_s],
            "led_partial_frames": self.led_partial_frames,
            "warnings": list(self.warnings),
        }

    def reference_motion(self) -> dict[str, float] | None:
        """How much the reference line turned (rad): ``{"rms", "peak_to_peak"}``; None without one measured."""
        if self.reference_angle_rad is None:
            return None
        motion = self.reference_angle_rad[np.isfinite(self.reference_angle_rad)]
        return None if motion.size == 0 else {"rms": float(np.std(motion)), "peak_to_peak": float(np.ptp(motion))}

    def columns(self) -> dict[str, np.ndarray]:
        """The per-frame table as a dict of columns (pandas-free)."""
        return {
            "frame": self.frame,
            "time_s": self.time_s,
            "angle_rad": self.angle_rad,
            "valid": self.valid.astype(np.int64),
            "lead_x_px": self.lead_xy_px[:, 0],
            "lead_y_px": self.lead_xy_px[:, 1],
            "trail_x_px": self.trail_xy_px[:, 0],
            "trail_y_px": self.trail_xy_px[:, 1],
            "lead_area_px": self.lead_area_px,
            "trail_area_px": self.trail_area_px,
            "lead_sigma_px": self.lead_sigma_px,
            "trail_sigma_px": self.trail_sigma_px,
            "angle_sigma_rad": self.angle_sigma_rad,
            "led_level": self.led_level,
            "angle_time_s": self.angle_time_s,
            **({} if self.intra is None else {"intra": np.asarray(self.intra).astype(np.int64)}),
            **({} if self.reference_angle_rad is None else {"reference_angle_rad": self.reference_angle_rad}),
            **self._extra_columns(),
            **self._plane_columns(),
        }

    def _plane_columns(self) -> dict[str, np.ndarray]:
        """The centroids in the plane's millimetres, when they were measured in a plane."""
        if self.plane_mm_per_px is None:
            return {}
        k = float(self.plane_mm_per_px)
        return {"lead_x_mm": k * self.lead_xy_px[:, 0], "lead_y_mm": k * self.lead_xy_px[:, 1],
                "trail_x_mm": k * self.trail_xy_px[:, 0], "trail_y_mm": k * self.trail_xy_px[:, 1]}

    def _extra_columns(self) -> dict[str, np.ndarray]:
        """Extra markers' centroids (``extra1_x_px`` …) and every marker's bending, when there are extra markers."""
        if self.extra_xy_px is None or self.bending_px is None:
            return {}
        cols: dict[str, np.ndarray] = {}
        for k in range(self.extra_xy_px.shape[1]):
            cols[f"extra{k + 1}_x_px"] = self.extra_xy_px[:, k, 0]
            cols[f"extra{k + 1}_y_px"] = self.extra_xy_px[:, k, 1]
            cols[f"extra{k + 1}_sigma_px"] = self.extra_sigma_px[:, k]
        for k, name in enumerate(marker_names(len(self.extra_colours))):
            cols[f"{name}_bending_px"] = self.bending_px[:, k]
        return cols

    def to_pandas(self):
        """The per-frame table as a pandas DataFrame (pandas is optional)."""
        try:
            import pandas as pd
        except ImportError as exc:  # pragma: no cover - depends on the environment
            raise ImportError("Track.to_pandas() needs pandas: pip install pandas") from exc
        df = pd.DataFrame(self.columns())
        df["reason"] = self.reason
        return df

    @classmethod
    def from_csv(cls, path: str | Path, *, video: str | None = None) -> "Track":
        """Read a track back from :meth:`to_csv`'s table.

        Parameters
        ----------
        path : path-like
            A track CSV (``tracks/<label>.csv`` of a result, or ``servoscope track``'s).
        video : str, optional
            The video's name (default: the CSV's stem).

        Returns
        -------
        Track
            The per-frame columns as written (floats to the last bit); what the table does
            not hold (the LED's switch time, warnings, the snapshot, the stickers' second
            moments) is left unset: a result's loader fills t0 from result.json.

        Raises
        ------
        ServoscopeError
            When the file is not a track table (its header lacks a column).
        """
        path = Path(path)
        lines = path.read_text(encoding="utf-8").splitlines()
        names = lines[0].split(",") if lines else []
        need = ["frame", "time_s", "angle_rad", "valid", "lead_x_px", "lead_y_px", "trail_x_px", "trail_y_px", "reason"]
        missing = [n for n in need if n not in names]
        if missing:
            raise ServoscopeError(f"{path}: not a servoscope track table (no column {', '.join(missing)})")
        rows = [line.split(",", len(names) - 1) for line in lines[1:]]
        cols = {n: [r[i] for r in rows] for i, n in enumerate(names)}

        def num(name: str) -> np.ndarray | None:
            if name not in cols:
                return None
            return np.array([float(v) if v else np.nan for v in cols[name]], dtype=np.float64)

        return cls(
            video=video or path.stem,
            frame=np.array([int(v) for v in cols["frame"]], dtype=np.int64),
            time_s=num("time_s"),
            lead_xy_px=np.stack([num("lead_x_px"), num("lead_y_px")], axis=1).reshape(-1, 2),
            trail_xy_px=np.stack([num("trail_x_px"), num("trail_y_px")], axis=1).reshape(-1, 2),
            lead_area_px=num("lead_area_px") if "lead_area_px" in cols else np.full(len(rows), np.nan),
            trail_area_px=num("trail_area_px") if "trail_area_px" in cols else np.full(len(rows), np.nan),
            angle_rad=num("angle_rad"),
            valid=np.array([v == "1" for v in cols["valid"]], dtype=bool),
            reason=list(cols["reason"]),
            led_level=num("led_level") if "led_level" in cols else np.full(len(rows), np.nan),
            lead_sigma_px=num("lead_sigma_px"),
            trail_sigma_px=num("trail_sigma_px"),
            angle_sigma_rad=num("angle_sigma_rad"),
            angle_time_s=num("angle_time_s"),
            intra=None if "intra" not in cols else np.array([v == "1" for v in cols["intra"]], dtype=bool),
            reference_angle_rad=num("reference_angle_rad"),
            **_extra_from_columns(num, len(rows)),
            plane_mm_per_px=_mm_per_px(num),
        )

    def to_csv(self, path: str | Path) -> None:
        """Write the per-frame table (``frame,time_s,angle_rad,valid,…``)."""
        cols = self.columns()
        names = list(cols) + ["reason"]
        lines = [",".join(names)]
        for i in range(self.n_frames):
            row = []
            for name in names[:-1]:
                value = cols[name][i]
                if name in ("frame", "valid", "intra"):
                    row.append(str(int(value)))
                elif np.isnan(value):
                    row.append("")
                else:
                    row.append(repr(float(value)))
            row.append(self.reason[i].replace(",", ";"))
            lines.append(",".join(row))
        Path(path).write_text("\n".join(lines) + "\n")


def _mm_per_px(num) -> float | None:
    """The plane's mm per px from a table's ``lead_x_mm`` beside ``lead_x_px`` (None without them)."""
    mm, px = num("lead_x_mm"), num("lead_x_px")
    if mm is None or px is None:
        return None
    ok = np.isfinite(mm) & np.isfinite(px) & (np.abs(px) > 1.0)
    return float(np.median(mm[ok] / px[ok])) if ok.any() else None


def _extra_from_columns(num, n_rows: int) -> dict:
    """A track table's extra markers' columns back as :class:`Track` fields (none without extra markers).

    The table does not hold their colours: they come back as ``""`` (a result's loader knows them).
    """
    k = 0
    while num(f"extra{k + 1}_x_px") is not None:
        k += 1
    if k == 0:
        return {}
    names = marker_names(k)
    out = {
        "extra_colours": ("",) * k,
        "extra_xy_px": np.stack([np.stack([num(f"extra{j + 1}_x_px"), num(f"extra{j + 1}_y_px")], axis=1)
                                 for j in range(k)], axis=1).reshape(n_rows, k, 2),
        "extra_sigma_px": np.stack([num(f"extra{j + 1}_sigma_px") for j in range(k)], axis=1).reshape(n_rows, k),
        "bending_px": np.stack([num(f"{name}_bending_px") for name in names], axis=1).reshape(n_rows, k + 2),
    }
    return out
