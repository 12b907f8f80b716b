"""Measured frequency response: one point per sine dwell."""

from __future__ import annotations

import csv
import dataclasses
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from servoscope.errors import ServoscopeError
from servoscope.results import html_rows, import_pandas, jsonable, readonly
from servoscope.sysid.plotting import new_axes, plot_gain, plot_phase
from servoscope.sysid.sine_result import SineFit

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes

__all__ = ["FrequencyResponse"]

_LN10_OVER_20 = math.log(10.0) / 20.0

_COLUMNS = (
    "video",
    "frequency_hz",
    "frequency_stderr_hz",
    "omega_rad_s",
    "gain",
    "gain_stderr",
    "gain_db",
    "gain_db_stderr",
    "phase_deg",
    "phase_stderr_deg",
    "fidelity",
    "thd",
    "flags",
)


@dataclass(frozen=True)
class FrequencyResponse:
    """Gain and phase of the actuator at the tested frequencies.

    All arrays have the same length and are sorted by ascending frequency
    when built with :meth:`from_sine_fits`. Arrays are stored read-only.

    Attributes
    ----------
    frequency_hz : numpy.ndarray
        Test frequencies in Hz.
    gain : numpy.ndarray
        ``|G|``: output amplitude / input amplitude (output units per input
        unit, e.g. rad per unit collective).
    gain_stderr : numpy.ndarray
        Standard error of `gain` (NaN where unknown).
    phase_deg : numpy.ndarray
        Phase of the output relative to the input in degrees, unwrapped
        across ascending frequency; NaN where unknown (no ``t0``).
    phase_stderr_deg : numpy.ndarray
        Standard error of `phase_deg` in degrees (NaN where unknown).
    fidelity : numpy.ndarray
        Sinusoidal fidelity of each dwell (1.0 = pure sine).
    labels : tuple of str
        Names of the videos (one per point).
    frequency_stderr_hz : numpy.ndarray
        Standard error of the refined frequency in Hz (NaN where unknown).
    thd : numpy.ndarray
        Total harmonic distortion of each dwell (ratio; NaN where unknown).
    flags : tuple of tuple of str
        Each dwell's :attr:`SineFit.flags` (empty where unknown).
    warnings : tuple of str
        Dwells left out and the dwells' own warnings, prefixed by label.
    """

    frequency_hz: NDArray[np.float64]
    gain: NDArray[np.float64]
    gain_stderr: NDArray[np.float64]
    phase_deg: NDArray[np.float64]
    phase_stderr_deg: NDArray[np.float64]
    fidelity: NDArray[np.float64]
    labels: tuple[str, ...]
    frequency_stderr_hz: NDArray[np.float64] | None = field(default=None)
    thd: NDArray[np.float64] | None = field(default=None)
    flags: tuple[tuple[str, ...], ...] | None = field(default=None)
    warnings: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        f = np.array(self.frequency_hz, dtype=float).ravel()
        n = f.size

        def arr(name: str, value: Any) -> NDArray[np.float64]:
            if value is None:
                a = np.full(n, np.nan)
            else:
                a = np.array(value, dtype=float).ravel()
            if a.size != n:
                raise ServoscopeError(
                    f"FrequencyResponse: {name} has {a.size} entries, expected {n}"
                )
            a.setflags(write=False)
            return a

        f.setflags(write=False)
        object.__setattr__(self, "frequency_hz", f)
        for name in ("gain", "gain_stderr", "phase_deg", "phase_stderr_deg", "fidelity", "frequency_stderr_hz", "thd"):
            object.__setattr__(self, name, arr(name, getattr(self, name)))
        labels = tuple(str(x) for x in self.labels) if self.labels is not None else ()
        if not labels:
            labels = tuple(f"point{i}" for i in range(n))
        if len(labels) != n:
            raise ServoscopeError(f"FrequencyResponse: {len(labels)} labels for {n} points")
        object.__setattr__(self, "labels", labels)
        flags = tuple(tuple(str(c) for c in fl) for fl in self.flags) if self.flags is not None else ((),) * n
        if len(flags) != n:
            raise ServoscopeError(f"FrequencyResponse: {len(flags)} flag sets for {n} points")
        object.__setattr__(self, "flags", flags)
        object.__setattr__(self, "warnings", tuple(str(w) for w in self.warnings))
        if np.any(~np.isfinite(f)) or np.any(f <= 0):
            raise ServoscopeError("FrequencyResponse: frequencies must be finite and positive")

    # ------------------------------------------------------------------ build
    @classmethod
    def from_sine_fits(
        cls,
        fits: Sequence[SineFit | None],
        input_amplitudes: float | ArrayLike,
        labels: Sequence[str] | None = None,
    ) -> FrequencyResponse:
        """Build a frequency response from per-dwell sine fits.

        Parameters
        ----------
        fits : sequence of SineFit or None
            One fit per sine dwell, in any order. None marks a dwell that
            could not be fitted (e.g. no valid frames): it is left out with
            a warning in `warnings`.
        input_amplitudes : float or array_like
            Input sine amplitude(s) (input units, > 0); a scalar applies to
            all dwells, otherwise one per fit, in the order of `fits`.
        labels : sequence of str, optional
            Video names, in the order of `fits`.

        Returns
        -------
        FrequencyResponse
            Points sorted by ascending fitted frequency; gain =
            amplitude / input amplitude; phases unwrapped across ascending
            frequency over the points whose phase is known (the unwrapping
            assumes less than 180 deg between neighbouring known points).
        """
        fits = list(fits)
        n = len(fits)
        if n == 0:
            raise ServoscopeError("FrequencyResponse.from_sine_fits: no sine fits given")
        amp_in = np.broadcast_to(np.asarray(input_amplitudes, dtype=float), (n,)) \
            if np.ndim(input_amplitudes) == 0 else np.asarray(input_amplitudes, dtype=float).ravel()
        if amp_in.size != n:
            raise ServoscopeError(
                f"FrequencyResponse.from_sine_fits: {amp_in.size} input amplitudes for {n} fits"
            )
        if labels is None:
            labels = [f"point{i}" for i in range(n)]
        labels = [str(x) for x in labels]
        if len(labels) != n:
            raise ServoscopeError(f"FrequencyResponse.from_sine_fits: {len(labels)} labels for {n} fits")
        notes: list[str] = [f"{labels[i]}: no sine fit (no valid frames?); dwell left out" for i in range(n) if fits[i] is None]
        keep = [i for i in range(n) if fits[i] is not None]
        if not keep:
            raise ServoscopeError("FrequencyResponse.from_sine_fits: no dwell could be fitted")
        fits = [fits[i] for i in keep]  # type: ignore[misc]
        labels = [labels[i] for i in keep]
        amp_in = np.asarray(amp_in)[keep]
        n = len(fits)
        if np.any(~np.isfinite(amp_in)) or np.any(amp_in <= 0):
            raise ServoscopeError("FrequencyResponse.from_sine_fits: input amplitudes must be positive")
        for fi, lab in zip(fits, labels):
            notes.extend(f"{lab}: {w}" for w in fi.warnings)

        def nan_if_none(v: float | None) -> float:
            return float("nan") if v is None else float(v)

        freq = np.array([fi.frequency_hz for fi in fits], dtype=float)
        order = np.argsort(freq, kind="stable")
        gain = np.array([fi.amplitude for fi in fits]) / amp_in
        gain_se = np.array([nan_if_none(fi.amplitude_stderr) for fi in fits]) / amp_in
        phase = np.array([nan_if_none(fi.phase_rad) for fi in fits])
        phase_se = np.array([nan_if_none(fi.phase_stderr_rad) for fi in fits])
        fid = np.array([nan_if_none(fi.fidelity) for fi in fits])
        f_se = np.array([nan_if_none(fi.frequency_stderr_hz) for fi in fits])
        thd = np.array([nan_if_none(getattr(fi, "thd", None)) for fi in fits])
        flags = [tuple(getattr(fi, "flags", ())) for fi in fits]

        phase = phase[order]
        known = np.isfinite(phase)
        if np.any(known):
            ph = phase[known]
            ph0 = math.remainder(float(ph[0]), 2 * math.pi)
            phase[known] = np.unwrap(ph - ph[0] + ph0)
        return cls(
            frequency_hz=freq[order],
            gain=gain[order],
            gain_stderr=gain_se[order],
            phase_deg=np.degrees(phase),
            phase_stderr_deg=np.degrees(phase_se[order]),
            fidelity=fid[order],
            labels=tuple(labels[i] for i in order),
            frequency_stderr_hz=f_se[order],
            thd=thd[order],
            flags=tuple(flags[i] for i in order),
            warnings=tuple(notes),
        )

    # ------------------------------------------------------------- properties
    def __len__(self) -> int:
        return int(self.frequency_hz.size)

    @property
    def omega_rad_s(self) -> NDArray[np.float64]:
        """Angular frequencies in rad/s."""
        return 2.0 * math.pi * self.frequency_hz

    @property
    def gain_db(self) -> NDArray[np.float64]:
        """``20*log10(gain)`` in dB (-inf for zero gain)."""
        with np.errstate(divide="ignore"):
            return 20.0 * np.log10(self.gain)

    @property
    def gain_db_stderr(self) -> NDArray[np.float64]:
        """Standard error of `gain_db` in dB (first-order propagation)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.gain_stderr / (self.gain * _LN10_OVER_20)

    @property
    def phase_rad(self) -> NDArray[np.float64]:
        """`phase_deg` in rad (NaN where unknown)."""
        return np.radians(self.phase_deg)

    @property
    def phase_stderr_rad(self) -> NDArray[np.float64]:
        """`phase_stderr_deg` in rad (NaN where unknown)."""
        return np.radians(self.phase_stderr_deg)

    @property
    def has_phase(self) -> bool:
        """True when at least one point has a known phase."""
        return bool(np.any(np.isfinite(self.phase_deg)))

    # ---------------------------------------------------------------- exports
    def corrected_for_exposure(self, exposure_s: float, exposure_stderr_s: float = 0.0) -> "FrequencyResponse":
        """Undo the camera's averaging of the motion over each exposure.

        A frame integrates the output over its exposure window
        [t − e/2, t + e/2]; for a sine that is a box filter whose gain is
        sinc(f·e) = sin(πfe)/(πfe) and whose phase is zero about the window's
        centre (the frame's timestamp). The measured gains and their standard
        errors are divided by it; phases are unchanged.

        Parameters
        ----------
        exposure_s : float
            Exposure time e, seconds (≥ 0, below 1/f of every point).
        exposure_stderr_s : float
            Its standard uncertainty (s) when it was estimated (from motion
            blur): each gain's standard error grows by gain·|d ln sinc(f·e)/de|·σ_e
            (in quadrature; the same error for every dwell, a shared systematic).

        Raises
        ------
        ServoscopeError
            When e is negative or the box filter has a zero within the band
            (f·e ≥ 1), where nothing can be recovered.
        """
        e = float(exposure_s)
        if not (math.isfinite(e) and e >= 0):
            raise ServoscopeError(f"exposure_s must be a finite number ≥ 0, got {exposure_s!r}")
        factor = np.sinc(self.frequency_hz * e)
        if np.any(self.frequency_hz * e >= 1.0):
            raise ServoscopeError(
                f"exposure {e:g} s spans a whole period at {self.frequency_hz.max():g} Hz: the motion averages out"
            )
        gain = self.gain / factor
        gain_stderr = self.gain_stderr / factor
        se_e = float(exposure_stderr_s)
        if se_e > 0 and e > 0:
            x = np.pi * self.frequency_hz * e
            # d ln sinc(f e)/de = (1/e)·(x·cot x − 1), x = π f e
            dlog = np.where(x > 1e-6, (x / np.tan(np.where(x > 1e-6, x, 1.0)) - 1.0) / e, 0.0)
            gain_stderr = np.hypot(gain_stderr, gain * np.abs(dlog) * se_e)
        return dataclasses.replace(self, gain=gain, gain_stderr=gain_stderr)

    def _rows(self) -> list[dict[str, Any]]:
        cols = {
            "frequency_hz": self.frequency_hz,
            "frequency_stderr_hz": self.frequency_stderr_hz,
            "omega_rad_s": self.omega_rad_s,
            "gain": self.gain,
            "gain_stderr": self.gain_stderr,
            "gain_db": self.gain_db,
            "gain_db_stderr": self.gain_db_stderr,
            "phase_deg": self.phase_deg,
            "phase_stderr_deg": self.phase_stderr_deg,
            "fidelity": self.fidelity,
            "thd": self.thd,
        }
        rows = []
        for i, label in enumerate(self.labels):
            row: dict[str, Any] = {"video": label}
            row.update({k: float(v[i]) for k, v in cols.items()})
            row["flags"] = " ".join(self.flags[i])
            rows.append(row)
        return rows

    @classmethod
    def from_summary(cls, rows: Sequence[dict[str, Any]], warnings: Sequence[str] = ()) -> "FrequencyResponse":
        """Rebuild the response from its :meth:`summary` rows (a saved result.json's ``frequency_response``).

        Returns
        -------
        FrequencyResponse
            Its :meth:`summary` equals `rows`.
        """
        def col(key: str) -> NDArray[np.float64]:
            return readonly([math.nan if r.get(key) is None else r[key] for r in rows])

        return cls(frequency_hz=col("frequency_hz"), gain=col("gain"), gain_stderr=col("gain_stderr"),
                   phase_deg=col("phase_deg"), phase_stderr_deg=col("phase_stderr_deg"), fidelity=col("fidelity"),
                   labels=tuple(r["video"] for r in rows), frequency_stderr_hz=col("frequency_stderr_hz"),
                   thd=col("thd"), flags=tuple(tuple(r.get("flags", "").split()) for r in rows),
                   warnings=tuple(warnings))

    def summary(self) -> list[dict[str, Any]]:
        """One JSON-serializable dict per point (NaN -> None).

        Keys: video, frequency_hz, frequency_stderr_hz, omega_rad_s, gain,
        gain_stderr, gain_db, gain_db_stderr, phase_deg, phase_stderr_deg,
        fidelity, thd, flags (space-separated codes).
        """
        return [jsonable(r) for r in self._rows()]

    def to_pandas(self) -> Any:
        """The table as a pandas DataFrame (one row per point). Needs pandas."""
        pd = import_pandas()
        return pd.DataFrame(self._rows(), columns=list(_COLUMNS))

    def to_csv(self, path: str | os.PathLike[str]) -> None:
        """Write the table as CSV (header row; unknown values as empty cells).

        Parameters
        ----------
        path : str or path-like
            Destination file.
        """
        with open(path, "w", newline="", encoding="utf-8") as fh:
            writer = csv.writer(fh)
            writer.writerow(_COLUMNS)
            for row in self._rows():
                out = []
                for k in _COLUMNS:
                    v = row[k]
                    if isinstance(v, float):
                        out.append(repr(v) if math.isfinite(v) else "")
                    else:
                        out.append(v)
                writer.writerow(out)

    def to_frd(self) -> Any:
        """The points with known phase as a ``control.FrequencyResponseData``.

        Raises
        ------
        ServoscopeError
            When no point has a known phase.
        """
        import control

        known = np.isfinite(self.phase_deg)
        if not np.any(known):
            raise ServoscopeError("FrequencyResponse.to_frd: no point has a known phase (t0 missing)")
        resp = self.gain[known] * np.exp(1j * np.radians(self.phase_deg[known]))
        return control.frd(resp, self.omega_rad_s[known])

    def plot(self, ax: Axes | None = None, *, phase_ax: Axes | None = None) -> list[Any]:
        """Draw the gains in dB (±1 standard error bars) against ω on `ax`, the phases on `phase_ax`.

        Parameters
        ----------
        ax : matplotlib.axes.Axes, optional
            Axes for the gains (log ω axis); a new figure's when None.
        phase_ax : matplotlib.axes.Axes, optional
            Axes for the phases in degrees (not drawn when None).

        Returns
        -------
        list
            The gains' ``ErrorbarContainer`` (its line: x = `omega_rad_s`, y = `gain_db`) and,
            with `phase_ax`, the phases' line (y = `phase_deg`).
        """
        ax = new_axes(ax)
        artists: list[Any] = [plot_gain(ax, self.omega_rad_s, self.gain, self.gain_stderr)]
        ax.set_xscale("log")
        if phase_ax is not None:
            artists.append(plot_phase(phase_ax, self.omega_rad_s, self.phase_deg))
        return artists

    def _repr_html_(self) -> str:
        rows = (
            [r["video"], f"{r['frequency_hz']:.4g}", f"{r['gain']:.4g}", f"{r['gain_db']:.3f}", f"{r['phase_deg']:.2f}",
             f"{r['fidelity']:.4f}"]
            for r in self._rows()
        )
        return html_rows(("video", "f [Hz]", "gain", "gain [dB]", "phase [deg]", "fidelity"), rows)
