"""Stable-by-construction rational transfer functions with dead time.

Internal module of :mod:`servoscope.sysid.tf_fit`. A model of order
``(nb, na)`` is::

    G(s) = K * N(s) / D(s) * exp(-s*tau),      N(0) = D(0) = 1

* ``D(s)`` is a product of ``na // 2`` quadratic factors
  ``s**2/wn**2 + 2*zeta*s/wn + 1`` (``wn > 0``, ``zeta > 0``: a complex pair
  for ``zeta < 1``, two real poles for ``zeta >= 1``) and, for odd ``na``,
  one real factor ``s/p + 1`` (``p > 0``). Every stable denominator of
  degree <= 4 with ``D(0) = 1`` has exactly this form, and no parameter
  value gives an unstable one.
* ``N(s)`` is either built the same way from zero factors
  (``zeros="minimum_phase"``: all zeros in the open left half plane) or is
  ``1 + c1*s + ... + c_nb*s**nb`` with free real ``c_i``
  (``zeros="free"``: right-half-plane zeros allowed; only identifiable when
  phases are fitted).

Parameter vector ``theta`` (internal units)::

    [ln K, zero part, pole part, (sqrt tau)]

with frequencies and damping ratios as natural logs (positivity, hence
stability, by construction for any real theta, so the fast unconstrained
Levenberg-Marquardt solver can be used), free numerator coefficients scaled
as ``d_i = c_i * w_ref**i`` (dimensionless, for conditioning) and the dead
time as ``tau = u**2`` (``tau >= 0``; u in sqrt(s)).

``log_response`` returns ``ln G(jw)`` whose real part is ``ln|G|`` and whose
imaginary part is the phase in rad; its Jacobian is analytic.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__: list[str] = []

#: Damping ratios outside this range mean the data do not determine the factor.
ZETA_RANGE = (1e-4, 20.0)
#: A pole or zero this far outside the measured band is not determined by it
#: (at 100x the top frequency a pole changes the phase there by < 0.6 deg).
FREQ_MARGIN = 1e2


def delay_limit_s(w_min: float) -> float:
    """The longest dead time a fit considers (s): one period of the lowest dwell, at least 1 s.

    The dwells' phases tell the delay modulo a whole turn at each frequency; beyond one
    period of the lowest there are aliases (the phases of 1.5, 4 and 10 Hz repeat every
    2 s) that fit as well, and the solver was seen to end on one (31.4 s for 85 ms on a
    three-dwell campaign). The delay's seeds span this range, and a local fit that ends
    beyond it is not taken (a hard limit instead would stall the solver's path there).
    """
    return max(1.0, 2.0 * math.pi / w_min)


_QUAD_NAMES_SINGLE = ("natural_frequency_rad_s", "damping_ratio")


@dataclass(frozen=True)
class Structure:
    """Layout of the parameter vector for an order ``(nb, na)`` model."""

    nb: int
    na: int
    zeros: str  # "minimum_phase" or "free"
    delay: bool
    w_ref: float  # rad/s, scale of the free numerator coefficients
    # Parameters the user held: (index, low, high) in theta's units; low == high fixes it.
    held: tuple[tuple[int, float, float], ...] = ()

    # ------------------------------------------------------------ layout
    @property
    def n_zero_real(self) -> int:
        return self.nb % 2 if self.zeros == "minimum_phase" else 0

    @property
    def n_zero_quad(self) -> int:
        return self.nb // 2 if self.zeros == "minimum_phase" else 0

    @property
    def n_zero_coef(self) -> int:
        return self.nb if self.zeros == "free" else 0

    @property
    def n_pole_real(self) -> int:
        return self.na % 2

    @property
    def n_pole_quad(self) -> int:
        return self.na // 2

    @property
    def n_params(self) -> int:
        return 1 + self.nb + self.na + int(self.delay)

    def offsets(self) -> dict[str, int]:
        """Start index of each block in theta."""
        i = 1
        out = {}
        out["zr"] = i
        i += self.n_zero_real
        out["zq"] = i
        i += 2 * self.n_zero_quad
        out["zc"] = i
        i += self.n_zero_coef
        out["pr"] = i
        i += self.n_pole_real
        out["pq"] = i
        i += 2 * self.n_pole_quad
        out["tau"] = i
        return out

    def names(self) -> tuple[str, ...]:
        """Physical parameter names, in theta order."""
        names = ["gain"]
        for _ in range(self.n_zero_real):
            names.append("zero_rad_s")
        for _ in range(self.n_zero_quad):
            names += ["zero_natural_frequency_rad_s", "zero_damping_ratio"]
        for i in range(self.n_zero_coef):
            names.append(f"num_c{i + 1}")
        for _ in range(self.n_pole_real):
            names.append("pole_rad_s")
        if self.n_pole_quad == 1:
            names += list(_QUAD_NAMES_SINGLE)
        else:
            for j in range(self.n_pole_quad):
                names += [f"natural_frequency{j + 1}_rad_s", f"damping_ratio{j + 1}"]
        if self.delay:
            names.append("dead_time_s")
        return tuple(names)

    def kinds(self) -> tuple[str, ...]:
        """Kind of each theta entry: 'gain', 'freq', 'zeta' (all logs), 'coef', 'tau' (sqrt)."""
        k = ["gain"]
        k += ["freq"] * self.n_zero_real
        k += ["freq", "zeta"] * self.n_zero_quad
        k += ["coef"] * self.n_zero_coef
        k += ["freq"] * self.n_pole_real
        k += ["freq", "zeta"] * self.n_pole_quad
        if self.delay:
            k.append("tau")
        return tuple(k)

    # ---------------------------------------------------------- physical
    def clamp_limits(self, w_min: float, w_max: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Hard limits on theta (far beyond anything the data can determine).

        The solver is unconstrained; a parameter the data do not determine
        can drift without end (a pole running off to infinity). Evaluating
        the model at the clipped theta, with a zero derivative beyond the
        limit, stops the drift there and keeps every number finite.
        """
        lo, hi = [], []
        for kind in self.kinds():
            if kind == "gain":
                lo.append(-60.0)
                hi.append(60.0)
            elif kind == "freq":
                lo.append(math.log(w_min / 1e4))
                hi.append(math.log(w_max * 1e4))
            elif kind == "zeta":
                lo.append(math.log(1e-6))
                hi.append(math.log(1e3))
            elif kind == "coef":
                lo.append(-1e8)
                hi.append(1e8)
            else:
                lo.append(-np.inf)
                hi.append(np.inf)
        lo_a, hi_a = np.array(lo), np.array(hi)
        for i, low, high in self.held:
            lo_a[i], hi_a[i] = low, high
        return lo_a, hi_a

    @property
    def fixed(self) -> NDArray[np.bool_]:
        """Which parameters are held at one value (their limits meet)."""
        out = np.zeros(self.n_params, dtype=bool)
        for i, low, high in self.held:
            out[i] = low == high
        return out

    def with_held(self, fixed: dict[str, float], bounds: dict[str, tuple[float, float]]) -> "Structure":
        """This layout with parameters held at a value (``fixed``) or within limits (``bounds``), physical units.

        Raises
        ------
        ValueError
            A name this model does not have, a parameter both fixed and bounded, a value its
            kind cannot take (a frequency, gain or damping ratio ≤ 0, a negative dead time),
            or limits in the wrong order; the message says which.
        """
        names = self.names()
        held = []
        for name in set(fixed) | set(bounds):
            if name not in names:
                raise ValueError(f"{name!r} is not a parameter of this model ({', '.join(names)})")
            if name in fixed and name in bounds:
                raise ValueError(f"{name!r} is both fixed and bounded: give one")
        for name in names:
            if name not in fixed and name not in bounds:
                continue
            i = names.index(name)
            low, high = (fixed[name], fixed[name]) if name in fixed else bounds[name]
            kind = self.kinds()[i]
            if not (math.isfinite(low) and math.isfinite(high) and low <= high):
                raise ValueError(f"{name!r}: limits {low}:{high} must be finite and in order")
            if (kind in ("gain", "freq", "zeta") and low <= 0) or (kind == "tau" and low < 0):
                raise ValueError(f"{name!r} must be {'> 0' if kind != 'tau' else '>= 0'}, got {low}")
            values = np.zeros(self.n_params)
            ends = []
            for v in (low, high):
                values[i] = v
                ends.append(float(self.theta_from_physical_one(i, v)))
            held.append((i, ends[0], ends[1]))
        return Structure(self.nb, self.na, self.zeros, self.delay, self.w_ref, tuple(held))

    def theta_from_physical_one(self, i: int, value: float) -> float:
        """Theta's entry ``i`` for a physical value (see :meth:`theta_from_physical`)."""
        kind = self.kinds()[i]
        if kind in ("gain", "freq", "zeta"):
            return math.log(value)
        if kind == "coef":
            return value / self.w_ref ** -(i - self.offsets()["zc"] + 1)
        return math.sqrt(max(value, 0.0))

    def physical(self, theta: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Physical values and d(physical)/d(theta) (diagonal) for a theta."""
        vals = np.empty(theta.size)
        der = np.empty(theta.size)
        zc = self.offsets()["zc"]
        for i, kind in enumerate(self.kinds()):
            if kind in ("gain", "freq", "zeta"):
                vals[i] = der[i] = math.exp(theta[i])
            elif kind == "coef":
                scale = self.w_ref ** -(i - zc + 1)
                vals[i] = theta[i] * scale
                der[i] = scale
            else:  # tau = u**2
                vals[i] = theta[i] ** 2
                der[i] = 2.0 * theta[i]
        return vals, der

    def theta_from_physical(self, values: NDArray[np.float64]) -> NDArray[np.float64]:
        """The theta whose :meth:`physical` values are `values` (names' order): a saved fit's parameters back."""
        return np.array([self.theta_from_physical_one(i, float(v)) for i, v in enumerate(values)])

    def canonical(self, theta: NDArray[np.float64]) -> NDArray[np.float64]:
        """Sort quadratic pole factors by natural frequency (names are then unique); u >= 0."""
        th = np.array(theta, dtype=float)
        if self.delay:
            th[-1] = abs(th[-1])
        if self.n_pole_quad > 1:
            o = self.offsets()["pq"]
            pairs = th[o : o + 2 * self.n_pole_quad].reshape(-1, 2)
            pairs = pairs[np.argsort(pairs[:, 0], kind="stable")]
            th[o : o + 2 * self.n_pole_quad] = pairs.ravel()
        return th

    # -------------------------------------------------------- polynomials
    def num_den(self, theta: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Numerator and denominator coefficients, descending powers of s, D(0) = 1."""
        off = self.offsets()
        k = math.exp(theta[0])
        num = _factored_poly(theta, off["zr"], self.n_zero_real, off["zq"], self.n_zero_quad)
        if self.n_zero_coef:
            c = [theta[off["zc"] + i] * self.w_ref ** -(i + 1) for i in range(self.n_zero_coef)]
            num = np.array(c[::-1] + [1.0])
        den = _factored_poly(theta, off["pr"], self.n_pole_real, off["pq"], self.n_pole_quad)
        return k * num, den


def _quad(lnw: NDArray[np.float64], lnzeta: NDArray[np.float64], w: NDArray[np.float64]) -> tuple[NDArray[np.complex128], NDArray[np.float64]]:
    """Factor ``1 - x**2 + 2j*zeta*x`` (x = w/wn) and x, broadcast over seeds."""
    x = w[None, :] * np.exp(-lnw)[:, None]
    return 1.0 - x**2 + 2j * np.exp(lnzeta)[:, None] * x, x


def log_response(st: Structure, theta: NDArray[np.float64], w: NDArray[np.float64], *, with_delay: bool = True) -> NDArray[np.complex128]:
    """``ln G(jw)`` for one theta (shape (P,)) or many (shape (S, P)).

    Returns shape (n,) or (S, n). The imaginary part is the phase in rad,
    continuous in w for minimum-phase numerators (each factor's principal
    log has a positive imaginary part for w > 0).
    """
    th = np.atleast_2d(np.asarray(theta, dtype=float))
    off = st.offsets()
    out = np.repeat(th[:, :1], w.size, axis=1).astype(complex)
    jw = 1j * w[None, :]
    for i in range(st.n_zero_real):
        out += np.log(1.0 + jw * np.exp(-th[:, off["zr"] + i])[:, None])
    for i in range(st.n_zero_quad):
        f, _ = _quad(th[:, off["zq"] + 2 * i], th[:, off["zq"] + 2 * i + 1], w)
        out += np.log(f)
    if st.n_zero_coef:
        poly = np.ones_like(out)
        for i in range(st.n_zero_coef):
            poly += th[:, off["zc"] + i][:, None] * (jw / st.w_ref) ** (i + 1)
        out += np.log(poly)
    for i in range(st.n_pole_real):
        out -= np.log(1.0 + jw * np.exp(-th[:, off["pr"] + i])[:, None])
    for i in range(st.n_pole_quad):
        f, _ = _quad(th[:, off["pq"] + 2 * i], th[:, off["pq"] + 2 * i + 1], w)
        out -= np.log(f)
    if st.delay and with_delay:
        out -= jw * (th[:, off["tau"]] ** 2)[:, None]
    return out[0] if np.ndim(theta) == 1 else out


def log_response_jac(st: Structure, theta: NDArray[np.float64], w: NDArray[np.float64]) -> NDArray[np.complex128]:
    """``d ln G(jw) / d theta``, shape (n, P), analytic."""
    th = np.asarray(theta, dtype=float)
    off = st.offsets()
    J = np.zeros((w.size, th.size), dtype=complex)
    jw = 1j * w
    J[:, 0] = 1.0

    def real_factor(idx: int, sign: float) -> None:
        # d/dq ln(1 + jw e^-q) = -jw e^-q / (1 + jw e^-q)
        a = jw * math.exp(-th[idx])
        J[:, idx] = sign * (-a / (1.0 + a))

    def quad_factor(idx: int, sign: float) -> None:
        x = w * math.exp(-th[idx])
        ze = math.exp(th[idx + 1])
        f = 1.0 - x**2 + 2j * ze * x
        # dx/dlnwn = -x; df/dx = -2x + 2j zeta; dzeta/dlnzeta = zeta
        J[:, idx] = sign * (2.0 * x**2 - 2j * ze * x) / f
        J[:, idx + 1] = sign * (2j * x * ze) / f

    for i in range(st.n_zero_real):
        real_factor(off["zr"] + i, 1.0)
    for i in range(st.n_zero_quad):
        quad_factor(off["zq"] + 2 * i, 1.0)
    if st.n_zero_coef:
        powers = [(jw / st.w_ref) ** (i + 1) for i in range(st.n_zero_coef)]
        poly = 1.0 + sum(th[off["zc"] + i] * powers[i] for i in range(st.n_zero_coef))
        for i in range(st.n_zero_coef):
            J[:, off["zc"] + i] = powers[i] / poly
    for i in range(st.n_pole_real):
        real_factor(off["pr"] + i, -1.0)
    for i in range(st.n_pole_quad):
        quad_factor(off["pq"] + 2 * i, -1.0)
    if st.delay:
        J[:, off["tau"]] = -jw * 2.0 * th[off["tau"]]
    return J


def continuous_phase_rad(st: Structure, theta: NDArray[np.float64], w: NDArray[np.float64]) -> NDArray[np.float64]:
    """Phase of ``G(jw)`` (incl. delay) that is continuous in w > 0, rad.

    For free numerators the numerator's phase is summed over its roots
    ``z_k`` as ``arg(1 - jw/z_k)``, each of which stays in one half plane
    for w > 0, so the sum is continuous (the principal log of the whole
    polynomial is not).
    """
    lg = log_response(st, theta, w)
    if not st.n_zero_coef:
        return np.asarray(lg.imag, dtype=float)
    off = st.offsets()
    base = np.asarray(lg.imag, dtype=float)
    c = [theta[off["zc"] + i] * st.w_ref ** -(i + 1) for i in range(st.n_zero_coef)]
    poly = np.array(c[::-1] + [1.0])
    jw = 1j * w
    principal = np.angle(np.polyval(poly, jw))
    roots = np.roots(np.trim_zeros(poly, "f")) if np.any(poly[:-1] != 0) else np.array([])
    cont = np.zeros_like(w)
    for z in roots:
        cont += np.angle(1.0 - jw / z)
    return base - principal + cont


def _factored_poly(theta: NDArray[np.float64], real_at: int, n_real: int, quad_at: int, n_quad: int) -> NDArray[np.float64]:
    """∏(s/r + 1) · ∏(s²/ωn² + 2ζs/ωn + 1), descending powers, constant term 1.

    Roots r and (ωn, ζ) pairs are stored as logs in ``theta`` from ``real_at``
    and ``quad_at`` on: numerator and denominator share this form.
    """
    poly = np.array([1.0])
    for i in range(n_real):
        poly = np.polymul(poly, [1.0 / math.exp(theta[real_at + i]), 1.0])
    for i in range(n_quad):
        wn, ze = math.exp(theta[quad_at + 2 * i]), math.exp(theta[quad_at + 2 * i + 1])
        poly = np.polymul(poly, [1.0 / wn**2, 2.0 * ze / wn, 1.0])
    return poly


def param_words(name: str) -> str:
    """A parameter's name as words for a message ("natural_frequency_rad_s" -> "natural frequency")."""
    return name.replace("_rad_s", "").replace("_s", "").replace("_", " ")
