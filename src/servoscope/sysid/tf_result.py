"""The results of a transfer-function fit and of an order selection.

:class:`TransferFunctionFit` (the model with its parameters, errors and goodness of fit) and
:class:`OrderSelection` (the candidates compared by :func:`~servoscope.sysid.select_order`)
refer to each other, so they live together; both are plain frozen data with no fitting code,
below the fit (:mod:`servoscope.sysid.tf_fit`) and the order selection
(:mod:`servoscope.sysid.order`), which both import them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import control
import numpy as np
from numpy.typing import ArrayLike, NDArray

from servoscope.errors import ServoscopeError
from servoscope.parameters import FitResult, Parameter, Parameters, unit_of
from servoscope.results import fields_from_summary, html_rows, import_pandas, jsonable, readonly
from servoscope.sysid._rational import Structure, continuous_phase_rad, log_response
from servoscope.sysid._tf_metrics import bandwidth_rad_s, j_rating
from servoscope.sysid.frequency_response import FrequencyResponse
from servoscope.sysid.plotting import new_axes, plot_model_gain, plot_model_phase

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes

__all__ = ["OrderSelection", "TransferFunctionFit"]

#: The columns of :attr:`OrderSelection.table`.
ORDER_TABLE_KEYS = (
    "order", "n_params", "J", "AIC", "BIC", "residual_rms_db", "residual_rms_deg", "relative_degree", "determined",
    "chosen",
)


@dataclass(frozen=True)
class TransferFunctionFit(FitResult):
    """Transfer function ``K * N(s)/D(s) * exp(-s*tau)`` fitted to a frequency response.

    Attributes
    ----------
    gain : float
        Static gain ``K = G(0)`` (output units per input unit, e.g. rad per unit).
    natural_frequency_rad_s, damping_ratio : float or None
        ``wn`` (rad/s) and ``zeta`` of a second-order denominator (``na ==
        2``); None for other orders (see `params`).
    gain_stderr : float
        Standard error of `gain` (NaN when not estimable).
    natural_frequency_stderr_rad_s, damping_ratio_stderr : float or None
        Their standard errors (None for other orders).
    dead_time_s : float or None
        Dead time ``tau`` in s (mode="complex"; None for a magnitude fit,
        which cannot identify it).
    dead_time_stderr_s : float or None
        Standard error of `dead_time_s` in s.
    covariance : numpy.ndarray
        Covariance of the physical parameters, in the order of `param_names`.
    residual_rms_db : float
        RMS of ``20*log10(model/measured)`` over the points, dB.
    residual_rms_deg : float or None
        RMS phase residual in degrees (mode="complex").
    n_points : int
        Number of frequency points (dwells) used.
    mode : str
        "magnitude" or "complex".
    cost : float
        Final least-squares cost ``0.5*sum(r**2)`` of the weighted residuals.
    warnings : tuple of str
        Non-fatal problems (parameter at a bound, distorted dwells, ...).
    data : FrequencyResponse or None
        The fitted measurements.
    order : tuple of int
        ``(nb, na)``: numerator and denominator degrees.
    zeros : str
        "minimum_phase" or "free" (how the zeros were parameterized).
    param_names : tuple of str
        Physical parameter names: "gain"; "pole_rad_s" (real pole at
        ``-p``); "natural_frequency_rad_s", "damping_ratio" (one quadratic
        factor) or "natural_frequency1_rad_s", "damping_ratio1", ...
        (two, ascending frequency); "zero_rad_s", "zero_natural_frequency_rad_s",
        "zero_damping_ratio" (minimum-phase zeros) or "num_c1", ... (free
        numerator coefficients of ``s**i``, units s**i); "dead_time_s".
    params, stderr : dict of str to float
        Values and standard errors (Jacobian), physical units.
    ci95 : dict of str to (float, float)
        95 % intervals ``value +- t(0.975, dof)*stderr`` (as nlparci).
    ci95_bootstrap : dict of str to (float, float) or None
        Percentile intervals from resampling the dwells (when asked).
    bootstrap_samples : numpy.ndarray or None
        The bootstrap estimates, shape (N, n_params), columns as `param_names`.
    J : float
        CIFER cost (magnitude term only in magnitude mode).
    aic, bic : float
        Akaike / Bayesian information criteria (unknown noise scale).
    n_params, n_residuals : int
        Number of fitted parameters and of residuals.
    undetermined : tuple of str
        Pole/zero parameters the data do not determine (empty for a
        well-posed fit); see :mod:`servoscope.sysid.tf_fit`.
    order_selection : OrderSelection or None
        The comparison of orders when the order was chosen automatically.
    stderr_jacobian : dict of str to float
        Standard errors from the Jacobian (Birge-scaled), before the
        jackknife's check.
    stderr_jackknife : dict of str to float or None
        Delete-one-dwell jackknife standard errors (None when there are too
        few dwells, fewer than ``n_params + 2``).
    held : dict of str to dict
        Parameters the user held, as lmfit's ``vary=False`` and ``min``/``max``:
        ``{"damping_ratio": {"fixed": 0.8}}`` or ``{"natural_frequency_rad_s":
        {"bounds": [20, 80]}}``. A fixed one has standard error 0 and its
        interval is its value; `n_params`, the degrees of freedom, AIC and BIC
        count the free ones only.
    influence : dict of str to dict or None
        Per parameter, the dwell whose removal moves it most:
        ``{"dwell": label, "without": value, "shift_stderr": (value without
        − value) / stated stderr}``.
    """

    covariance: NDArray[np.float64] = field(repr=False, compare=False)
    residual_rms_db: float = float("nan")
    residual_rms_deg: float | None = None
    n_points: int = 0
    mode: str = "magnitude"
    cost: float = float("nan")
    warnings: tuple[str, ...] = ()
    data: FrequencyResponse | None = field(default=None, repr=False, compare=False)
    order: tuple[int, int] = (0, 2)
    zeros: str = "minimum_phase"
    param_names: tuple[str, ...] = ()
    params: dict[str, float] = field(default_factory=dict)
    stderr: dict[str, float] = field(default_factory=dict)
    ci95: dict[str, tuple[float, float]] = field(default_factory=dict, repr=False)
    ci95_bootstrap: dict[str, tuple[float, float]] | None = field(default=None, repr=False)
    bootstrap_samples: NDArray[np.float64] | None = field(default=None, repr=False, compare=False)
    J: float = float("nan")
    aic: float = float("nan")
    bic: float = float("nan")
    n_params: int = 0
    n_residuals: int = 0
    order_selection: OrderSelection | None = field(default=None, repr=False, compare=False)
    undetermined: tuple[str, ...] = ()
    stderr_jacobian: dict[str, float] = field(default_factory=dict, repr=False)
    stderr_jackknife: dict[str, float] | None = field(default=None, repr=False)
    influence: dict[str, dict[str, Any]] | None = field(default=None, repr=False)
    held: dict[str, dict[str, Any]] = field(default_factory=dict, repr=False)
    _structure: Structure | None = field(default=None, repr=False, compare=False)
    _theta: NDArray[np.float64] | None = field(default=None, repr=False, compare=False)

    # ------------------------------------------------ named parameters
    # K, ωn, ζ and τ by name: read from `params`/`stderr`, their one home (they were stored twice).
    def _second(self, name: str, table: dict[str, float]) -> float | None:
        return table.get(name) if self.order[1] == 2 else None

    @property
    def gain(self) -> float:
        """Static gain ``K = G(0)`` (output units per input unit, e.g. rad per unit)."""
        return self.params["gain"]

    @property
    def gain_stderr(self) -> float:
        """Standard error of :attr:`gain` (NaN when not estimable)."""
        return self.stderr["gain"]

    @property
    def natural_frequency_rad_s(self) -> float | None:
        """``ωn`` (rad/s) of a second-order denominator; None for other orders (see `params`)."""
        return self._second("natural_frequency_rad_s", self.params)

    @property
    def natural_frequency_stderr_rad_s(self) -> float | None:
        """Standard error of :attr:`natural_frequency_rad_s` (None for other orders)."""
        return self._second("natural_frequency_rad_s", self.stderr)

    @property
    def damping_ratio(self) -> float | None:
        """``ζ`` of a second-order denominator; None for other orders."""
        return self._second("damping_ratio", self.params)

    @property
    def damping_ratio_stderr(self) -> float | None:
        """Standard error of :attr:`damping_ratio` (None for other orders)."""
        return self._second("damping_ratio", self.stderr)

    @property
    def dead_time_s(self) -> float | None:
        """Dead time ``τ`` in s (a complex fit's; None for a magnitude fit, which cannot identify it)."""
        return self.params.get("dead_time_s")

    @property
    def dead_time_stderr_s(self) -> float | None:
        """Standard error of :attr:`dead_time_s`, s."""
        return self.stderr.get("dead_time_s")

    @property
    def dof(self) -> int:
        """Degrees of freedom of the fit: residuals less free parameters."""
        return self.n_residuals - self.n_params

    @property
    def model_name(self) -> str:  # type: ignore[override]
        return f"transfer function of order {tuple(self.order)}, {self.mode} fit"

    @property
    def parameters(self) -> Parameters:
        """Every parameter with its error and its Student-t 95 % interval (as MATLAB's ``nlparci``)."""
        names = list(self.param_names or self.params)
        cov = np.asarray(self.covariance, dtype=float)
        correlation = None
        free = [n for n in names if "fixed" not in self.held.get(n, {})]
        if cov.shape == (len(names), len(names)) and len(free) > 1:
            idx = [names.index(n) for n in free]
            c = cov[np.ix_(idx, idx)]
            d = np.sqrt(np.clip(np.diag(c), 0.0, None))
            with np.errstate(invalid="ignore", divide="ignore"):
                correlation = c / np.outer(d, d)
        out = []
        for name in names:
            held = self.held.get(name, {})
            lo, hi = held.get("bounds", (-math.inf, math.inf))
            out.append(Parameter(name, self.params[name], self.stderr.get(name, math.nan),
                                 self.ci95.get(name, (math.nan, math.nan)), vary="fixed" not in held, min=lo, max=hi,
                                 unit=unit_of(name), interval="student", dof=float(self.dof)))
        return Parameters(out, correlation=correlation, correlated=free if correlation is not None else ())

    def fit_statistics(self) -> dict[str, Any]:
        """Points, parameters, residuals, degrees of freedom, CIFER's J, AIC, BIC, the residuals' RMS."""
        return {"points": self.n_points, "free parameters": self.n_params, "residuals": self.n_residuals,
                "degrees of freedom": self.dof, "J": self.J, "J rating": self.J_rating, "AIC": self.aic,
                "BIC": self.bic, "residual RMS (dB)": self.residual_rms_db,
                "residual RMS (deg)": self.residual_rms_deg}

    # -------------------------------------------------------------- model
    @property
    def num(self) -> list[float]:
        """Numerator coefficients, descending powers of s (``K*[c_nb, ..., c1, 1]``)."""
        assert self._structure is not None and self._theta is not None
        return [float(v) for v in self._structure.num_den(self._theta)[0]]

    @property
    def den(self) -> list[float]:
        """Denominator, descending powers of s, constant term 1 (``[1/wn**2, 2*zeta/wn, 1]`` for order (0, 2))."""
        assert self._structure is not None and self._theta is not None
        return [float(v) for v in self._structure.num_den(self._theta)[1]]

    @property
    def transfer_function(self) -> control.TransferFunction:
        """The rational part as a ``control.TransferFunction`` (no dead time)."""
        return control.tf(self.num, self.den)

    @property
    def poles_rad_s(self) -> NDArray[np.complex128]:
        """Poles in rad/s (all with negative real part)."""
        return np.roots(self.den)

    @property
    def zeros_rad_s(self) -> NDArray[np.complex128]:
        """Zeros in rad/s."""
        num = np.trim_zeros(np.asarray(self.num), "f")
        return np.roots(num) if num.size > 1 else np.zeros(0, dtype=complex)

    @property
    def natural_frequency_hz(self) -> float | None:
        """``wn`` in Hz (None for orders other than na == 2)."""
        wn = self.natural_frequency_rad_s
        return None if wn is None else wn / (2.0 * math.pi)

    @property
    def bandwidth_rad_s(self) -> float:
        """-3 dB bandwidth (relative to the DC gain) of the fitted model, rad/s."""
        return bandwidth_rad_s(self.transfer_function)

    @property
    def bandwidth_hz(self) -> float:
        """-3 dB bandwidth in Hz."""
        return self.bandwidth_rad_s / (2.0 * math.pi)

    @property
    def J_rating(self) -> str:
        """CIFER's verdict on `J`: "near-perfect" (<= 50), "acceptable" (<= 100) or "poor"."""
        return j_rating(self.J)

    def frequency_response(self, omega_rad_s: ArrayLike) -> NDArray[np.complex128]:
        """Model ``G(jw)`` including the dead time (if fitted), complex."""
        assert self._structure is not None and self._theta is not None
        w = np.asarray(omega_rad_s, dtype=float)
        return np.exp(log_response(self._structure, self._theta, w.ravel())).reshape(w.shape)

    def magnitude(self, omega_rad_s: ArrayLike) -> NDArray[np.float64]:
        """Model ``|G(jw)|`` at angular frequencies `omega_rad_s` (rad/s)."""
        return np.abs(self.frequency_response(omega_rad_s))

    def phase_rad(self, omega_rad_s: ArrayLike) -> NDArray[np.float64]:
        """Model phase in rad, continuous in w (incl. the dead time if fitted)."""
        assert self._structure is not None and self._theta is not None
        w = np.asarray(omega_rad_s, dtype=float)
        return continuous_phase_rad(self._structure, self._theta, w.ravel()).reshape(w.shape)

    def phase_deg(self, omega_rad_s: ArrayLike) -> NDArray[np.float64]:
        """Model phase in degrees (see :meth:`phase_rad`)."""
        return np.degrees(self.phase_rad(omega_rad_s))

    # ------------------------------------------------------------- output
    def summary(self) -> dict[str, Any]:
        """Scalar results as a JSON-serializable dict (NaN -> None).

        Keys: mode, order, zeros, gain (+ _stderr), natural_frequency_rad_s,
        damping_ratio (+ stderrs; None unless na == 2), dead_time_s,
        dead_time_stderr_s, bandwidth_rad_s, bandwidth_hz, num, den, poles
        and zeros_rad_s (``[re, im]`` pairs), params, stderr, ci95,
        ci95_bootstrap, fit ({mode, J, J_rating, AIC, BIC, n_points,
        n_params, n_residuals, dof}), residual_rms_db, residual_rms_deg,
        n_points, undetermined, warnings.
        """
        try:
            bw = self.bandwidth_rad_s
        except ServoscopeError:
            bw = float("nan")
        return jsonable(
            {
                "mode": self.mode,
                "order": list(self.order),
                "zeros": self.zeros,
                "gain": self.gain,
                "gain_stderr": self.gain_stderr,
                "natural_frequency_rad_s": self.natural_frequency_rad_s,
                "natural_frequency_stderr_rad_s": self.natural_frequency_stderr_rad_s,
                "damping_ratio": self.damping_ratio,
                "damping_ratio_stderr": self.damping_ratio_stderr,
                "dead_time_s": self.dead_time_s,
                "dead_time_stderr_s": self.dead_time_stderr_s,
                "bandwidth_rad_s": bw,
                "bandwidth_hz": bw / (2.0 * math.pi),
                "num": self.num,
                "den": self.den,
                "poles": [[p.real, p.imag] for p in self.poles_rad_s],
                "zeros_rad_s": [[z.real, z.imag] for z in self.zeros_rad_s],
                "params": dict(self.params),
                "stderr": dict(self.stderr),
                "ci95": {k: list(v) for k, v in self.ci95.items()},
                "ci95_bootstrap": None
                if self.ci95_bootstrap is None
                else {k: list(v) for k, v in self.ci95_bootstrap.items()},
                "stderr_jacobian": dict(self.stderr_jacobian),
                "stderr_jackknife": None if self.stderr_jackknife is None else dict(self.stderr_jackknife),
                "influence": None if self.influence is None else {k: dict(v) for k, v in self.influence.items()},
                "fit": {
                    "mode": self.mode,
                    "J": self.J,
                    "J_rating": self.J_rating,
                    "AIC": self.aic,
                    "BIC": self.bic,
                    "n_points": self.n_points,
                    "n_params": self.n_params,
                    "n_residuals": self.n_residuals,
                    "dof": self.n_residuals - self.n_params,
                },
                "residual_rms_db": self.residual_rms_db,
                "residual_rms_deg": self.residual_rms_deg,
                "n_points": self.n_points,
                "undetermined": list(self.undetermined),
                "held": {k: dict(v) for k, v in self.held.items()},
                "warnings": list(self.warnings),
                # The parameters' covariance, rows and columns in `params`' order.
                "covariance": np.asarray(self.covariance, dtype=float),
            }
        )

    @classmethod
    def from_summary(cls, summary: dict[str, Any], data: FrequencyResponse | None = None) -> "TransferFunctionFit":
        """Rebuild a fit from its :meth:`summary` (a saved result.json's ``model``).

        Parameters
        ----------
        summary : dict
            What :meth:`summary` returned (the model part of result.json).
        data : FrequencyResponse, optional
            The points it was fitted to (for :meth:`plot` and :meth:`to_pandas`).

        Returns
        -------
        TransferFunctionFit
            Its :meth:`summary` equals `summary` (to the last bit or two: the model is
            rebuilt from its parameters); the bootstrap's samples and the order
            comparison are not in a summary.

        Raises
        ------
        ServoscopeError
            When the parameters do not match the model's order.
        """
        order = (int(summary["order"][0]), int(summary["order"][1]))
        structure = Structure(order[0], order[1], summary["zeros"], summary["mode"] == "complex", 1.0)
        names = structure.names()
        params = summary.get("params") or {}
        if sorted(params) != sorted(names):
            raise ServoscopeError(f"model of order {order}: parameters {sorted(params)} are not {sorted(names)}")
        theta = structure.theta_from_physical(np.array([params[n] for n in names], dtype=float))
        cov = summary.get("covariance")
        cov = (np.full((len(names), len(names)), np.nan) if cov is None
               else np.array([[math.nan if v is None else v for v in row] for row in cov], dtype=float))

        def nan(d: dict | None) -> dict | None:
            return None if d is None else {k: math.nan if v is None else v for k, v in d.items()}

        def pairs(d: dict | None) -> dict | None:
            return None if d is None else {k: tuple(math.nan if x is None else x for x in v) for k, v in d.items()}

        fit = summary.get("fit") or {}
        kw = fields_from_summary(
            cls, summary, covariance=readonly(cov), data=data, order=order, param_names=names,
            params={n: float(params[n]) for n in names}, stderr=nan(summary.get("stderr")),
            ci95=pairs(summary.get("ci95")), ci95_bootstrap=pairs(summary.get("ci95_bootstrap")),
            stderr_jacobian=nan(summary.get("stderr_jacobian")), stderr_jackknife=nan(summary.get("stderr_jackknife")),
            J=math.nan if fit.get("J") is None else fit["J"], aic=math.nan if fit.get("AIC") is None else fit["AIC"],
            bic=math.nan if fit.get("BIC") is None else fit["BIC"], n_params=int(fit.get("n_params", len(names))),
            n_residuals=int(fit.get("n_residuals", 0)), _structure=structure, _theta=theta)
        return cls(**kw)

    def to_pandas(self) -> Any:
        """Measured vs. fitted gain (and phase) per point as a DataFrame. Needs pandas."""
        pd = import_pandas()
        if self.data is None:
            raise ServoscopeError("TransferFunctionFit.to_pandas: no data attached")
        w = self.data.omega_rad_s
        model_db = 20.0 * np.log10(self.magnitude(w))
        return pd.DataFrame(
            {
                "video": list(self.data.labels),
                "omega_rad_s": w,
                "gain_db": self.data.gain_db,
                "model_gain_db": model_db,
                "residual_db": self.data.gain_db - model_db,
                "phase_deg": self.data.phase_deg,
                "model_phase_deg": np.degrees(self.phase_rad(w)),
            }
        )

    def plot(
        self, ax: Axes | None = None, *, phase_ax: Axes | None = None, omega_rad_s: ArrayLike | None = None
    ) -> list[Any]:
        """Draw the fitted data (:meth:`FrequencyResponse.plot`) and the model's gain (and phase) on `ax`.

        Parameters
        ----------
        ax : matplotlib.axes.Axes, optional
            Axes for the gains in dB (a new figure's when None).
        phase_ax : matplotlib.axes.Axes, optional
            Axes for the phases in degrees (the model's includes the dead time when fitted).
        omega_rad_s : array_like, optional
            Where to draw the model; default 300 points from half the lowest to twice the
            highest measured frequency (0.1 to 100 rad/s without data).

        Returns
        -------
        list
            The data's artists (when data are attached), then the model's gain line (x =
            `omega_rad_s`, y = ``20*log10(magnitude(omega_rad_s))``) and, with `phase_ax`, its
            phase line.
        """
        ax = new_axes(ax)
        artists: list[Any] = []
        if self.data is not None:
            artists += self.data.plot(ax, phase_ax=phase_ax)
        if omega_rad_s is None:
            w = self.data.omega_rad_s if self.data is not None else np.array([0.2, 50.0])
            w = w[np.isfinite(w) & (w > 0)]
            omega_rad_s = np.logspace(np.log10(w.min() / 2), np.log10(w.max() * 2), 300)
        w = np.asarray(omega_rad_s, dtype=float)
        artists.append(plot_model_gain(ax, w, self.magnitude(w)))
        if phase_ax is not None:
            artists.append(plot_model_phase(phase_ax, w, self.phase_deg(w)))
        return artists


@dataclass(frozen=True)
class OrderSelection:
    """Result of :func:`~servoscope.sysid.select_order`.

    Attributes
    ----------
    table : tuple of dict
        One row per candidate, ascending ``n_params``: ``order`` ([nb, na]),
        ``n_params``, ``J``, ``AIC``, ``BIC``, ``residual_rms_db``,
        ``residual_rms_deg``, ``relative_degree`` (na - nb), ``determined``
        (every pole/zero parameter determined by the data), ``chosen``.
    best : TransferFunctionFit
        The chosen model.
    fits : dict of (nb, na) to TransferFunctionFit
        Every candidate's fit.
    criterion : str
        "BIC" or "AIC".
    mode : str
        "magnitude" or "complex".
    slope_db_per_decade, slope_stderr_db_per_decade : float
        Measured high-frequency slope (see :func:`~servoscope.sysid.estimate_slope_db_per_decade`).
    relative_degree_estimate : int or None
        ``max(1, round(-slope/20))`` (None when the slope is unknown).
    noise_scale : float
        ``phi`` (see :mod:`servoscope.sysid.order`); 1 when the measured standard
        errors explain the scatter of the best candidate.
    warnings : tuple of str
        Candidates that could not be fitted, disagreements.
    """

    table: tuple[dict[str, Any], ...]
    best: TransferFunctionFit
    fits: dict[tuple[int, int], TransferFunctionFit] = field(repr=False)
    criterion: str
    mode: str
    slope_db_per_decade: float
    slope_stderr_db_per_decade: float
    relative_degree_estimate: int | None
    noise_scale: float = 1.0
    warnings: tuple[str, ...] = ()

    @property
    def order(self) -> tuple[int, int]:
        """The chosen ``(nb, na)``."""
        return self.best.order

    def summary(self) -> dict[str, Any]:
        """JSON-serializable dict: chosen order, criterion, slope, table, warnings."""
        return jsonable(
            {
                "chosen_order": list(self.best.order),
                "criterion": self.criterion,
                "mode": self.mode,
                "slope_db_per_decade": self.slope_db_per_decade,
                "slope_stderr_db_per_decade": self.slope_stderr_db_per_decade,
                "relative_degree_estimate": self.relative_degree_estimate,
                "noise_scale": self.noise_scale,
                "table": [dict(r) for r in self.table],
                "warnings": list(self.warnings),
            }
        )

    def to_pandas(self) -> Any:
        """The table as a pandas DataFrame. Needs pandas."""
        pd = import_pandas()
        rows = [dict(r, order=f"({r['order'][0]}, {r['order'][1]})") for r in self.table]
        return pd.DataFrame(rows, columns=list(ORDER_TABLE_KEYS))

    def _repr_html_(self) -> str:
        def cell(v: Any) -> str:
            if isinstance(v, float):
                return f"{v:.4g}"
            if isinstance(v, list):
                return f"({v[0]}, {v[1]})"
            return "✔" if v is True else ("" if v is False or v is None else str(v))

        cap = (
            f"Order selection ({self.mode}, {self.criterion}); high-frequency slope "
            f"{self.slope_db_per_decade:.1f} ± {self.slope_stderr_db_per_decade:.1f} dB/decade"
        )
        return html_rows(ORDER_TABLE_KEYS, ([cell(r[k]) for k in ORDER_TABLE_KEYS] for r in self.table), cap)
