"""The result of :func:`~servoscope.sysid.sweep.sweep_response`: a sweep's composite frequency response.

:mod:`servoscope.sysid.sweep` describes the method (CIFER's overlapped, windowed spectra at
several window lengths and their composite); this module holds what it returns, its views
(``summary()``/``from_summary()``, ``to_pandas()``, ``plot()``) and its door to the
transfer-function fit (:meth:`SweepResponse.to_frequency_response`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from servoscope.errors import ServoscopeError
from servoscope.results import import_pandas, jsonable, readonly
from servoscope.sysid.frequency_response import FrequencyResponse

__all__ = ["COHERENCE_MIN", "SweepResponse"]

#: CIFER's coherence threshold: points below it are not fitted.
COHERENCE_MIN = 0.6


@dataclass(frozen=True)
class SweepResponse:
    """A sweep's composite frequency response (CIFER), one point per grid frequency.

    Attributes
    ----------
    frequency_hz : numpy.ndarray
        Grid frequencies (Hz), ascending, nearly independent (see the module's description).
    gain, phase_deg : numpy.ndarray
        ``|H|`` (output units per input unit) and its phase in degrees (continuous, negative
        for a lagging system).
    coherence : numpy.ndarray
        Composite ``γ²``.
    random_error : numpy.ndarray
        Composite ``ε_r`` (relative error of the gain; phase error in rad).
    gain_stderr, phase_stderr_deg : numpy.ndarray
        ``ε_r·gain`` and ``degrees(ε_r)``.
    kept : numpy.ndarray of bool
        ``coherence ≥ coherence_min``: the points a fit may use.
    windows_s : tuple of float
        Window lengths computed, longest first.
    n_averages : tuple of int
        Segments averaged per window (``n_d``).
    effective_averages : tuple of float
        Independent averages per window (``n_e``, used in ``ε_r``).
    shifts_s : tuple of float
        The output's alignment shift per window.
    window_points : tuple of int
        Grid points each window contributed to.
    coherence_min, overlap : float
    filled_samples : int
        Invalid output samples filled by interpolation.
    sample_rate_hz : float
    warnings : tuple of str
    """

    frequency_hz: NDArray[np.float64]
    gain: NDArray[np.float64]
    phase_deg: NDArray[np.float64]
    coherence: NDArray[np.float64]
    random_error: NDArray[np.float64]
    kept: NDArray[np.bool_]
    windows_s: tuple[float, ...]
    n_averages: tuple[int, ...]
    effective_averages: tuple[float, ...] = ()
    shifts_s: tuple[float, ...] = ()
    window_points: tuple[int, ...] = ()
    coherence_min: float = COHERENCE_MIN
    overlap: float = 0.8
    filled_samples: int = 0
    sample_rate_hz: float = math.nan
    warnings: tuple[str, ...] = field(default=())

    def __post_init__(self) -> None:
        n = np.asarray(self.frequency_hz).size
        for name in ("frequency_hz", "gain", "phase_deg", "coherence", "random_error"):
            a = readonly(np.asarray(getattr(self, name), dtype=float).ravel())
            if a.size != n:
                raise ServoscopeError(f"SweepResponse: {name} has {a.size} entries, expected {n}")
            object.__setattr__(self, name, a)
        kept = np.array(self.kept, dtype=bool).ravel()
        if kept.size != n:
            raise ServoscopeError(f"SweepResponse: kept has {kept.size} entries, expected {n}")
        kept.setflags(write=False)
        object.__setattr__(self, "kept", kept)
        object.__setattr__(self, "windows_s", tuple(float(x) for x in self.windows_s))
        object.__setattr__(self, "n_averages", tuple(int(x) for x in self.n_averages))
        object.__setattr__(self, "effective_averages", tuple(float(x) for x in self.effective_averages))
        object.__setattr__(self, "shifts_s", tuple(float(x) for x in self.shifts_s))
        object.__setattr__(self, "window_points", tuple(int(x) for x in self.window_points))
        object.__setattr__(self, "warnings", tuple(str(w) for w in self.warnings))

    def __len__(self) -> int:
        return int(self.frequency_hz.size)

    @property
    def gain_stderr(self) -> NDArray[np.float64]:
        """``ε_r·|H|``."""
        return readonly(self.random_error * self.gain)

    @property
    def phase_stderr_deg(self) -> NDArray[np.float64]:
        """``degrees(ε_r)``."""
        return readonly(np.degrees(self.random_error))

    @property
    def gain_db(self) -> NDArray[np.float64]:
        with np.errstate(divide="ignore"):
            return readonly(20.0 * np.log10(self.gain))

    @property
    def omega_rad_s(self) -> NDArray[np.float64]:
        return readonly(2.0 * np.pi * self.frequency_hz)

    @property
    def response(self) -> NDArray[np.complex128]:
        """``gain·e^{j·phase}`` (complex)."""
        return self.gain * np.exp(1j * np.radians(self.phase_deg))

    # ------------------------------------------------------------------ exports
    def to_frequency_response(self, label_prefix: str = "sweep") -> FrequencyResponse:
        """The kept points (``γ² ≥ coherence_min``) as a :class:`FrequencyResponse`.

        Standard errors ``ε_r·|H|`` and ``degrees(ε_r)``; the coherence stands in the
        `fidelity` column (both are the share of the output's power linear in the input, and
        the transfer-function fit's CIFER cost weighs points by it); labels
        ``"<prefix>@<f>Hz"``.

        Raises
        ------
        ServoscopeError
            When no point is kept.
        """
        k = self.kept
        if not np.any(k):
            raise ServoscopeError(f"sweep: no frequency has coherence ≥ {self.coherence_min:g}: nothing to fit")
        f = self.frequency_hz[k]
        return FrequencyResponse(
            frequency_hz=f, gain=self.gain[k], gain_stderr=self.gain_stderr[k], phase_deg=self.phase_deg[k],
            phase_stderr_deg=self.phase_stderr_deg[k], fidelity=self.coherence[k],
            labels=tuple(f"{label_prefix}@{x:.4g}Hz" for x in f), warnings=self.warnings)

    def _columns(self) -> dict[str, NDArray[Any]]:
        return {"frequency_hz": self.frequency_hz, "gain": self.gain, "gain_db": self.gain_db,
                "phase_deg": self.phase_deg, "coherence": self.coherence, "random_error": self.random_error,
                "gain_stderr": self.gain_stderr, "phase_stderr_deg": self.phase_stderr_deg, "kept": self.kept}

    def summary(self) -> dict[str, Any]:
        """Plain JSON types: the points (one list per column) and the method's numbers."""
        cols = {k: v for k, v in self._columns().items() if k not in ("gain_db", "gain_stderr", "phase_stderr_deg")}
        return jsonable({**{k: [bool(x) for x in v] if k == "kept" else v for k, v in cols.items()},
                         "windows_s": self.windows_s, "n_averages": self.n_averages,
                         "effective_averages": self.effective_averages, "shifts_s": self.shifts_s,
                         "window_points": self.window_points, "coherence_min": self.coherence_min,
                         "overlap": self.overlap, "filled_samples": self.filled_samples,
                         "sample_rate_hz": self.sample_rate_hz, "warnings": self.warnings})

    @classmethod
    def from_summary(cls, data: dict[str, Any]) -> "SweepResponse":
        """Rebuild from :meth:`summary` (JSON's None read back as NaN)."""
        def col(key: str) -> NDArray[np.float64]:
            return np.array([math.nan if v is None else v for v in data[key]], dtype=float)

        def num(v: Any) -> float:
            return math.nan if v is None else float(v)

        return cls(col("frequency_hz"), col("gain"), col("phase_deg"), col("coherence"), col("random_error"),
                   np.array(data["kept"], dtype=bool), tuple(data["windows_s"]), tuple(data["n_averages"]),
                   tuple(data.get("effective_averages", ())), tuple(data.get("shifts_s", ())),
                   tuple(data.get("window_points", ())), num(data.get("coherence_min", COHERENCE_MIN)),
                   num(data.get("overlap", 0.8)), int(data.get("filled_samples", 0)),
                   num(data.get("sample_rate_hz")), tuple(data.get("warnings", ())))

    def to_pandas(self) -> Any:
        """One row per grid frequency (the columns of :meth:`summary` and gain_db, the stderrs). Needs pandas."""
        return import_pandas().DataFrame({k: np.asarray(v) for k, v in self._columns().items()})

    def plot(self, axes: Any = None) -> list[Any]:
        """CIFER's three panels against frequency (Hz, log axis): gain in dB, phase in degrees, coherence.

        Parameters
        ----------
        axes : sequence of three matplotlib Axes, optional
            A new figure's (shared frequency axis) when None.

        Returns
        -------
        list
            ``[gain line, phase line, coherence line, threshold line]``; kept points are
            drawn filled, the others hollow (the lines hold all points: x = `frequency_hz`).
        """
        if axes is None:
            import matplotlib.pyplot as plt

            _, axes = plt.subplots(3, 1, sharex=True)
        ax_g, ax_p, ax_c = axes
        f, k = self.frequency_hz, self.kept
        artists = [ax_g.plot(f, self.gain_db, "-o", ms=4, color="C0", mfc="none", label="sweep")[0],
                   ax_p.plot(f, self.phase_deg, "-o", ms=4, color="C0", mfc="none")[0],
                   ax_c.plot(f, self.coherence, "-o", ms=4, color="C0", mfc="none")[0],
                   ax_c.axhline(self.coherence_min, ls="--", color="C3", lw=1)]
        for ax, y in ((ax_g, self.gain_db), (ax_p, self.phase_deg), (ax_c, self.coherence)):
            ax.plot(f[k], y[k], "o", ms=4, color="C0")
            ax.set_xscale("log")
        ax_g.set_ylabel("magnitude [dB]")
        ax_p.set_ylabel("phase [deg]")
        ax_c.set_ylabel("coherence γ²")
        ax_c.set_ylim(0, 1.05)
        ax_c.set_xlabel("frequency [Hz]")
        return artists
