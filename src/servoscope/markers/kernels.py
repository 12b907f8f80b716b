"""The fused per-frame tracking kernel, on the decoder's native YUV 4:2:0 planes.

One call per frame measures both markers (and the LED) without converting
the frame to RGB: for each marker, inside its tracking window,

1. **classify** every luma pixel by *chroma* (identity): its (Cb, Cr), taken
   bilinearly from the half-resolution chroma planes, must point within a
   hue tolerance of the marker's chroma direction with a saturation above a
   floor (robust to brightness). The class's binary moments give a coarse
   centre, the detection and its bounding box;
2. sample the **local background** on a ring around that centre, binned by
   angle (a blade/sky edge across the ring is followed bin by bin);
3. **unmix** every pixel of the support disk between the marker's colour
   ``M`` and its own background ``b`` (the ring bin in its direction):

       α = (w_Y·c_Y·r_Y + c_U·r_U + c_V·r_V) / (w_Y·c_Y² + c_U² + c_V²),
       c = M − b,  r = p − b,

   the blend ``α = (w_Y·c_Y²·α_Y + |c_C|²·α_C) / (w_Y·c_Y² + |c_C|²)`` of
   the luma-only ``α_Y = r_Y / c_Y`` and the chroma-only
   ``α_C = c_C·r_C / |c_C|²`` (each clipped to [``alpha_lo``, ``alpha_hi``]
   first, so that a background luma step far above a weak luma contrast
   cannot dominate): with ``w_Y`` ≫ 1 the sharp, full-resolution luma sets
   the sub-pixel weight wherever the marker/background luma contrast is
   adequate, and the (smeared) chroma takes over where it is weak — a
   sticker whose luma equals the blade's or the sky's. Unclipped, it is the
   least-squares unmixing ``(w_Y·c_Y·r_Y + c_C·r_C) / (w_Y·c_Y² + |c_C|²)``.
   Luma's weight is kept only where ``α_Y`` agrees with ``α_C`` (within
   ``agree`` ± 0.1, a ramp): a background pixel whose luma happens to equal
   the marker's (sky next to a green sticker, where the ring's bin mixes
   sky and blade) is then told by its chroma. The two are compared at
   *chroma's* resolution: ``α_Y`` is averaged over the 2×2 blocks the
   writer averaged the chroma over and read bilinearly at chroma's siting,
   exactly as ``α_C``'s chroma was (chroma is linear in the mixture, so
   where luma's background is right the two agree to noise, also across
   the sticker's edge). Compared pixel by pixel, the half-resolution
   chroma's smear made them disagree by 0.2–0.5 all along the edge, so
   luma was dropped exactly where its sharpness matters; a marker whose
   chroma contrast is weak and luma contrast strong (magenta on a dark
   blade) then took the codec's chroma error in full;
4. accumulate the weighted moments m00, m10, m01, the second moments and
   the noise-propagation sums, and recentre (``iterations`` passes).

Then the LED: its disk follows the markers' axis (its position in the
markers' frame is learned once); the mean luma over it is its level.

:func:`track_frame_numpy` is the plain-numpy reference of the same maths;
:func:`track_frame_numba` the compiled one (``nogil``: a decoder thread runs
meanwhile). Both take and fill the same arrays (layouts in
:mod:`.kernel_layout`) and agree to rounding (the tests hold them to 1e-9).
This module is their public face; the code lives in :mod:`.kernel_layout`,
:mod:`.kernel_numpy` and :mod:`.kernel_numba`.
"""

from __future__ import annotations

from .kernel_layout import LED_NP, LED_NQ, N_BINS, NP, NQ, P, Q, chroma_window
from .kernel_numba import led_level_numba, track_frame_numba
from .kernel_numpy import chroma_np, classify_np, led_level_numpy, track_frame_numpy

__all__ = [
    "P", "Q", "NP", "NQ", "LED_NP", "LED_NQ", "N_BINS",
    "track_frame_numpy", "track_frame_numba", "track_frame", "led_level_numpy", "led_level_numba",
    "ENGINES", "LED_ENGINES", "chroma_window", "chroma_np", "classify_np",
]

ENGINES = {"numpy": track_frame_numpy, "numba": track_frame_numba}
LED_ENGINES = {"numpy": led_level_numpy, "numba": led_level_numba}


def track_frame(engine: str, Y, U, V, row_off, row_step, params, led, out, led_out) -> None:
    """Dispatch to ``engine`` ("numpy" or "numba")."""
    ENGINES[engine](Y, U, V, row_off, row_step, params, led, out, led_out)
