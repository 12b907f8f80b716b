"""The result of a dwell fitted to a rotor's passes: :class:`PassSineFit`, its blades' offsets and differences.

Made by :func:`~servoscope.sysid.pass_sine.fit_pass_sine` (its module says how).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from servoscope.results import jsonable, readonly
from servoscope.sysid.sine_result import SineFit

__all__ = ["BladeDifference", "BladeOffset", "PassSineFit", "readonly_int"]


@dataclass(frozen=True)
class BladeOffset:
    """One blade's constant pitch in a dwell (its sine is the common one).

    Attributes
    ----------
    blade : int
        The blade's number (0 first, as campaign.toml's ``[rotor] blades``).
    offset_rad, offset_stderr_rad : float
        Its constant pitch and standard error, rad.
    ci95_rad : (float, float)
        95 % interval of `offset_rad` (normal), rad.
    n_passes : int
        Its passes in the window.
    """

    blade: int
    offset_rad: float
    offset_stderr_rad: float
    ci95_rad: tuple[float, float]
    n_passes: int

    def summary(self) -> dict[str, Any]:
        """Plain values (NaN -> None)."""
        return jsonable({"blade": self.blade, "offset_rad": self.offset_rad,
                         "offset_stderr_rad": self.offset_stderr_rad, "ci95_rad": list(self.ci95_rad),
                         "n_passes": self.n_passes})


@dataclass(frozen=True)
class BladeDifference:
    """One blade's pitch minus the reference blade's: a rigging error.

    Attributes
    ----------
    blade, reference_blade : int
        The two blades' numbers (the reference is the first blade seen, blade 0 normally).
    difference_rad, difference_stderr_rad : float
        ``offset[blade] − offset[reference_blade]`` and its standard error, rad.
    ci95_rad : (float, float)
        Its 95 % interval (normal), rad.
    """

    blade: int
    reference_blade: int
    difference_rad: float
    difference_stderr_rad: float
    ci95_rad: tuple[float, float]

    def summary(self) -> dict[str, Any]:
        """Plain values (NaN -> None)."""
        return jsonable({"blade": self.blade, "reference_blade": self.reference_blade,
                         "difference_rad": self.difference_rad, "difference_stderr_rad": self.difference_stderr_rad,
                         "ci95_rad": list(self.ci95_rad)})


def _empty() -> NDArray[np.float64]:
    return readonly(np.zeros(0))


def readonly_int(a: ArrayLike) -> NDArray[np.int_]:
    """An int copy of `a` that cannot be written to (the blades' numbers)."""
    arr = np.array(a, dtype=int)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True)
class PassSineFit(SineFit):
    """A dwell fitted to a rotor's passes (:func:`fit_pass_sine`): a :class:`SineFit` and the blades.

    The :class:`SineFit` fields mean what they mean for a static dwell, with samples the
    passes: ``offset`` is the blades' mean constant, ``y`` the window's pitches with each
    blade's offset moved onto that mean (so that ``y − model(time_s)`` is the residual),
    ``covariance`` that of ``(offset, a, b)`` at ``tc``, ``frequency_stderr_hz`` None (the
    frequency is the commanded one).

    Attributes
    ----------
    blade_offsets : tuple of BladeOffset
        Each blade's constant, in blade order.
    blade_differences : tuple of BladeDifference
        Each other blade's constant minus the first blade's.
    rev_per_s : float
        Rotor speed used for the checks (given, or from the passes), rev/s.
    n_blades : int
        Blades on the rotor (N).
    pass_rate_hz, pass_nyquist_hz : float
        N·Ω and N·Ω/2, Hz.
    chi2_reduced : float
        Residual scatter over the stated errors (χ² per degree of freedom; NaN without stated
        errors): about 1 when the tracker's errors are honest.
    covariance_kind : str
        ``"stated errors"`` (scaled by the reduced χ² where it exceeds 1) or ``"HAC"``
        (correlated residuals, or no stated errors): module docstring, "Standard errors".
    blade : numpy.ndarray of int
        The window's passes' blades (same order as ``time_s``).
    pitch_rad, pitch_stderr_rad : numpy.ndarray
        The window's passes' pitches as measured and their stated errors, rad.
    """

    blade_offsets: tuple[BladeOffset, ...] = ()
    blade_differences: tuple[BladeDifference, ...] = ()
    rev_per_s: float = float("nan")
    n_blades: int = 0
    pass_rate_hz: float = float("nan")
    pass_nyquist_hz: float = float("nan")
    chi2_reduced: float = float("nan")
    covariance_kind: str = "HAC"
    blade: NDArray[np.int_] = field(default_factory=lambda: readonly_int([]), repr=False, compare=False)
    pitch_rad: NDArray[np.float64] = field(default_factory=_empty, repr=False, compare=False)
    pitch_stderr_rad: NDArray[np.float64] = field(default_factory=_empty, repr=False, compare=False)

    def summary(self) -> dict[str, Any]:
        """The :class:`SineFit` summary, plus ``rotor``: speed, pass rate, blades' offsets and differences."""
        out = super().summary()
        out["rotor"] = jsonable({
            "rev_per_s": self.rev_per_s, "n_blades": self.n_blades, "pass_rate_hz": self.pass_rate_hz,
            "pass_nyquist_hz": self.pass_nyquist_hz, "chi2_reduced": self.chi2_reduced,
            "covariance_kind": self.covariance_kind,
            "blade_offsets": [b.summary() for b in self.blade_offsets],
            "blade_differences": [d.summary() for d in self.blade_differences]})
        return out

    @classmethod
    def from_summary(cls, data: dict[str, Any], *, time_s: ArrayLike = (), y: ArrayLike = ()) -> "PassSineFit":
        """Rebuild a pass fit from its :meth:`summary` (a dwell of a saved result.json).

        The :class:`SineFit` part as :meth:`SineFit.from_summary` rebuilds it, and the rotor's
        part from ``data["rotor"]``; its :meth:`summary` equals `data`. The passes' blades and
        raw pitches are not in the summary (empty arrays).
        """
        fit = super().from_summary(data, time_s=time_s, y=y)
        rotor = data.get("rotor") or {}

        def num(v: Any) -> float:
            return float("nan") if v is None else float(v)

        extra = {
            "rev_per_s": num(rotor.get("rev_per_s")), "n_blades": int(rotor.get("n_blades") or 0),
            "pass_rate_hz": num(rotor.get("pass_rate_hz")), "pass_nyquist_hz": num(rotor.get("pass_nyquist_hz")),
            "chi2_reduced": num(rotor.get("chi2_reduced")), "covariance_kind": rotor.get("covariance_kind", "HAC"),
            "blade_offsets": tuple(
                BladeOffset(int(o["blade"]), num(o["offset_rad"]), num(o["offset_stderr_rad"]),
                            (num(o["ci95_rad"][0]), num(o["ci95_rad"][1])), int(o["n_passes"]))
                for o in rotor.get("blade_offsets", ())),
            "blade_differences": tuple(
                BladeDifference(int(d["blade"]), int(d["reference_blade"]), num(d["difference_rad"]),
                                num(d["difference_stderr_rad"]), (num(d["ci95_rad"][0]), num(d["ci95_rad"][1])))
                for d in rotor.get("blade_differences", ())),
        }
        for name, value in extra.items():  # the rebuilt object is new: set once, as __init__ would
            object.__setattr__(fit, name, value)
        return fit
