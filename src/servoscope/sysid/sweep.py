"""A frequency sweep's frequency response with coherence: CIFER's spectral method (issue 31).

One recording of a frequency sweep (a chirp command ``u(t)`` dated by the LED, the blade's
measured angle ``y(t)`` at the video's frame times) gives the response at every frequency the
sweep visits, as in Tischler & Remple, *Aircraft and Rotorcraft System Identification*
(CIFER), chapters 7–8:

1. **Samples.** The frame times must be nearly uniform (a least-squares line through
   time against frame index; its residual must stay below a quarter frame). Frames missing
   from the series or invalid (NaN angle) form gaps: a gap whose span between the valid
   frames around it is at most ``max_gap_s`` (default half a period of `to_hz`) is filled by
   a cubic spline through the valid frames, and the warnings say how many; a longer gap is
   refused (:class:`~servoscope.errors.ServoscopeError`). Invalid frames at the ends are cut.
2. **Windows.** Auto- and cross-spectra from :func:`scipy.signal.csd` (Welch's overlapped,
   averaged periodograms) at several window lengths (CIFER uses 5): by default 5 lengths
   log-spaced from ``T_max = clip(2/from_hz, T_rec/5, T_rec/2)`` (two periods of the lowest
   frequency, within the record) down to ``T_min``, the shortest window the grid's spacing at
   `to_hz` lets contribute (step 5) and at least 3 periods of `to_hz` (1.29 s, 19 periods at
   15 Hz with 20 points per decade; 0.53 s with 8; a window holding only 2–3 periods of the top
   frequency has bins 5–7 Hz wide there and could only serve a grid of a point or two per
   octave). The taper is the (periodic) **Hann** window: it is
   constant-overlap-add at 50 % and 80 % overlap (every instant of the sweep weighs the same,
   so no frequency of the chirp is favoured by where the segments fall); its sidelobes fall
   fast (little leakage from the large low-frequency motion into the small high-frequency one);
   and its normalized autocorrelation is flat at zero lag (``1 − 2π²x²/3`` for a lag ``x``
   window lengths), which keeps the bias from the output's delay small (below). A Tukey window
   is flatter in time but falls off like a rectangle at its edges (a bias linear in the lag).
   Default overlap 80 % (CIFER's): there the lagged products ``w(t)·w(t+τ)`` of the segments
   add up to a constant too (at 50 % they do not: the paper's servo's gain came out up to 1.2 % off
   with 50 %, 0.6 % with 80 %, on one record with 5e-5 rad of noise). The record's means are taken out and ``nperseg − hop``
   zeros put at each end (``detrend=False``), so that the overlap-add stays constant up to the
   record's ends: without it the first and last segments' tapers weigh the chirp's first and
   last frequencies unevenly against the output that lags them (a 0.6 % gain error at 0.5 Hz
   and 1–3 % at 14–15 Hz for the paper's servo). A slow drift of the output is then not taken
   out segment by segment: it leaks into the lowest frequencies.
3. **Each window.** ``H = Gxy/Gxx``, ``γ² = |Gxy|²/(Gxx·Gyy)``, the number of averages
   ``n_d`` (segments) and the random error ``ε_r = sqrt(1 − γ²)/(|γ|·sqrt(2·n_e))`` (relative
   error of ``|H|``, error of the phase in rad), where ``n_e`` is the number of *independent*
   averages: overlapped Hann segments are correlated, and Welch's (1967) variance of the
   overlapped average gives ``n_e = n_d / (1 + 2·Σ_j (1 − j/n_d)·ρ²(j·hop))`` with ``ρ`` the
   window's normalized autocorrelation (``n_e ≈ 0.53·n_d`` at 80 %, ``≈ 0.95·n_d`` at 50 %).
4. **Alignment.** A window of length ``T`` estimates the gain at a frequency whose group delay
   is ``τ`` times ``R(τ/T) ≈ 1 − 6.6·(τ/T)²`` (stationary phase; 5 % low for the paper's
   servo, τ ≈ 0.1 s, in a 1.1 s window), and its coherence by ``R²`` (without alignment:
   gain 1.8 % and phase 3.6° off at worst for that servo; with one shift of 85 ms for all
   windows 0.8 %, 0.9°; with each window's own, 0.6 %, 0.6°; one record, noise 5e-5 rad). So each window's output
   is first shifted back by a whole number of samples near the group delay of the band it
   serves (``shift="auto"``: read from the phase slope of the longest window's estimate), and
   the shift is put back into the phase exactly (``H = H_shifted·e^{−jωs}``).
5. **Composite.** On a log-spaced grid inside ``[from_hz, to_hz]`` (``points_per_decade``),
   widened where needed so that neighbouring points are at least ``2/T`` apart for every
   window of length ``T`` that contributes to either of them (Hann bins two apart are 1/6
   correlated in the complex estimate, 3 % in power: nearly independent), and a window
   contributes only at frequencies holding at least 2 of its periods (CIFER's ω_min). At each
   point, the windows' estimates (their spectra interpolated from 4×-zero-padded bins) are
   averaged with weights ``a_w ∝ 1/ε_w²`` (inverse variance of the complex estimate, whose
   variance is ``2·ε_w²·|H|²`` and ``|H|`` is common to all)::

       H   = Σ a_w·H_w
       γ²  = Σ a_w·γ²_w
       ε_r = Σ a_w·ε_w          (windows of one record share its noise: their errors are
                                 correlated; this is the fully correlated combination, the
                                 upper end; independent ones would give (Σ 1/ε_w²)^(-1/2))

   Measured on the paper's servo (12 s log chirp 0.5–15 Hz, 100 frames/s, white noise 1e-3 rad,
   30 records): the gain's error over ``ε_r`` scatters with s.d. 1.07 with this combination, 1.45
   with the independent one (which is 0.82 of it on average). Where the noise is far below the
   signal (5e-5 rad) the coherence is limited by the estimator's own small biases (γ² ≈ 0.999),
   not by the noise, and ``ε_r`` is 2–3 times the actual error.

   Points with ``γ² < coherence_min`` (0.6, CIFER's threshold) are kept in the response but
   flagged: :meth:`SweepResponse.to_frequency_response` leaves them out.

The phase is continuous (unwrapped along the grid after the reference shift is taken out) and
negative for a lagging system: ``H`` is the output's Fourier transform over the input's on the
same clock, so the dead time between the command and the blade appears in the phase.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import signal
from scipy.interpolate import CubicSpline

from servoscope.errors import ServoscopeError
from servoscope.sysid.sweep_result import COHERENCE_MIN, SweepResponse

__all__ = ["COHERENCE_MIN", "SweepResponse", "WindowEstimate", "random_error", "sweep_response", "window_estimate"]

_MIN_CYCLES = 2.0  # a window serves frequencies holding at least this many of its periods
_SPACING_BINS = 2.0  # neighbouring grid points at least this many of a window's bins (1/T) apart
_PAD = 4  # zero padding of each segment (nfft = _PAD * nperseg): spectra read between bins
_N_WINDOWS = 5


@dataclass(frozen=True)
class WindowEstimate:
    """One window length's estimate at its own frequency bins (``nfft`` of :func:`scipy.signal.csd`).

    Attributes
    ----------
    window_s : float
        Segment length (s).
    nperseg : int
        Its samples.
    frequency_hz, gxx, gyy : numpy.ndarray
        Bins and the one-sided auto-spectra of input and output.
    gxy : numpy.ndarray
        The cross-spectrum (complex, scipy's convention: ``conj(X)·Y``).
    response : numpy.ndarray
        ``H = Gxy/Gxx`` (complex), the shift put back.
    coherence : numpy.ndarray
        ``|Gxy|²/(Gxx·Gyy)``.
    n_averages : int
        Segments averaged (``n_d``).
    effective_averages : float
        Independent averages ``n_e`` (Welch's correction for the overlap).
    random_error : numpy.ndarray
        ``sqrt(1 − γ²)/(|γ|·sqrt(2·n_e))``.
    shift_s : float
        The output was advanced by this (a whole number of samples) before the spectra.
    """

    window_s: float
    nperseg: int
    frequency_hz: NDArray[np.float64]
    gxx: NDArray[np.float64]
    gyy: NDArray[np.float64]
    gxy: NDArray[np.complex128]
    response: NDArray[np.complex128]
    coherence: NDArray[np.float64]
    n_averages: int
    effective_averages: float
    random_error: NDArray[np.float64]
    shift_s: float = 0.0


def _effective_averages(nperseg: int, hop: int, n_d: int) -> float:
    """Welch's number of independent averages of `n_d` overlapped Hann segments."""
    w = signal.get_window("hann", nperseg)
    w2 = float(np.sum(w * w))
    total = 0.0
    for j in range(1, n_d):
        lag = j * hop
        if lag >= nperseg:
            break
        rho = float(np.sum(w[:-lag] * w[lag:])) / w2
        total += (1.0 - j / n_d) * rho * rho
    return n_d / (1.0 + 2.0 * total)


def random_error(coherence: ArrayLike, effective_averages: float | ArrayLike) -> NDArray[np.float64]:
    """CIFER's random error ``sqrt(1 − γ²)/(|γ|·sqrt(2·n))`` (relative error of |H|, phase error in rad)."""
    g2 = np.clip(np.asarray(coherence, dtype=float), 1e-12, 1.0)
    return np.sqrt(1.0 - g2) / (np.sqrt(g2) * np.sqrt(2.0 * np.asarray(effective_averages, dtype=float)))


def window_estimate(u: ArrayLike, y: ArrayLike, fs: float, nperseg: int, *, overlap: float = 0.8,
                    shift_samples: int = 0, nfft: int | None = None, pad: bool = False) -> WindowEstimate:
    """One window length's ``H``, ``γ²``, averages and random error from uniformly sampled `u`, `y`.

    The spectra are :func:`scipy.signal.csd`'s (Hann window, ``noverlap = round(overlap·nperseg)``,
    ``detrend="constant"``, one-sided density); ``y`` is first advanced by `shift_samples`
    (``y[n + shift]`` against ``u[n]``) and the shift put back into ``H``'s phase.
    """
    u = np.asarray(u, dtype=float)
    y = np.asarray(y, dtype=float)
    k = int(shift_samples)
    if k > 0:
        u, y = u[: u.size - k], y[k:]
    elif k < 0:
        u, y = u[-k:], y[: y.size + k]
    nperseg = int(nperseg)
    if nperseg > u.size:
        raise ServoscopeError(f"sweep: a window of {nperseg} samples is longer than the record ({u.size})")
    noverlap = int(round(overlap * nperseg))
    noverlap = min(noverlap, nperseg - 1)
    hop = nperseg - noverlap
    n_rec = u.size
    detrend: str | bool = "constant"
    if pad:
        zeros = np.zeros(nperseg - hop)
        u = np.concatenate((zeros, u - u.mean(), zeros))
        y = np.concatenate((zeros, y - y.mean(), zeros))
        detrend = False
    nfft = int(nfft or nperseg)
    kw = dict(fs=fs, window="hann", nperseg=nperseg, noverlap=noverlap, nfft=nfft, detrend=detrend)
    f, gxx = signal.welch(u, **kw)
    _, gyy = signal.welch(y, **kw)
    _, gxy = signal.csd(u, y, **kw)
    n_d = 1 + (u.size - nperseg) // hop
    n_e = _effective_averages(nperseg, hop, n_d)
    if pad:
        n_e *= min(1.0, n_rec / hop / n_d)
    with np.errstate(divide="ignore", invalid="ignore"):
        h = gxy / gxx
        coh = np.abs(gxy) ** 2 / (gxx * gyy)
    h = h * np.exp(-2j * np.pi * f * k / fs)
    coh = np.clip(np.nan_to_num(coh, nan=0.0), 0.0, 1.0)
    return WindowEstimate(nperseg / fs, nperseg, f, gxx, gyy, gxy, h, coh, int(n_d), float(n_e),
                          random_error(coh, n_e), k / fs)


# ---------------------------------------------------------------------------- samples
def _uniform_samples(time_s: NDArray[np.float64], u: NDArray[np.float64], y: NDArray[np.float64],
                     max_gap_s: float) -> tuple[float, NDArray[np.float64], NDArray[np.float64], int, list[str]]:
    """(fs, u, y) on a uniform grid, gaps filled; the number of samples filled; warnings."""
    notes: list[str] = []
    if time_s.ndim != 1 or u.shape != time_s.shape or y.shape != time_s.shape:
        raise ServoscopeError(f"sweep: time_s, input and output must be 1-D and of one length "
                              f"(got {time_s.shape}, {u.shape}, {y.shape})")
    if time_s.size < 16 or not np.all(np.isfinite(time_s)) or np.any(np.diff(time_s) <= 0):
        raise ServoscopeError("sweep: time_s must be at least 16 finite, increasing frame times")
    if not np.all(np.isfinite(u)):
        raise ServoscopeError("sweep: the input command has non-finite samples (it is computed, not measured)")
    dt0 = float(np.median(np.diff(time_s)))
    idx = np.rint((time_s - time_s[0]) / dt0).astype(np.int64)
    if np.any(np.diff(idx) < 1):
        raise ServoscopeError("sweep: the frame times are not nearly uniform (two frames in one frame period)")
    slope, icpt = np.polyfit(idx, time_s, 1)
    jitter = float(np.max(np.abs(time_s - (icpt + slope * idx))))
    if jitter > 0.25 * slope:
        raise ServoscopeError(f"sweep: the frame times are not nearly uniform (a frame {1e3 * jitter:.2f} ms "
                              f"off the uniform clock of {1e3 * slope:.3f} ms)")
    n = int(idx[-1]) + 1
    uu = np.empty(n)
    yy = np.full(n, np.nan)
    yy[idx] = y
    missing = np.ones(n, bool)
    missing[idx] = False
    uu[idx] = u
    if np.any(missing):
        uu[missing] = CubicSpline(idx.astype(float), u)(np.nonzero(missing)[0].astype(float))
        notes.append(f"{int(missing.sum())} frame(s) missing from the time series (dropped frames) treated as "
                     "invalid; the input there interpolated")
    valid = np.isfinite(yy)
    if valid.sum() < 16:
        raise ServoscopeError("sweep: fewer than 16 valid output samples")
    first, last = int(np.argmax(valid)), int(n - 1 - np.argmax(valid[::-1]))
    if first > 0 or last < n - 1:
        notes.append(f"{first + n - 1 - last} invalid frame(s) at the record's ends cut off")
    uu, yy, valid = uu[first:last + 1], yy[first:last + 1], valid[first:last + 1]
    bad = ~valid
    filled = int(bad.sum())
    if filled:
        edges = np.diff(np.concatenate(([0], bad.astype(np.int8), [0])))
        starts, stops = np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0]
        runs = stops - starts
        longest = int(runs.max())
        span = (longest + 1) * slope
        if span > max_gap_s:
            where = float(time_s[0] + slope * (first + starts[int(np.argmax(runs))]))
            raise ServoscopeError(
                f"sweep: a gap of {longest} invalid frame(s) at t = {where:.3f} s spans {1e3 * span:.1f} ms "
                f"between valid frames, more than {1e3 * max_gap_s:.1f} ms (half a period of the top "
                "frequency by default): it cannot be interpolated; cut the record or raise max_gap_s")
        k = np.arange(yy.size, dtype=float)
        yy[bad] = CubicSpline(k[valid], yy[valid])(k[bad])
        notes.append(f"{filled} invalid frame(s) in {runs.size} gap(s) (the longest {longest} frame(s), "
                     f"{1e3 * span:.1f} ms) filled by cubic interpolation")
    return 1.0 / float(slope), uu, yy, filled, notes


def _edge_notes(u: NDArray[np.float64], fs: float) -> list[str]:
    """Warnings when the command still moves at the record's start or end (a sweep needs rest at both)."""
    m = max(2, int(round(0.25 * fs)))
    whole = float(np.std(u))
    out = []
    for where, part in (("starts", u[:m]), ("ends", u[-m:])):
        if whole > 0 and float(np.std(part)) > 0.2 * whole:
            out.append(f"the record {where} while the command moves: what the output does in answer to the "
                       "command outside the record is missing, and biases the spectra; record a second or more "
                       "of rest before and after the sweep")
    return out


# ---------------------------------------------------------------------------- the grid
def _grid(windows: list[float], from_hz: float, to_hz: float, points_per_decade: float
          ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Grid frequencies and, per point and window, whether the window contributes there."""
    t_max = max(windows)
    r = 10.0 ** (1.0 / points_per_decade)
    f = max(from_hz, _MIN_CYCLES / t_max)
    grid = [f]
    while True:
        f = f + max(f * (r - 1.0), _SPACING_BINS / t_max)
        if f > to_hz * (1 + 1e-9):
            break
        grid.append(f)
    g = np.array(grid)
    gaps = np.diff(g)
    # The spacing to the nearer neighbour bounds the windows that may contribute.
    near = np.minimum(np.concatenate(([np.inf], gaps)), np.concatenate((gaps, [np.inf])))
    if g.size == 1:
        near = np.array([np.inf])
    t = np.array(windows)[None, :]
    use = (g[:, None] >= _MIN_CYCLES / t * (1 - 1e-9)) & (near[:, None] >= _SPACING_BINS / t * (1 - 0.02))  # 2 %: the windows' whole samples
    return g, use


def _default_windows(t_rec: float, from_hz: float, to_hz: float, fs: float, points_per_decade: float) -> list[float]:
    """5 lengths log-spaced from T_max down to the shortest window the grid lets contribute."""
    t_max = float(np.clip(_MIN_CYCLES / from_hz, t_rec / 5.0, t_rec / 2.0))
    grid, _ = _grid([t_max], from_hz, to_hz, points_per_decade)
    # At the top point the spacing to its neighbour bounds the bins (2/T) of a contributing window.
    top_spacing = float(grid[-1] - grid[-2]) if grid.size > 1 else to_hz
    t_min = min(max(3.0 / to_hz, _SPACING_BINS / top_spacing, 16.0 / fs), t_max)
    return [float(x) for x in np.geomspace(t_max, t_min, _N_WINDOWS)]


def _interp(f_bins: NDArray[np.float64], values: NDArray[Any], f: NDArray[np.float64]) -> NDArray[Any]:
    if np.iscomplexobj(values):
        return np.interp(f, f_bins, values.real) + 1j * np.interp(f, f_bins, values.imag)
    return np.interp(f, f_bins, values)


def _group_delay_shift(est: WindowEstimate, lo: float, hi: float, coherence_min: float, fs: float) -> int:
    """Whole samples near the mean group delay over [lo, hi], from `est`'s phase slope."""
    f = est.frequency_hz
    sel = (f >= lo) & (f <= hi) & (est.coherence >= coherence_min) & np.isfinite(est.response)
    if sel.sum() < 3:
        return 0
    ph = np.unwrap(np.angle(est.response[sel]))
    w = 2 * np.pi * f[sel]
    weight = 1.0 / np.maximum(est.random_error[sel], 1e-6) ** 2
    slope = np.polyfit(w, ph, 1, w=np.sqrt(weight))[0]
    tau = -float(slope) + est.shift_s
    return int(round(max(tau, 0.0) * fs))


def _composite(estimates: list[WindowEstimate], grid: NDArray[np.float64], use: NDArray[np.bool_]
               ) -> tuple[NDArray[np.complex128], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The windows' inverse-variance composite at the grid: H, γ², ε_r and the continuous phase (rad)."""
    n = grid.size
    h_sum = np.zeros(n, complex)
    g2_sum = np.zeros(n)
    e_sum = np.zeros(n)
    w_sum = np.zeros(n)
    for j, est in enumerate(estimates):
        sel = use[:, j]
        if not np.any(sel):
            continue
        f = grid[sel]
        gxy = _interp(est.frequency_hz, est.gxy, f)
        gxx = _interp(est.frequency_hz, est.gxx, f)
        gyy = _interp(est.frequency_hz, est.gyy, f)
        with np.errstate(divide="ignore", invalid="ignore"):
            h = gxy / gxx * np.exp(-2j * np.pi * f * est.shift_s)
            g2 = np.clip(np.nan_to_num(np.abs(gxy) ** 2 / (gxx * gyy)), 0.0, 1.0)
        eps = random_error(g2, est.effective_averages)
        wt = 1.0 / np.maximum(eps, 1e-9) ** 2
        h_sum[sel] += wt * h
        g2_sum[sel] += wt * g2
        e_sum[sel] += wt * eps
        w_sum[sel] += wt
    h = h_sum / w_sum
    coherence = g2_sum / w_sum
    eps = e_sum / w_sum
    # Continuous phase: unwrap with the reference shift taken out (slowly varying), then put it back.
    ref = estimates[0].shift_s
    rot = h * np.exp(2j * np.pi * grid * ref)
    phase = np.unwrap(np.angle(rot)) - 2 * np.pi * grid * ref
    return h, coherence, eps, phase


# ---------------------------------------------------------------------------- entry point
def sweep_response(time_s: ArrayLike, input: ArrayLike, output: ArrayLike, *, from_hz: float, to_hz: float,
                   windows_s: ArrayLike | None = None, overlap: float = 0.8,
                   coherence_min: float = COHERENCE_MIN, points_per_decade: float = 20.0,
                   shift: str | float = "auto", max_gap_s: float | None = None) -> SweepResponse:
    """One frequency-sweep recording's frequency response with coherence (CIFER's composite).

    Parameters
    ----------
    time_s : array_like
        Frame times (s), nearly uniform.
    input : array_like
        The command at those times (finite).
    output : array_like
        The measured output (NaN at invalid frames).
    from_hz, to_hz : float
        The band of interest (``0 < from_hz < to_hz <`` Nyquist).
    windows_s : array_like, optional
        Window lengths (s); default 5 (see the module's description).
    overlap : float
        Segment overlap (0 ≤ overlap < 1), 0.8 as CIFER.
    coherence_min : float
        Points below are flagged, not fitted (0.6).
    points_per_decade : float
        Density of the log grid where the windows' resolution allows it.
    shift : "auto" or float
        The output's alignment per window: "auto" (group delay of the window's band), or one
        shift in seconds for all (0: none).
    max_gap_s : float, optional
        Longest span between valid frames a gap may have to be filled (``1/(2·to_hz)``).

    Returns
    -------
    SweepResponse

    Raises
    ------
    ServoscopeError
        Bad band or options, frame times not nearly uniform, a gap too long, or a record
        too short for the windows.
    """
    from_hz, to_hz = float(from_hz), float(to_hz)
    if not (math.isfinite(from_hz) and math.isfinite(to_hz) and 0 < from_hz < to_hz):
        raise ServoscopeError(f"sweep: the band must satisfy 0 < from_hz < to_hz (got {from_hz}, {to_hz})")
    if not 0 <= overlap < 1:
        raise ServoscopeError(f"sweep: overlap must be in [0, 1), got {overlap}")
    if not 0 < coherence_min < 1:
        raise ServoscopeError(f"sweep: coherence_min must be in (0, 1), got {coherence_min}")
    max_gap = 0.5 / to_hz if max_gap_s is None else float(max_gap_s)
    fs, u, y, filled, notes = _uniform_samples(np.asarray(time_s, dtype=float), np.asarray(input, dtype=float),
                                               np.asarray(output, dtype=float), max_gap)
    if to_hz >= 0.5 * fs:
        raise ServoscopeError(f"sweep: to_hz = {to_hz:g} Hz is not below the Nyquist frequency {0.5 * fs:g} Hz")
    t_rec = u.size / fs
    notes += _edge_notes(u, fs)
    if windows_s is None:
        windows = _default_windows(t_rec, from_hz, to_hz, fs, points_per_decade)
    else:
        windows = sorted((float(w) for w in np.atleast_1d(np.asarray(windows_s, dtype=float))), reverse=True)
        if not windows or any(not (8 / fs <= w <= t_rec) for w in windows):
            raise ServoscopeError(f"sweep: windows_s must lie between 8 samples and the record ({t_rec:.3g} s)")
    npersegs = [int(round(w * fs)) for w in windows]
    windows = [n / fs for n in npersegs]
    grid, use = _grid(windows, from_hz, to_hz, points_per_decade)
    if grid[0] > from_hz * 1.001:
        notes.append(f"below {grid[0]:.3g} Hz the longest window ({windows[0]:.3g} s) holds fewer than "
                     f"{_MIN_CYCLES:g} periods: the response starts there")

    # Alignment: the output advanced by each window's group delay (see the module's description).
    fixed_shift = None if shift == "auto" else int(round(float(shift) * fs))
    first = window_estimate(u, y, fs, npersegs[0], overlap=overlap, shift_samples=fixed_shift or 0,
                            nfft=_PAD * npersegs[0], pad=True)
    estimates: list[WindowEstimate] = []
    for j, nps in enumerate(npersegs):
        if fixed_shift is not None:
            k = fixed_shift
        else:
            band = grid[use[:, j]]
            lo, hi = (band[0], band[-1]) if band.size else (from_hz, to_hz)
            k = _group_delay_shift(first, lo - 1.0 / windows[j], hi + 1.0 / windows[j], coherence_min, fs)
        estimates.append(window_estimate(u, y, fs, nps, overlap=overlap, shift_samples=k, nfft=_PAD * nps, pad=True))

    h, coherence, eps, phase = _composite(estimates, grid, use)
    kept = coherence >= coherence_min
    n_low = int((~kept).sum())
    if n_low:
        notes.append(f"{n_low} of {grid.size} frequencies have coherence below {coherence_min:g} "
                     f"({', '.join(f'{x:.3g}' for x in grid[~kept])} Hz): not fitted")
    return SweepResponse(
        frequency_hz=grid, gain=np.abs(h), phase_deg=np.degrees(phase), coherence=coherence, random_error=eps,
        kept=kept, windows_s=tuple(windows), n_averages=tuple(e.n_averages for e in estimates),
        effective_averages=tuple(e.effective_averages for e in estimates),
        shifts_s=tuple(e.shift_s for e in estimates), window_points=tuple(int(c) for c in use.sum(axis=0)),
        coherence_min=coherence_min, overlap=overlap, filled_samples=filled, sample_rate_hz=fs,
        warnings=tuple(notes))
