"""Numbers for people: a value shown to the precision its uncertainty supports.

The convention of metrology (GUM §7.2.6, and what lmfit and ``uncertainties``
print): the uncertainty with two significant digits, the value rounded to the
same decimal place. ``0.229664 ± 0.000317651`` reads ``0.22966 ± 0.00032``.
"""

from __future__ import annotations

import math

__all__ = ["decimals_for", "format_value", "format_with_uncertainty", "format_interval"]


def _finite(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def decimals_for(uncertainty: float, digits: int = 2) -> int | None:
    """Decimal places that show ``uncertainty`` with ``digits`` significant digits (None: not usable)."""
    if not _finite(uncertainty) or uncertainty <= 0:
        return None
    return max(0, digits - 1 - math.floor(math.log10(uncertainty)))


def format_value(value, significant: int = 6) -> str:
    """A value without an uncertainty: ``significant`` digits, "—" for None or NaN."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "—"
    if isinstance(value, float):
        return f"{value:.{significant}g}"
    return str(value)


def format_with_uncertainty(value, uncertainty) -> tuple[str, str]:
    """``(value, uncertainty)`` as strings, the value rounded where the uncertainty's 2nd digit is.

    Falls back to :func:`format_value` for each when the uncertainty is
    missing, zero or not finite, or the value is not finite. Values beyond
    1e6 or uncertainties below 1e-9 keep the general format (no run of zeros).
    """
    d = decimals_for(uncertainty)
    if d is None or not _finite(value) or abs(value) >= 1e6 or uncertainty < 1e-9:
        return format_value(value), format_value(uncertainty, 2)
    return f"{value:.{d}f}", f"{uncertainty:.{d}f}"


def format_interval(low, high, uncertainty=None) -> str:
    """``[low, high]`` at the decimals of ``uncertainty`` (else 5 significant digits)."""
    if not (_finite(low) and _finite(high)):
        return "—"
    d = decimals_for(uncertainty) if uncertainty is not None else None
    if d is None or max(abs(low), abs(high)) >= 1e6 or uncertainty < 1e-9:
        return f"[{low:.5g}, {high:.5g}]"
    return f"[{low:.{d}f}, {high:.{d}f}]"
