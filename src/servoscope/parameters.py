"""One Parameters layer under every fit: a parameter's value, error, interval and how it was held.

Every model servoscope fits (the transfer function, the servo structures, the step, the
blade's modes, the heave model, the exposure, the dead time) states its numbers as
:class:`Parameter` objects gathered in one :class:`Parameters`, after lmfit's
``Parameter``/``Parameters``: a value, its standard error, its 95 % interval, whether it
varied, its limits, the expression it is tied by, its unit, and *how* its interval was made.
The report, the command line's tables, the notebook view and result.json all read these, so
one run cannot show one number two ways.

Intervals are made in one place, :func:`interval95`:

``"normal"``
    ``value ± z·stderr`` with ``z`` the normal 97.5 % point (errors from a sandwich or
    a propagation, many effective samples).
``"student"``
    ``value ± t(0.975, dof)·stderr`` (as MATLAB's ``nlparci``; the transfer-function fit's
    few dwells).
``"lognormal"``
    ``value ×/÷ exp(z·stderr/value)`` for a positive quantity fitted on a log scale (a
    natural frequency, a damping ratio, a rate limit, an exposure): never below zero.
``"profile"``
    Given by a profile of the cost (a parameter fitted on a grid); its standard error is
    the interval's half width over ``z``, for tables only.
``"wilson"``
    Given by Wilson's score interval of a proportion (the exposure read from the LED's
    switching frames), its standard error stated beside it.

What the user holds (lmfit's ``vary=False``, ``min``/``max`` and ``expr``) is checked once,
by :func:`check_held`, whichever door it came in by: the Python API, campaign.toml's
``[model]`` or the command line's ``--fix``/``--bound``.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from typing import Any, Literal

from statistics import NormalDist

import numpy as np

from .errors import ServoscopeError
from .numbers import format_interval, format_value, format_with_uncertainty
from .results import html_rows, import_pandas, jsonable

__all__ = ["INTERVAL_KINDS", "FitResult", "Parameter", "Parameters", "check_held", "interval95", "inverse_variance_mean",
           "stderr_of_interval",
           "Tie", "tie_names", "unit_of"]

#: How a 95 % interval can be made (see the module's description).
INTERVAL_KINDS = ("normal", "student", "lognormal", "profile", "wilson")
IntervalKind = Literal["normal", "student", "lognormal", "profile", "wilson"]

# The normal distribution's 97.5 % point: the one place it is written. (The standard library's
# quantile, exact to the last bit: scipy.stats costs 0.7 s to import, and every stage imports this.)
_Z = NormalDist().inv_cdf(0.975)


# Units as the names spell them (``natural_frequency_rad_s``), longest suffix first.
_SUFFIX_UNITS = (("_rad_s", "rad/s"), ("_rad_s2", "rad/s²"), ("_s2", "s²"), ("_hz", "Hz"), ("_rad", "rad"),
                 ("_deg", "°"), ("_px", "px"), ("_ms", "ms"), ("_s", "s"))


def unit_of(name: str) -> str:
    """The unit a parameter's name carries (``dead_time_s`` → "s", ``natural_frequency_rad_s`` → "rad/s"; "" for none)."""
    for suffix, unit in sorted(_SUFFIX_UNITS, key=lambda su: -len(su[0])):
        if name.endswith(suffix):
            return unit
    return ""


def inverse_variance_mean(values, stderrs) -> tuple[float, float]:
    """Several estimates of one quantity pooled: their inverse-variance mean and its standard error.

    Where the estimates disagree beyond their errors (χ² over its n − 1 degrees of freedom above 1),
    the error is widened by its square root (the Birge ratio), so that it never claims more than the
    estimates' own scatter supports.
    """
    v = np.asarray(values, dtype=float)
    w = 1.0 / np.asarray(stderrs, dtype=float) ** 2
    mean = float(np.sum(w * v) / np.sum(w))
    stderr = math.sqrt(1.0 / float(np.sum(w)))
    if v.size > 1:
        chi2 = float(np.sum(w * (v - mean) ** 2)) / (v.size - 1)
        stderr *= math.sqrt(max(chi2, 1.0))
    return mean, stderr


def interval95(value: float, stderr: float, kind: IntervalKind = "normal", *,
               dof: float | None = None) -> tuple[float, float]:
    """The 95 % interval of a parameter: the one function every fit's intervals come from.

    Parameters
    ----------
    value : float
        The estimate.
    stderr : float
        Its standard error (0 for a parameter held fixed: the interval is the value; NaN
        when not estimable: the interval is NaN).
    kind : {"normal", "student", "lognormal"}
        How the interval is made (see the module's description). A log-normal interval of
        a value that is not positive falls back to the normal one.
    dof : float, optional
        Degrees of freedom, for ``kind="student"`` (NaN interval when < 1).

    Returns
    -------
    (float, float)
        Lower and upper limits.

    Raises
    ------
    ValueError
        An unknown `kind`, ``"student"`` without `dof`, or ``"profile"``/``"wilson"``
        (such intervals are given by their estimators, not made from an error).
    """
    value, stderr = float(value), float(stderr)
    if kind in ("profile", "wilson"):
        raise ValueError(f"a {kind} interval is given by its own estimator, not made from a standard error")
    if kind not in INTERVAL_KINDS:
        raise ValueError(f"unknown interval kind {kind!r} (one of {', '.join(INTERVAL_KINDS)})")
    if not (math.isfinite(value) and math.isfinite(stderr)) or stderr < 0:
        return (math.nan, math.nan)
    if stderr == 0.0:
        return (value, value)
    if kind == "student":
        if dof is None:
            raise ValueError("a Student-t interval needs its degrees of freedom")
        if not dof >= 1:
            return (math.nan, math.nan)
        from scipy.stats import t as student_t  # only a Student-t interval needs it

        q = float(student_t.ppf(0.975, dof))
        return (value - q * stderr, value + q * stderr)
    if kind == "lognormal" and value > 0:
        # Capped so that a huge relative error gives (0+, inf-ish), not an overflow.
        factor = math.exp(min(_Z * stderr / value, 50.0))
        return (value / factor, value * factor)
    return (value - _Z * stderr, value + _Z * stderr)


def stderr_of_interval(low: float, high: float) -> float:
    """The standard error a 95 % interval stands for (its half width over the normal 97.5 % point).

    For an interval not made from an error (a profile's): the tables' "stderr" column.
    """
    return (float(high) - float(low)) / (2.0 * _Z)


@dataclass(frozen=True)
class Parameter:
    """One fitted (or held) parameter, as lmfit's ``Parameter``.

    Attributes
    ----------
    name : str
        As the model names it (``gain``, ``natural_frequency_rad_s``, ``dead_time_s``, …):
        the unit is in the name where it has one.
    value : float
    stderr : float
        Standard error (0 when held fixed, NaN when the data cannot tell it).
    ci95 : (float, float)
        The 95 % interval, made by :func:`interval95` (or given by a profile).
    vary : bool
        False when the user held it fixed.
    min, max : float
        Limits the fit kept it within (``-inf``/``inf``: none).
    expr : str or None
        The expression it is tied by (lmfit's ``expr``), else None.
    unit : str
        Its unit for tables ("rad/s", "s", "" for a ratio).
    interval : str
        How `ci95` was made: "normal", "student", "lognormal" or "profile".
    dof : float or None
        The Student-t interval's degrees of freedom.
    """

    name: str
    value: float
    stderr: float = math.nan
    ci95: tuple[float, float] = (math.nan, math.nan)
    vary: bool = True
    min: float = -math.inf
    max: float = math.inf
    expr: str | None = None
    unit: str = ""
    interval: str = "normal"
    dof: float | None = None

    @classmethod
    def estimated(cls, name: str, value: float, stderr: float, *, interval: IntervalKind = "normal",
                  dof: float | None = None, unit: str = "", **held: Any) -> "Parameter":
        """A parameter with its interval made from `stderr` by :func:`interval95`.

        ``held`` takes ``vary``, ``min``, ``max``, ``expr``; a parameter with ``vary=False``
        has stderr 0 and its value as its interval.
        """
        value = float(value)
        stderr = 0.0 if held.get("vary", True) is False else float(stderr)
        return cls(name, value, stderr, interval95(value, stderr, interval, dof=dof), unit=unit,
                   interval=interval, dof=dof, **held)

    @classmethod
    def profiled(cls, name: str, value: float, ci95: tuple[float, float], *, unit: str = "",
                 **held: Any) -> "Parameter":
        """A parameter whose interval a cost profile gave (its stderr the interval's equivalent)."""
        lo, hi = float(ci95[0]), float(ci95[1])
        return cls(name, float(value), stderr_of_interval(lo, hi), (lo, hi), unit=unit, interval="profile", **held)

    @property
    def relative_stderr(self) -> float:
        """``stderr/|value|`` (NaN at zero)."""
        return self.stderr / abs(self.value) if self.value else math.nan

    def cells(self) -> tuple[str, str, str]:
        """The value, its standard error and its 95 % interval as every view writes them.

        The value rounded where the error's second digit is (:func:`servoscope.numbers.format_with_uncertainty`):
        the report, ``identify``'s table and the notebook show these same strings. A fixed
        parameter's error and interval are "—".
        """
        if not self.vary:
            return format_value(self.value), "—", "—"
        value, err = format_with_uncertainty(self.value, self.stderr)
        return value, err, format_interval(self.ci95[0], self.ci95[1], self.stderr)

    def held_text(self) -> str:
        """How the user held it, for a label: " (held fixed)", " (= 4*gain)", " (bounded 20–80)" or ""."""
        if self.expr is not None:
            return f" (= {self.expr})"
        if not self.vary:
            return " (held fixed)"
        if math.isfinite(self.min) and math.isfinite(self.max):
            return f" (bounded {self.min:.4g}–{self.max:.4g})"
        return ""

    def holds(self, truth: float) -> bool:
        """Whether the 95 % interval holds `truth`."""
        return bool(self.ci95[0] <= truth <= self.ci95[1])

    def summary(self) -> dict[str, Any]:
        """Plain JSON types: every attribute (limits only where set)."""
        out: dict[str, Any] = {"value": self.value, "stderr": self.stderr, "ci95": list(self.ci95),
                               "vary": self.vary, "interval": self.interval}
        if self.dof is not None:
            out["dof"] = self.dof
        if math.isfinite(self.min) or math.isfinite(self.max):
            out["min"], out["max"] = self.min, self.max
        if self.expr is not None:
            out["expr"] = self.expr
        if self.unit:
            out["unit"] = self.unit
        return jsonable(out)

    @classmethod
    def from_summary(cls, name: str, data: Mapping[str, Any]) -> "Parameter":
        """Rebuild from :meth:`summary` (JSON's None read back as NaN or an open limit)."""
        def num(v: Any, default: float = math.nan) -> float:
            return default if v is None else float(v)

        ci = data.get("ci95") or (None, None)
        return cls(name, num(data.get("value")), num(data.get("stderr")), (num(ci[0]), num(ci[1])),
                   bool(data.get("vary", True)), num(data.get("min"), -math.inf), num(data.get("max"), math.inf),
                   data.get("expr"), data.get("unit", ""), data.get("interval", "normal"), data.get("dof"))


class Parameters(Mapping[str, Parameter]):
    """An ordered, read-only collection of :class:`Parameter` by name (lmfit's ``Parameters``).

    Parameters
    ----------
    parameters : iterable of Parameter
        In the order tables show them; names must be unique.
    correlation : numpy.ndarray, optional
        The free parameters' correlation matrix, rows and columns in the order of
        `correlated` (for :meth:`fit_report`).
    correlated : sequence of str, optional
    """

    def __init__(self, parameters: Iterable[Parameter] = (), *, correlation: Any = None,
                 correlated: Iterable[str] = ()):
        self._items: dict[str, Parameter] = {}
        for p in parameters:
            if p.name in self._items:
                raise ValueError(f"parameter {p.name!r} given twice")
            self._items[p.name] = p
        self.correlated = tuple(correlated)
        corr = None if correlation is None else np.array(correlation, dtype=float)
        if corr is not None:
            if corr.shape != (len(self.correlated),) * 2:
                raise ValueError("the correlation matrix must be square, one row per name in `correlated`")
            corr.setflags(write=False)
        self.correlation = corr

    def __getitem__(self, name: str) -> Parameter:
        try:
            return self._items[name]
        except KeyError:
            close = difflib.get_close_matches(name, list(self._items), n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise KeyError(f"no parameter {name!r}{hint}; the parameters: {', '.join(self._items)}") from None

    def __iter__(self) -> Iterator[str]:
        return iter(self._items)

    def __len__(self) -> int:
        return len(self._items)

    def __repr__(self) -> str:
        inner = ", ".join(f"{p.name}={p.value:.6g}±{p.stderr:.2g}" for p in self._items.values())
        return f"Parameters({inner})"

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Parameters) and list(self._items.values()) == list(other._items.values())

    __hash__ = None  # type: ignore[assignment]

    def valuesdict(self) -> dict[str, float]:
        """``{name: value}`` (lmfit's name)."""
        return {k: p.value for k, p in self._items.items()}

    def summary(self) -> dict[str, Any]:
        """``{name: Parameter.summary()}``; plain JSON types."""
        return {k: p.summary() for k, p in self._items.items()}

    @classmethod
    def from_summary(cls, data: Mapping[str, Mapping[str, Any]]) -> "Parameters":
        """Rebuild from :meth:`summary`."""
        return cls(Parameter.from_summary(k, v) for k, v in data.items())

    def rows(self) -> list[dict[str, Any]]:
        """One dict per parameter: name, value, stderr, ci95_low, ci95_high, vary, expr, unit, interval."""
        return [{"parameter": p.name, "value": p.value, "stderr": p.stderr, "ci95_low": p.ci95[0],
                 "ci95_high": p.ci95[1], "vary": p.vary, "expr": p.expr, "unit": p.unit, "interval": p.interval}
                for p in self._items.values()]

    def to_pandas(self) -> Any:
        """A DataFrame indexed by parameter (the columns of :meth:`rows`)."""
        return import_pandas().DataFrame(self.rows()).set_index("parameter")

    def report_lines(self, min_correlation: float = 0.1) -> list[str]:
        """lmfit's ``[[Variables]]`` and ``[[Correlations]]`` blocks, as lines."""
        lines = ["[[Variables]]"]
        width = max((len(k) for k in self._items), default=0)
        for p in self._items.values():
            if p.expr is not None:
                how = f"== '{p.expr}'"
            elif not p.vary:
                how = "(fixed)"
            else:
                rel = f" ({100 * p.relative_stderr:.2f}%)" if math.isfinite(p.relative_stderr) else ""
                how = f"+/- {p.stderr:.4g}{rel}"
            interval = f"  95% [{p.ci95[0]:.6g}, {p.ci95[1]:.6g}] {p.interval}" if p.vary or p.expr else ""
            unit = f" {p.unit}" if p.unit else ""
            lines.append(f"    {p.name:<{width}}: {p.value:.6g}{unit} {how}{interval}")
        if self.correlation is not None and len(self.correlated) > 1:
            pairs = [(abs(self.correlation[i, j]), self.correlated[i], self.correlated[j], self.correlation[i, j])
                     for i in range(len(self.correlated)) for j in range(i + 1, len(self.correlated))
                     if np.isfinite(self.correlation[i, j]) and abs(self.correlation[i, j]) >= min_correlation]
            if pairs:
                lines.append(f"[[Correlations]] (unreported correlations are < {min_correlation:.3f})")
                for _, a, b, c in sorted(pairs, reverse=True):
                    lines.append(f"    C({a}, {b}) = {c:+.4f}")
        return lines


def tie_names(expression: str) -> set[str]:
    """The parameter names a tie's expression uses (asteval's own functions and constants left out).

    Raises
    ------
    ServoscopeError
        Not an expression.
    """
    from asteval import Interpreter, get_ast_names

    interp = Interpreter(minimal=True, use_numpy=False)
    try:
        tree = interp.parse(expression)
    except SyntaxError as exc:
        raise ServoscopeError(f"tie {expression!r}: not an expression ({exc.msg or 'syntax error'})") from None
    if tree is None:
        raise ServoscopeError(f"tie {expression!r}: not an expression")
    return {n for n in get_ast_names(tree) if n not in interp.symtable}


class Tie:
    """An lmfit-style constraint expression (asteval: arithmetic and math functions only), parsed once.

    A fit evaluates its ties at every residual: one interpreter and one parse serve them all
    (a fresh interpreter costs 0.37 ms, a sizeable part of a simulation).
    """

    def __init__(self, expression: str):
        from asteval import Interpreter

        self.expression = expression
        self._interp = Interpreter(minimal=True, use_numpy=False)
        self._tree = self._interp.parse(expression)  # its syntax was checked by check_held

    def __call__(self, values: dict[str, float]) -> float:
        interp = self._interp
        interp.symtable.update(values)
        value = interp.eval(self._tree, show_errors=False, raise_errors=False)
        if interp.error or value is None:
            message = interp.error[0].get_error()[1].strip().splitlines()[-1] if interp.error else "no value"
            raise ServoscopeError(f"tie {self.expression!r}: {message}")
        return float(value)


def _unknown(who: str, name: str, known: Iterable[str]) -> str:
    known = sorted(known)
    close = difflib.get_close_matches(name, known, n=1)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    return f"{who} has no parameter {name!r}{hint}; its parameters: {', '.join(known)}"


def check_held(known: Iterable[str], fix: Mapping[str, float] | None = None,
               bounds: Mapping[str, tuple[float, float]] | None = None,
               ties: Mapping[str, str] | None = None, *, who: str = "the model") -> None:
    """Check what the user holds against a model's parameter names: the one check, whatever the door.

    Parameters
    ----------
    known : iterable of str
        The parameters the model (or any of the models tried) has.
    fix : mapping of name → value
        Held fixed (lmfit's ``vary=False``).
    bounds : mapping of name → (low, high)
        Kept within limits (``min``/``max``).
    ties : mapping of name → expression
        Computed from others (``expr``).
    who : str
        The model(s) in the message ("the rate_limit model", "--nonlinear auto").

    Raises
    ------
    ServoscopeError
        An unknown name (with a did-you-mean), limits not finite or not in order, a value
        fixed outside its bounds, a tie that uses an unknown or a tied parameter (a chain),
        or a tied parameter also fixed or bounded. The first problem found, in that order.
    """
    known = set(known)
    fix, bounds, ties = dict(fix or {}), dict(bounds or {}), dict(ties or {})
    for name in [*fix, *bounds, *ties]:
        if name not in known:
            raise ServoscopeError(_unknown(who, name, known))
    for name, (lo, hi) in bounds.items():
        if not lo < hi:
            raise ServoscopeError(f"bound on {name}: the lower limit {lo} must be below the upper {hi}")
        if name in fix and not lo <= fix[name] <= hi:
            raise ServoscopeError(f"{name} is fixed at {fix[name]}, outside its bounds [{lo}, {hi}]")
    for name, expression in ties.items():
        for used in sorted(tie_names(expression)):
            if used not in known:
                raise ServoscopeError(f"tie {name} = {expression!r}: {_unknown(who, used, known)}")
            if used in ties:
                raise ServoscopeError(f"tie {name} = {expression!r}: {used} is tied itself; tie to free or fixed "
                                      "parameters only")
        if name in fix or name in bounds:
            raise ServoscopeError(f"{name} is tied ({expression!r}): it cannot also be fixed or bounded")


def _cell(value: float, digits: int = 6) -> str:
    return "—" if value is None or not math.isfinite(value) else f"{value:.{digits}g}"


class FitResult:
    """What every fit's result offers, read from its :attr:`parameters` (lmfit's ``ModelResult``).

    A subclass (a frozen dataclass) provides :attr:`parameters` and, where it has them,
    :meth:`fit_statistics` and ``warnings``; this base turns them into the text report
    (:meth:`fit_report`), the DataFrame (:meth:`to_pandas`) and the notebook's table
    (``_repr_html_``), so that every view of a result shows the same numbers. ``summary()``,
    ``from_summary()`` and ``plot()`` are each result's own (their JSON fields predate this
    layer and stay as result.json has them).
    """

    #: The model's name in reports ("transfer function", "rate_limit servo model", …).
    model_name: str = "model"

    @property
    def parameters(self) -> Parameters:  # pragma: no cover - every subclass overrides it
        """The fitted and held parameters."""
        raise NotImplementedError

    def fit_statistics(self) -> dict[str, Any]:
        """The fit's statistics for the report (samples, cost, AIC, …); empty by default."""
        return {}

    def _warnings(self) -> list[str]:
        return [str(w) for w in (getattr(self, "warnings", None) or ())]

    def fit_report(self, min_correlation: float = 0.1) -> str:
        """A text report like lmfit's: the model, fit statistics, parameters with errors and intervals,
        correlations and warnings.

        Parameters
        ----------
        min_correlation : float
            Correlations smaller in magnitude are left out.
        """
        lines = [f"[[Model]]", f"    {self.model_name}"]
        stats = self.fit_statistics()
        if stats:
            lines.append("[[Fit Statistics]]")
            width = max(len(k) for k in stats)
            for k, v in stats.items():
                shown = _cell(v) if isinstance(v, float) else str(v)
                lines.append(f"    {k:<{width}} = {shown}")
        lines += self.parameters.report_lines(min_correlation)
        warnings = self._warnings()
        if warnings:
            lines.append("[[Warnings]]")
            lines += [f"    {w}" for w in warnings]
        return "\n".join(lines)

    def to_pandas(self) -> Any:
        """One row per parameter: value, stderr, 95 % interval, whether it varied, its tie, unit, interval kind."""
        return self.parameters.to_pandas()

    def _repr_html_(self) -> str:
        # The cells the report and the command line write (Parameter.cells): one number, one text.
        rows = [[p.name + p.held_text(), *p.cells(), p.unit] for p in self.parameters.values()]
        table = html_rows(["parameter", "value", "std. error", "95 % interval", "unit"], rows,
                          caption=f"{type(self).__name__}: {self.model_name}")
        stats = self.fit_statistics()
        extra = ""
        if stats:
            extra = html_rows(["statistic", "value"],
                              [[k, _cell(v) if isinstance(v, float) else v] for k, v in stats.items()])
        warnings = "".join(f"<li>{w}</li>" for w in self._warnings())
        return table + extra + (f"<ul>{warnings}</ul>" if warnings else "")
