"""A frame's global illumination gain against the first frame.

Lamps on the mains flicker at twice its frequency (8 % in brightness is
common), cameras adjust their exposure, clouds pass. All of these scale the
light of the whole scene, stickers and background alike, by one factor per
frame. The YUV kernel unmixes each pixel between the marker's colour learned
on the first frame and the local background measured in this frame: under a
gain g the marker's pixels are g times that colour, so the sticker's soft
area came out g times its reference, and a 3 % area tolerance read every dim
frame as a partly hidden sticker. With the learned colour scaled by g for the
frame, the unmixing sees the sticker's outline again, whatever the light.

g is the median, over a sparse grid of the luma plane, of the ratio of the
frame's luma to the first frame's (both above black). The moving blade
changes a minority of the grid's pixels; the median ignores them. On still
footage with sensor noise of 1.5 DN its spread is ~0.1 %.

A rolling shutter breaks the one-factor-per-frame picture: each sensor row
integrates the lamps over its own exposure window, so flicker shows as bands
along the rows (100 Hz read out in 3.5 ms: a third of a period over the
frame). The frame's median then is the light of the frame's middle bands, and
a sticker in another band was scaled by the wrong gain (5–10 % off at 8 %
depth: its area read 94–96 % of its reference, "partly hidden"). Under a
rolling shutter :class:`BandGain` takes each marker's gain from the grid
samples in the band of sensor rows around it, narrow enough that the lamps'
phase hardly changes across it.

Monochrome footage read as the camera stored it (the monochrome engine's
native samples: 8–16 bits, Photron's packed 12-bit bytes) has its own
:class:`NativeGain`: the same grid and median, read through
:func:`~servoscope.video.native.sample_at` and with the 8-bit floor
:data:`MIN_SIGNAL_DN` scaled to the samples' depth.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..video.native import sample_at

__all__ = ["GlobalGain", "BandGain", "NativeGain", "scale_colour", "varied_warning", "GAIN_DEADBAND", "BLACK_DN",
           "NEUTRAL_DN"]

#: Gains within this of 1 are taken as 1: the learned colour is then used unchanged, so
#: footage under steady light is tracked exactly as before (bit for bit). A 1 % gain moves a
#: sticker's soft area by ~1 %, a third of the partly-hidden tolerance; the estimate's own
#: spread on steady footage is ~0.1 % (8-bit luma, sensor noise, H.264 at 20 Mbit/s).
GAIN_DEADBAND = 0.01
#: Limited-range (BT.601/709) black level of luma and neutral level of chroma (DN).
BLACK_DN = 16.0
NEUTRAL_DN = 128.0
#: Grid pixels darker than this above black in the first frame are left out (their ratio is noise).
MIN_SIGNAL_DN = 24.0
#: About this many grid pixels per frame (the median of 1000 ratios of 2–3 % noise each: ±0.1 %).
GRID_SAMPLES = 1024
#: :class:`NativeGain`'s grid lies on this many image rows, evenly spaced (GRID_SAMPLES in all). Lamps
#: light a global shutter's frame as one, so any rows will do, and spread rows keep one moving object from
#: a majority of them; few rows are few of a memory-mapped file's pages to map each frame. Measured on a
#: loaded 2-core machine: 512×512 16-bit MRAW, 26 µs a frame on 4 rows against 52 µs on the square grid's
#: 32; 1024×1024, about the same on 1 to 4 rows (the samples' arithmetic, not the pages, was the cost).
NATIVE_GRID_ROWS = 4
#: :class:`NativeGain` takes a frame whose grid ratios are surely centred within this of 1 as 1.0, its
#: median not computed: half the dead band, so that the median's rounding at the band's edge never
#: decides (a gain between the two is measured, and the engine's dead band decides as it would).
NATIVE_QUICK_BAND = 0.5 * GAIN_DEADBAND
#: Fastest flicker a band is sized for: mains lamps on 60 Hz flicker at 120 Hz (100 Hz on 50 Hz).
FLICKER_HZ_MAX = 120.0
#: A band spans ±30° of that flicker's phase: across it the light changes by at most
#: depth·(1 − cos 30°) = 13 % of the depth (a 1 % spread at 8 % depth), and on the flicker's
#: slopes, where it changes fastest, linearly, which the band's median (its middle) does not see.
BAND_HALF_PHASE_RAD = math.pi / 6.0
#: ...and at most this fraction of the sensor's rows each side (slow readouts): a band much wider
#: than the marker's neighbourhood would only add the blade's motion to the samples.
BAND_MAX_FRACTION = 0.2
#: About this many samples over the frame for the bands (a band of a tenth of the rows holds
#: ~400: the median's spread ±0.15 %, a sixth of the dead-band).
BAND_GRID_SAMPLES = 4096
#: Fewer bright samples than this in a band: take the frame's gain instead.
MIN_BAND_SAMPLES = 48
#: A wide band's samples are thinned to about this many (every k-th): its median's spread is then
#: ~0.15 % still, at ~13 µs a marker instead of ~30 µs for the ~1900 of a fifth of the rows each side.
BAND_MAX_SAMPLES = 512


class GlobalGain:
    """Per-frame illumination gain against the first frame (or field) seen.

    Parameters
    ----------
    black_dn : float
        Luma of black (16 for limited-range video, 0 for full range).

    Notes
    -----
    Fields of interlaced footage are compared with the first field of the
    same parity: they sample different rows.
    """

    def __init__(self, black_dn: float = BLACK_DN) -> None:
        self.black_dn = float(black_dn)
        self._ref: dict[int, tuple] = {}

    def __call__(self, luma: np.ndarray, parity: int = 0) -> float:
        """Gain of this luma plane against the first one of this parity (1.0 for that first one).

        Parameters
        ----------
        luma : ndarray, shape (h, w), uint8
        parity : int
            Which kind of image it is (a field's row offset); each has its own reference.

        Returns
        -------
        float
            The gain; 1.0 when it cannot be measured (too few bright pixels).
        """
        ref = self._ref.get(parity)
        if ref is None:
            h, w = luma.shape
            step = max(1, int(math.sqrt(h * w / GRID_SAMPLES)))
            rows, cols = np.mgrid[step // 2:h:step, step // 2:w:step]
            base = np.asarray(luma)[rows, cols].astype(np.float64) - self.black_dn
            keep = base >= MIN_SIGNAL_DN
            self._ref[parity] = (rows[keep].astype(np.int64), cols[keep].astype(np.int64), base[keep],
                                 np.empty(int(keep.sum())), (h, w))
            return 1.0
        rows, cols, base, buf, shape = ref
        if base.size < 16 or luma.shape != shape:
            return 1.0
        # Compiled: ~3 µs a frame (NumPy's slicing and median of 2000 samples took ~18 µs).
        return float(_median_ratio(luma, rows, cols, base, self.black_dn, buf))


class BandGain:
    """Illumination gain of the band of sensor rows around a point, against the first frame.

    Parameters
    ----------
    readout_s : float
        Rolling-shutter readout time (> 0): the bands' width follows from it.
    axis : {0, 1}
        The image axis along which the sensor's rows follow one another: 0 (image
        rows), or 1 (image columns: a phone's 90° or 270° display rotation).
    black_dn : float
        Luma of black.

    Notes
    -----
    Call :meth:`set_frame` once a frame (the first one is the reference), then
    :meth:`gain` for each marker. Whole frames only: a rolling shutter is not
    combined with interlaced fields (see :func:`~servoscope.camera.rolling_shutter.check_readout`).
    """

    def __init__(self, readout_s: float, axis: int = 0, black_dn: float = BLACK_DN) -> None:
        if not readout_s > 0 or axis not in (0, 1):
            raise ValueError("BandGain needs a readout time > 0 and axis 0 or 1")
        self.readout_s = float(readout_s)
        self.axis = int(axis)
        self.black_dn = float(black_dn)
        self._ref: tuple | None = None
        self._luma: np.ndarray | None = None
        self._first = True

    def half_width_px(self, sensor_rows: int) -> float:
        """Half-width of a band (sensor rows) for a sensor of ``sensor_rows`` rows."""
        # Row y is exposed readout·y/rows after row 0: ±φ of the flicker's phase is
        # ±rows·φ/(2π·f·readout) rows.
        rows = sensor_rows * BAND_HALF_PHASE_RAD / (2.0 * math.pi * FLICKER_HZ_MAX * self.readout_s)
        return min(rows, BAND_MAX_FRACTION * sensor_rows)

    def set_frame(self, luma: np.ndarray) -> None:
        """Take ``luma`` (shape (h, w), uint8) as this frame's; the first frame's is the reference."""
        self._luma = luma
        if self._ref is not None:
            self._first = False
            return
        h, w = luma.shape
        step = max(1, int(math.sqrt(h * w / BAND_GRID_SAMPLES)))
        rows, cols = np.mgrid[step // 2:h:step, step // 2:w:step]
        if self.axis == 1:
            rows, cols = rows.T, cols.T  # ordered by column: a band is one slice
        rows, cols = rows.ravel(), cols.ravel()
        base = np.asarray(luma)[rows, cols].astype(np.float64) - self.black_dn
        keep = base >= MIN_SIGNAL_DN
        rows, cols = rows[keep].astype(np.int64), cols[keep].astype(np.int64)
        coord = rows if self.axis == 0 else cols
        self._ref = (rows, cols, base[keep], coord.astype(np.float64), np.empty(int(keep.sum())), (h, w), step)

    def gain(self, along_px: float, fallback: float = 1.0) -> float:
        """Gain of the band centred on ``along_px`` (the marker's coordinate along :attr:`axis`).

        Parameters
        ----------
        along_px : float
            Image row (axis 0) or column (axis 1) of the band's centre.
        fallback : float
            Returned when the band cannot be measured (too few bright samples, another size).

        Returns
        -------
        float
            1.0 on the reference frame.
        """
        if self._ref is None or self._luma is None:
            return fallback
        if self._first:
            return 1.0
        rows, cols, base, coord, buf, shape, step = self._ref
        if self._luma.shape != shape:
            return fallback
        size = shape[self.axis]
        # Symmetric about the marker (a lopsided band's median is the light of another row),
        # narrowed near the image's edge, but never under two grid lines each side.
        half = max(min(self.half_width_px(size), along_px, size - 1 - along_px), 2.0 * step)
        i0, i1 = np.searchsorted(coord, (along_px - half, along_px + half), side="left")
        if i1 - i0 < MIN_BAND_SAMPLES:
            return fallback
        k = max(1, (i1 - i0) // BAND_MAX_SAMPLES)
        band = slice(i0, i1, k)
        n = len(range(i0, i1, k))
        return float(_median_ratio(self._luma, rows[band], cols[band], base[band], self.black_dn, buf[:n]))


class NativeGain:
    """Per-frame illumination gain of a monochrome frame's native samples against the first frame's.

    :class:`GlobalGain`'s estimate (the median ratio over a sparse grid, here on
    :data:`NATIVE_GRID_ROWS` rows) on a
    :class:`~servoscope.video.native.NativeFrame`: the grid's samples read where
    they are stored (packed 12-bit decoded by :func:`~servoscope.video.native.sample_at`,
    a 16-bit word's high-bit samples unshifted), above the frame's own black
    level, and the floor :data:`MIN_SIGNAL_DN` (8-bit DN) scaled to the samples'
    depth, so that the same pixels count at any depth.

    A frame whose gain surely lies within :data:`NATIVE_QUICK_BAND` of 1
    (fewer than half the grid's ratios beyond it either way) is given 1.0
    without the median: the engine leaves such a frame unscaled either way
    (it is inside :data:`GAIN_DEADBAND`), and steady footage then costs one
    pass over the grid, without the median's selection. The track's warning
    (:func:`varied_warning`) counts such a frame as 1.0.
    """

    def __init__(self) -> None:
        self._ref: tuple | None = None

    def __call__(self, frame) -> float:
        """Gain of ``frame`` (a :class:`~servoscope.video.native.NativeFrame`) against the first one (1.0 for it).

        Returns
        -------
        float
            The gain; 1.0 when it cannot be measured (too few bright samples, another frame size or layout).
        """
        img, packed, black = frame.samples, frame.packed, float(frame.black)
        if self._ref is None:
            h, w = frame.shape
            # GRID_SAMPLES on a few whole rows, not a square grid: the file's pages a frame touches cost
            # more than the samples (a memory-mapped frame's page is mapped on its first read, each frame).
            ys = ((np.arange(NATIVE_GRID_ROWS) + 0.5) * h / NATIVE_GRID_ROWS).astype(np.int64)
            per_row = min(w, GRID_SAMPLES // NATIVE_GRID_ROWS)
            xs = ((np.arange(per_row) + 0.5) * w / per_row).astype(np.int64)
            rows, cols = np.repeat(ys, per_row), np.tile(xs, len(ys))
            base = np.empty(rows.size)
            _samples_at(img, packed, rows, cols, base)
            base -= black
            keep = base >= frame.from_8bit(MIN_SIGNAL_DN) - black
            # Reciprocals: a product a sample instead of a quotient (measured 7 µs a frame against 34 µs).
            self._ref = (rows[keep], cols[keep], 1.0 / base[keep], np.empty(int(keep.sum())), frame.shape, packed,
                         black)
            return 1.0
        rows, cols, inv_base, buf, shape, was_packed, was_black = self._ref
        if inv_base.size < 16 or frame.shape != shape or packed != was_packed or black != was_black:
            return 1.0
        return float(_median_ratio_native(img, packed, rows, cols, inv_base, black, NATIVE_QUICK_BAND, buf))


def varied_warning(gains: list[float], scaled: str, bands: bool = False) -> str | None:
    """The track's warning that the light varied, or None when every gain was within the dead band.

    Parameters
    ----------
    gains : list of float
        Each frame's gain (the one furthest from 1 that frame took).
    scaled : str
        What was scaled with the light ("the markers' colours", "the markers' levels").
    bands : bool
        Whether each marker took the gain of its band of sensor rows (a rolling shutter).
    """
    corrected = [g for g in gains if abs(g - 1.0) > GAIN_DEADBAND]
    if not corrected:
        return None
    lo, hi = min(gains), max(gains)
    return (f"illumination varied ({100 * (lo - 1):+.1f} % to {100 * (hi - 1):+.1f} % of the first "
            f"frame's: flicker, auto-exposure or clouds) in {len(corrected)} of {len(gains)} frames; "
            f"{scaled} were scaled with it"
            + (" (each by the light of its band of sensor rows: a rolling shutter)" if bands else ""))


def scale_colour(prm_yuv: tuple[float, float, float], gain: float, black_dn: float = BLACK_DN
                 ) -> tuple[float, float, float]:
    """A (Y, Cb, Cr) colour as it looks under ``gain``: luma about black, chroma about neutral."""
    y, u, v = prm_yuv
    return (black_dn + gain * (y - black_dn), NEUTRAL_DN + gain * (u - NEUTRAL_DN),
            NEUTRAL_DN + gain * (v - NEUTRAL_DN))


@njit(cache=True, nogil=True)
def _median_ratio(luma, rows, cols, base, black, buf):
    for i in range(rows.size):
        buf[i] = (float(luma[rows[i], cols[i]]) - black) / base[i]
    return np.median(buf)


@njit(cache=True, nogil=True)
def _samples_at(img, packed, rows, cols, out):
    for i in range(rows.size):
        out[i] = sample_at(img, rows[i], cols[i], packed)


@njit(cache=True, nogil=True)
def _median_ratio_native(img, packed, rows, cols, inv_base, black, quick, buf):
    # Fewer than half the ratios below 1 − quick and fewer than half above 1 + quick: the median lies
    # within ±quick (the two middle order statistics both do), and 1.0 is returned without it.
    # Counted without branches: the loop then compiles to straight-line code.
    n = rows.size
    lo = 0
    hi = 0
    for i in range(n):
        r = (sample_at(img, rows[i], cols[i], packed) - black) * inv_base[i]
        buf[i] = r
        lo += r < 1.0 - quick
        hi += r > 1.0 + quick
    if 2 * lo < n and 2 * hi < n:
        return 1.0
    return np.median(buf)
