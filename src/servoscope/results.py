"""What every result object shares: JSON-ready values, read-only arrays, pandas, an HTML table.

A stage's result (a :class:`~servoscope.sysid.SineFit`, a
:class:`~servoscope.sysid.TransferFunctionFit`, a campaign's identification result, …) keeps
its numbers as NumPy values and read-only arrays, and offers ``summary()`` (plain JSON types),
``to_pandas()`` (pandas is optional) and ``_repr_html_()`` (a table in a notebook). The pieces
those methods have in common live here, once, so that every result writes NaN, NumPy scalars
and paths the same way.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["jsonable", "readonly", "import_pandas", "html_table", "html_rows", "fields_from_summary"]


def jsonable(value: Any) -> Any:
    """Plain JSON types, recursively: the form ``summary()`` returns and result.json holds.

    Parameters
    ----------
    value : Any
        A scalar, array, mapping or sequence (nested freely).

    Returns
    -------
    Any
        Dicts (keys as ``str``), lists, ``bool``, ``int``, ``float``, ``str`` or None:
        NumPy scalars and arrays converted, tuples as lists, NaN and infinities as None
        (JSON has neither), paths as strings. Anything else is returned unchanged.
    """
    if value is None:
        return None
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return [jsonable(v) for v in value.tolist()]
    # bool before int: bool is an int subclass and must stay a bool.
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        v = float(value)
        return v if math.isfinite(v) else None
    if isinstance(value, Path):
        return str(value)
    return value


def fields_from_summary(cls: type, data: Mapping[str, Any], /, **given: Any) -> dict[str, Any]:
    """The keyword arguments that rebuild a result dataclass from its ``summary()``, as far as it holds them.

    The inverse of :func:`jsonable` on the dataclass's own fields: a field named in
    `data` is taken from it, a list becomes a tuple where the field is a tuple (nested
    lists too) and a read-only array where it is an array, and None becomes NaN where the
    field is a plain ``float`` (``summary()`` writes NaN as None). Fields `data` lacks are
    left to their defaults or to `given`, which also wins over `data`.

    Parameters
    ----------
    cls : dataclass type
    data : mapping
        One object's part of a ``summary()`` (or of result.json).
    **given
        Fields the summary does not hold (arrays of samples, the data a fit was made from).

    Returns
    -------
    dict
        Keyword arguments for ``cls(**kwargs)``; private fields (``_name``) only from `given`.
    """
    import dataclasses

    out: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        if f.name in given:
            out[f.name] = given[f.name]
            continue
        if f.name.startswith("_") or f.name not in data:
            continue
        value, kind = data[f.name], str(f.type)
        if value is None:
            out[f.name] = math.nan if kind in ("float", "np.float64") else None
        elif "NDArray" in kind:
            out[f.name] = readonly([math.nan if v is None else v for v in value])
        elif kind.startswith("tuple") and isinstance(value, list):
            out[f.name] = tuple(tuple(v) if isinstance(v, list) else v for v in value)
        else:
            out[f.name] = value
    return out


def readonly(a: ArrayLike) -> NDArray[np.float64]:
    """A float64 copy of `a` that cannot be written to.

    Result objects are frozen dataclasses; their arrays are read-only too, so a user who
    keeps a result cannot change the numbers its ``summary()`` and plots were made from.
    """
    arr = np.array(a, dtype=float)
    arr.setflags(write=False)
    return arr


def import_pandas() -> Any:
    """The pandas module, imported on first use (``to_pandas()`` only).

    Raises
    ------
    ImportError
        pandas is not installed (it is not a servoscope dependency); the message says how
        to install it.
    """
    try:
        import pandas as pd
    except ImportError as exc:  # pragma: no cover - depends on environment
        raise ImportError(
            "to_pandas() needs pandas, which is not a servoscope dependency; "
            "install it with `pip install pandas`"
        ) from exc
    return pd


def html_table(summary: Mapping[str, Any], caption: str) -> str:
    """A two-column HTML table (key, value) of a summary dict, for ``_repr_html_``.

    Parameters
    ----------
    summary : mapping
        Usually ``result.summary()``; values are written with ``str()``.
    caption : str
        The table's caption (the result's class name, say).

    Returns
    -------
    str
        ``<table><caption>…</caption><tr><td>key</td><td>value</td></tr>…</table>``.
        Keys, values and caption are written as they are (they are the package's own
        numbers and names, not user markup).
    """
    rows = "".join(f"<tr><td>{k}</td><td>{v}</td></tr>" for k, v in summary.items())
    return f"<table><caption>{caption}</caption>{rows}</table>"


def html_rows(columns: Iterable[str], rows: Iterable[Iterable[Any]], caption: str | None = None) -> str:
    """An HTML table with a header row and one row per item of `rows`, for ``_repr_html_``.

    Parameters
    ----------
    columns : iterable of str
        Header cells.
    rows : iterable of iterables
        Cells, already formatted as the result wants them shown (written with ``str()``).
    caption : str, optional
        The table's caption.

    Returns
    -------
    str
        ``<table>[<caption>…</caption>]<tr><th>…</th></tr><tr><td>…</td></tr>…</table>``.
    """
    cap = "" if caption is None else f"<caption>{caption}</caption>"
    head = "".join(f"<th>{c}</th>" for c in columns)
    body = "".join("<tr>" + "".join(f"<td>{v}</td>" for v in row) + "</tr>" for row in rows)
    return f"<table>{cap}<tr>{head}</tr>{body}</table>"
