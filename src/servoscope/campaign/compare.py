"""A turning rotor's identification beside a static one (issue 33): the servo's K, ωn, ζ, τ static against rotating.

The rotor's loads (the blades' inertia and aerodynamic moments about the pitch axis) may change what the
servo does: the comparison states each headline parameter of both results, their difference with its
standard error (the two errors in quadrature: the campaigns are independent) and its z, and which differ
beyond their errors (|z| > :data:`DIFFERS_Z`, a two-sided 95 % test). :func:`compare_results` gives it to a
notebook; ``servoscope identify ROTOR_CAMPAIGN --beside STATIC_OUT/result.json`` records it in result.json's
``rotor["beside_static"]`` (:func:`with_static_comparison`) and the report's "Under rotation" draws it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

from ..errors import ServoscopeError
from ..parameters import interval95
from ..results import html_rows, import_pandas, jsonable
from .result import IdentificationResult

__all__ = ["COMPARED_PARAMETERS", "DIFFERS_Z", "ParameterComparison", "ResultComparison", "compare_results",
           "load_static_result", "with_static_comparison"]

#: The headline parameters compared, in the report's order: K, ωn, ζ, τ.
COMPARED_PARAMETERS = ("gain", "natural_frequency_rad_s", "damping_ratio", "dead_time_s")
#: |z| beyond which a difference is called real: a two-sided test at 5 % (the intervals' 95 %).
DIFFERS_Z = interval95(0.0, 1.0)[1]


def _number(value) -> float:
    return math.nan if value is None else float(value)


@dataclass(frozen=True)
class ParameterComparison:
    """One parameter static against rotating.

    Attributes
    ----------
    name : str
        The parameter's name (``gain``, ``natural_frequency_rad_s``, ``damping_ratio``, ``dead_time_s``).
    static, static_stderr : float
        The static campaign's value and standard error (NaN where not stated).
    static_ci95 : (float, float)
    rotating, rotating_stderr : float
        The rotor campaign's.
    rotating_ci95 : (float, float)
    difference, difference_stderr : float
        rotating − static, and the two errors in quadrature.
    z : float
        difference / difference_stderr (NaN when either error is unknown).
    differs : bool
        |z| > :data:`DIFFERS_Z`.
    """

    name: str
    static: float
    static_stderr: float
    static_ci95: tuple[float, float]
    rotating: float
    rotating_stderr: float
    rotating_ci95: tuple[float, float]
    difference: float
    difference_stderr: float
    z: float
    differs: bool

    @classmethod
    def of(cls, name: str, static, rotating) -> "ParameterComparison":
        """From two :class:`~servoscope.parameters.Parameter` (either None: NaN)."""
        sv, se = (math.nan, math.nan) if static is None else (_number(static.value), _number(static.stderr))
        rv, re = (math.nan, math.nan) if rotating is None else (_number(rotating.value), _number(rotating.stderr))
        sci = (math.nan, math.nan) if static is None else tuple(_number(c) for c in static.ci95)
        rci = (math.nan, math.nan) if rotating is None else tuple(_number(c) for c in rotating.ci95)
        diff = rv - sv
        diff_se = math.hypot(se, re)
        z = diff / diff_se if diff_se > 0 else math.nan
        return cls(name, sv, se, sci, rv, re, rci, diff, diff_se, z, bool(abs(z) > DIFFERS_Z))

    def summary(self) -> dict:
        """Plain types."""
        return jsonable({"name": self.name, "static": self.static, "static_stderr": self.static_stderr,
                         "static_ci95": list(self.static_ci95), "rotating": self.rotating,
                         "rotating_stderr": self.rotating_stderr, "rotating_ci95": list(self.rotating_ci95),
                         "difference": self.difference, "difference_stderr": self.difference_stderr, "z": self.z,
                         "differs": self.differs})

    @classmethod
    def from_summary(cls, data: dict) -> "ParameterComparison":
        """Back from :meth:`summary` (None read as NaN)."""
        return cls(data["name"], _number(data.get("static")), _number(data.get("static_stderr")),
                   tuple(_number(c) for c in data.get("static_ci95") or (None, None)),
                   _number(data.get("rotating")), _number(data.get("rotating_stderr")),
                   tuple(_number(c) for c in data.get("rotating_ci95") or (None, None)),
                   _number(data.get("difference")), _number(data.get("difference_stderr")), _number(data.get("z")),
                   bool(data.get("differs")))


@dataclass(frozen=True)
class ResultComparison:
    """A rotor's identification beside a static campaign's: :data:`COMPARED_PARAMETERS` static against rotating.

    Attributes
    ----------
    static_path : str
        The static result.json compared with ("" when the result was given as an object).
    static_campaign : str
        The static campaign's manifest, as its result names it.
    parameters : tuple of ParameterComparison
    """

    static_path: str
    static_campaign: str
    parameters: tuple[ParameterComparison, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "parameters", tuple(self.parameters))

    def __getitem__(self, name: str) -> ParameterComparison:
        for p in self.parameters:
            if p.name == name:
                return p
        raise KeyError(name)

    @property
    def differing(self) -> tuple[str, ...]:
        """The parameters that differ beyond their errors."""
        return tuple(p.name for p in self.parameters if p.differs)

    def describe(self) -> list[str]:
        """One line a parameter: static, rotating, the difference and its z (what ``identify --beside`` prints)."""
        return [f"{p.name}: static {p.static:.5g} ± {p.static_stderr:.2g}, rotating {p.rotating:.5g} ± "
                f"{p.rotating_stderr:.2g}, difference {p.difference:+.3g} ± {p.difference_stderr:.2g} "
                f"(z {p.z:+.2f}{', beyond the errors' if p.differs else ''})" for p in self.parameters]

    def summary(self) -> dict:
        """Plain types (result.json's ``rotor["beside_static"]``)."""
        return {"static_result": self.static_path, "static_campaign": self.static_campaign,
                "differs_beyond_z": DIFFERS_Z, "parameters": [p.summary() for p in self.parameters],
                "differing": list(self.differing)}

    @classmethod
    def from_summary(cls, data: dict) -> "ResultComparison":
        """Back from :meth:`summary`."""
        return cls(str(data.get("static_result", "")), str(data.get("static_campaign", "")),
                   tuple(ParameterComparison.from_summary(p) for p in data.get("parameters", [])))

    def to_pandas(self):
        """One row a parameter, its columns :class:`ParameterComparison`'s (pandas is optional)."""
        pd = import_pandas()
        rows = [p.summary() for p in self.parameters]
        return pd.DataFrame(rows).set_index("name")

    def _repr_html_(self) -> str:
        rows = [(p.name, f"{p.static:.5g} ± {p.static_stderr:.2g}", f"{p.rotating:.5g} ± {p.rotating_stderr:.2g}",
                 f"{p.difference:+.3g} ± {p.difference_stderr:.2g}", f"{p.z:+.2f}", "yes" if p.differs else "no")
                for p in self.parameters]
        return html_rows(("parameter", "static", "rotating", "rotating − static", "z", "differs"), rows,
                         f"beside {self.static_path or self.static_campaign}")


def compare_results(static: IdentificationResult, rotating: IdentificationResult, *,
                    static_path: str | Path | None = None) -> ResultComparison:
    """The rotor's identification beside a static campaign's: K, ωn, ζ, τ, their differences and z.

    Parameters
    ----------
    static : IdentificationResult
        A static blade's identification (no ``rotor``).
    rotating : IdentificationResult
        The turning rotor's (the same servo under rotation).
    static_path : path-like, optional
        Where ``static`` was read from, recorded with the comparison.

    Returns
    -------
    ResultComparison
        Each parameter from the results' headlines (:attr:`IdentificationResult.parameters`, what their
        reports state first), so the numbers are the ones both reports show.

    Raises
    ------
    ServoscopeError
        When ``static`` is a turning rotor's result.
    """
    if static.rotor is not None:
        raise ServoscopeError(f"{static_path or static.campaign.path}: a turning rotor's result was given as the "
                              "static one; give the result.json of a campaign without [rotor]")
    s, r = static.parameters, rotating.parameters
    rows = tuple(ParameterComparison.of(name, s.get(name), r.get(name)) for name in COMPARED_PARAMETERS)
    where = None if static_path is None else Path(static_path).resolve()
    if where is not None and where.is_dir():
        where = where / "result.json"
    return ResultComparison("" if where is None else str(where),
                            str(static.campaign.path), rows)


def load_static_result(path: str | Path, *, what: str = "--beside") -> IdentificationResult:
    """A saved static identification (``servoscope identify``'s result.json or its folder), checked.

    Raises
    ------
    ServoscopeError
        One line naming ``what`` and the file: missing, unreadable, not a result, its tracks/ missing,
        or a turning rotor's result.
    """
    path = Path(path)
    try:
        result = IdentificationResult.load(path)
    except ServoscopeError as exc:
        text = str(exc)  # names the file already, and what to give where it can
        advice = ("" if "give" in text or "tracks/" in text
                  else "; give the result.json that `servoscope identify` wrote")
        raise ServoscopeError(f"{what}: {text}{advice}") from None
    except OSError as exc:
        raise ServoscopeError(f"{what} {path}: cannot be read ({exc.strerror or exc}); give the result.json that "
                              "`servoscope identify` wrote for the static campaign") from None
    except (KeyError, TypeError, ValueError) as exc:
        raise ServoscopeError(f"{what} {path}: not a servoscope result.json ({type(exc).__name__}: {exc}); give "
                              "the result.json that `servoscope identify` wrote for the static campaign") from None
    if result.rotor is not None:
        raise ServoscopeError(f"{what} {path}: a turning rotor's result (it has a rotor section); give the "
                              "result.json of a static campaign (one without [rotor])")
    return result


def with_static_comparison(rotating: IdentificationResult, static: IdentificationResult, *,
                           static_path: str | Path | None = None) -> IdentificationResult:
    """The rotor's result with the comparison recorded in its ``rotor["beside_static"]`` (result.json, the report).

    Raises
    ------
    ServoscopeError
        When ``rotating`` is not a turning rotor's result, or ``static`` is one.
    """
    if rotating.rotor is None:
        raise ServoscopeError(f"{rotating.campaign.path}: not a turning rotor's result; the comparison with a "
                              "static campaign is a rotor campaign's (campaign.toml's [rotor])")
    comparison = compare_results(static, rotating, static_path=static_path)
    return replace(rotating, rotor={**rotating.rotor, "beside_static": comparison.summary()})
