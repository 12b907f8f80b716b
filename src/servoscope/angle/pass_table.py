"""The pass table: every pass of every blade through one video of a turning rotor (:class:`PassTable`).

Made by :func:`servoscope.pipeline.rotor.track_passes` from the estimator of
:mod:`servoscope.angle.passes` (which re-exports it, the contract's home).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..results import fields_from_summary, html_rows, import_pandas, jsonable, readonly

__all__ = ["ORTHOGRAPHIC_K", "PassTable"]

#: The orthographic limit's foreshortening constant (tan φ = tan θ / cos ψ), the table's default.
ORTHOGRAPHIC_K = 0.5


@dataclass(frozen=True)
class PassTable:
    """Every pass of every blade through one video: the pitch at ψ = 0, its error, the rotor speed.

    Attributes
    ----------
    video : str
    time_s : ndarray
        Each pass's time at ψ = 0 (s, the video's clock).
    blade : ndarray of int
        Which blade (its index in ``[rotor] blades``, told by its stickers' colours).
    pitch_rad, pitch_stderr_rad : ndarray
        The pitch at ψ = 0 and its standard error (rad).
    azimuth_from_rad, azimuth_to_rad : ndarray
        ψ at the first and last frame used for the pitch.
    frames : ndarray of int
        Frames in which the blade's stickers were seen (whole or cut).
    rev_per_s, rev_per_s_stderr : float
        The rotor's mean speed over the passes (measured; the given one, stderr NaN, when
        no blade passed twice).
    t0_s, t0_uncertainty_s : float or None
        The LED's switch (the input's start), as ``servoscope track`` dates it.
    foreshortening_k, foreshortening_k_stderr : float
        The fitted curvature of F(ψ) (½ orthographic; NaN error when held or not told).
    centre_column_px : tuple of float
        Each blade's column of ψ = 0 in the picture.
    first_frame, last_frame : ndarray of int
        Each pass's first and last frame with the blade's stickers in the picture.
    pitch_rate_rad_s : ndarray
        The pitch's own change through each pass (0 where held: a short pass).
    n_whole : ndarray of int
        Frames with both stickers whole read for the pitch (outliers out). Fewer than
        :data:`servoscope.angle.passes.MIN_PASS_FRAMES` (4): a *short* pass, its crossing
        time from the blade's path and its own rate held at 0 (its error says so); -1 in
        a table written before the column.
    warnings : tuple of str
    """

    video: str
    time_s: NDArray[np.float64]
    blade: NDArray[np.float64]
    pitch_rad: NDArray[np.float64]
    pitch_stderr_rad: NDArray[np.float64]
    azimuth_from_rad: NDArray[np.float64]
    azimuth_to_rad: NDArray[np.float64]
    frames: NDArray[np.float64]
    rev_per_s: float
    rev_per_s_stderr: float
    t0_s: float | None = None
    t0_uncertainty_s: float | None = None
    foreshortening_k: float = ORTHOGRAPHIC_K
    foreshortening_k_stderr: float = math.nan
    centre_column_px: tuple[float, ...] = ()
    first_frame: NDArray[np.float64] = field(default_factory=lambda: readonly([]))
    last_frame: NDArray[np.float64] = field(default_factory=lambda: readonly([]))
    pitch_rate_rad_s: NDArray[np.float64] = field(default_factory=lambda: readonly([]))
    n_whole: NDArray[np.float64] = field(default_factory=lambda: readonly([]))
    warnings: tuple[str, ...] = ()

    #: The per-pass columns, in the order of :meth:`to_pandas` and the summary's ``passes``.
    COLUMNS = ("time_s", "blade", "pitch_rad", "pitch_stderr_rad", "azimuth_from_rad", "azimuth_to_rad", "frames",
               "first_frame", "last_frame", "pitch_rate_rad_s", "n_whole")
    INT_COLUMNS = ("blade", "frames", "first_frame", "last_frame", "n_whole")

    def __post_init__(self) -> None:
        n = np.size(self.time_s)
        for name in self.COLUMNS:
            a = getattr(self, name)
            if np.size(a) == 0 and n:
                a = np.full(n, np.nan)
            if name in self.INT_COLUMNS:
                arr = np.array(np.nan_to_num(np.asarray(a, dtype=float), nan=-1), dtype=np.int64)
                arr.setflags(write=False)
            else:
                arr = readonly(a)
            if arr.shape != (n,):
                raise ValueError(f"PassTable.{name}: {arr.shape[0]} values for {n} passes")
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "warnings", tuple(self.warnings))
        object.__setattr__(self, "centre_column_px", tuple(float(c) for c in self.centre_column_px))

    def __len__(self) -> int:
        return int(np.size(self.time_s))

    @property
    def blades(self) -> tuple[int, ...]:
        """The blades seen, in order."""
        return tuple(int(b) for b in np.unique(self.blade))

    def columns(self) -> dict[str, NDArray]:
        """The per-pass arrays by name (:attr:`COLUMNS`)."""
        return {name: getattr(self, name) for name in self.COLUMNS}

    def to_pandas(self):
        """One row a pass (:attr:`COLUMNS`) as a pandas DataFrame (pandas is optional)."""
        pd = import_pandas()
        return pd.DataFrame(self.columns())

    def summary(self) -> dict:
        """Plain types (what result.json holds): the scalars, and ``passes`` as a dict of lists (:attr:`COLUMNS`)."""
        return jsonable({
            "video": self.video,
            "passes": len(self),
            "rev_per_s": self.rev_per_s,
            "rev_per_s_stderr": self.rev_per_s_stderr,
            "t0_s": self.t0_s,
            "t0_uncertainty_s": self.t0_uncertainty_s,
            "foreshortening_k": self.foreshortening_k,
            "foreshortening_k_stderr": self.foreshortening_k_stderr,
            "centre_column_px": list(self.centre_column_px),
            "warnings": list(self.warnings),
            "table": self.columns(),
        })

    @classmethod
    def from_summary(cls, data: dict) -> "PassTable":
        """The table back from :meth:`summary` (its ``table`` of columns)."""
        table = data.get("table", {})
        given = {name: np.array([math.nan if v is None else v for v in table.get(name, [])], dtype=float)
                 for name in cls.COLUMNS}
        scalars = {k: v for k, v in data.items() if k not in ("table", "passes")}
        kwargs = fields_from_summary(cls, scalars, **given)
        for key in ("t0_s", "t0_uncertainty_s"):
            if data.get(key) is None:
                kwargs[key] = None
        return cls(**kwargs)

    def _repr_html_(self) -> str:
        rows = [(f"{t:.6f}", int(b), f"{math.degrees(p):.4f}", f"{math.degrees(e):.4f}",
                 f"{math.degrees(a0):.2f} … {math.degrees(a1):.2f}", int(n))
                for t, b, p, e, a0, a1, n in zip(self.time_s, self.blade, self.pitch_rad, self.pitch_stderr_rad,
                                                  self.azimuth_from_rad, self.azimuth_to_rad, self.frames)]
        cap = (f"PassTable of {self.video}: {len(self)} passes, "
               f"{self.rev_per_s:.5g} ± {self.rev_per_s_stderr:.2g} rev/s")
        return html_rows(("time (s)", "blade", "pitch (°)", "± (°)", "ψ span (°)", "frames"), rows, cap)
