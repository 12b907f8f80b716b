"""The turning rotor's geometry (issue 33): blades, their azimuth and pitch, the camera in the rotor plane.

World frame (metres): the rotor axis is +Z (up), the rotor turns counter-clockwise seen from
above (the azimuth ψ grows with time). The camera's pinhole stands in the rotor plane (Z = 0) at
``(camera_distance_m, 0, 0)``, outside the disc, and looks along −X at the axis; its picture's
right is +Y and its up is +Z, so the axis and the rotor plane project to the picture's centre
and middle row (principal point ``((W − 1)/2, (H − 1)/2)``, pixel centres on integers).

A blade's azimuth ψ is 0 when it points at the camera. Its span direction is
``e_r = (cos ψ, sin ψ, 0)``, its direction of travel (the leading edge's side)
``e_t = (−sin ψ, cos ψ, 0)``: at ψ = 0 the tip moves to the picture's right, leading edge on the
right. Pitch θ turns the section about the pitch axis (a quarter chord behind the leading edge):
the chord's leading-edge direction is ``c = cos θ·e_t + sin θ·e_z`` and the section's thickness
direction ``n = −sin θ·e_t + cos θ·e_z``; pitch-up lifts the leading edge, which the camera sees
at ψ = 0 as the chord turned counter-clockwise by θ: servoscope's angle of the line from the
trail sticker to the lead sticker (:func:`~servoscope.simulate.scene.marker_angle_rad`) is θ
there, exactly (the tip face is then square to the optical axis). Away from ψ = 0 the tip face
is seen obliquely: in the orthographic limit ``tan θ_image = tan θ / cos ψ``, and in perspective.

Blade ``b`` of N trails blade 0 by ``2π·b/N`` (``ψ_b = ψ_0 − 2π·b/N``), so that the passes come
in the order 0, 1, …, N−1, 0, … . The rotor speed wanders slowly as an engine's does:
``Ω(t) = Ω_0·(1 + δ·sin(2π t / T + φ))``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from collections.abc import Callable

import numpy as np

from ..defaults import ROTOR_BLADE_COLOURS
from ..errors import ServoscopeError

__all__ = ["ROTOR_BLADE_COLOURS", "RotorRig", "rotor_passes"]

@dataclass(frozen=True)
class RotorRig:
    """A turning rotor filmed edge-on by a fixed camera in its plane (see the module's geometry).

    Parameters
    ----------
    blades : tuple of (str, str)
        Each blade's (lead, trail) sticker colours, blade 0 first; the count is the blade count.
    rev_per_s : float
        Mean rotor speed Ω_0, rev/s.
    drift_fraction, drift_period_s, drift_phase_rad : float
        The speed's slow wander: ``Ω_0·(1 + δ·sin(2π t / T + φ))``.
    azimuth0_rad : float
        Blade 0's azimuth at t = 0.
    blade_offsets_rad : tuple of float
        Each blade's pitch offset (rigging), rad; missing entries are 0.
    cyclic_rad, cyclic_phase_rad : float
        A 1/rev pitch ``cyclic_rad·cos(ψ_b − cyclic_phase_rad)`` added to each blade's.
    coning_rad : float
        The blades' flapping as a steady coning angle β: each blade's span rises by β out of the rotor
        plane (about the hinge at the axis), its tip face tilting with it. Not a pitch: what the camera
        reads of it is the method's error (docs/rotor.md).
    tip_radius_m, root_radius_m : float
        Where the blade's tip face is, and where its drawn span starts (the hub inboard of it
        is not drawn).
    chord_m, thickness_ratio, pivot_chord_fraction : float
        The tip's section: chord, NACA 00xx thickness / chord, pitch axis behind the leading
        edge (chords).
    sticker_chord_fractions : (float, float)
        The lead and trail stickers' centres on the tip face's chord line, chords behind the
        leading edge (either side of the pitch axis).
    sticker_diameter_m : float
        The stickers' diameter (discs on the tip face).
    camera_distance_m : float
        The camera's pinhole to the rotor axis (> tip radius).
    focal_length_px : float
        The pinhole camera's focal length, px.
    blade_colour : str
        The blades' colour.
    """

    blades: tuple[tuple[str, str], ...] = ROTOR_BLADE_COLOURS[:2]
    rev_per_s: float = 20.0
    drift_fraction: float = 0.003
    drift_period_s: float = 1.7
    drift_phase_rad: float = 0.0
    azimuth0_rad: float = 0.0
    blade_offsets_rad: tuple[float, ...] = ()
    cyclic_rad: float = 0.0
    cyclic_phase_rad: float = 0.0
    coning_rad: float = 0.0
    tip_radius_m: float = 0.30
    root_radius_m: float = 0.15
    chord_m: float = 0.05
    thickness_ratio: float = 0.15
    pivot_chord_fraction: float = 0.25
    sticker_chord_fractions: tuple[float, float] = (0.15, 0.55)
    sticker_diameter_m: float = 0.004
    camera_distance_m: float = 0.62
    focal_length_px: float = 1100.0
    blade_colour: str = "#3a3c40"

    def __post_init__(self) -> None:
        blades = tuple((str(a), str(b)) for a, b in self.blades)
        object.__setattr__(self, "blades", blades)
        object.__setattr__(self, "blade_offsets_rad", tuple(float(v) for v in self.blade_offsets_rad))
        problems = []
        if not 1 <= len(blades) <= 8:
            problems.append(f"1 to 8 blades, not {len(blades)}")
        if len(self.blade_offsets_rad) > len(blades):
            problems.append("more blade offsets than blades")
        if not (self.rev_per_s > 0 and math.isfinite(self.rev_per_s)):
            problems.append(f"rev_per_s must be > 0, not {self.rev_per_s!r}")
        if not (0 <= self.drift_fraction < 0.5 and self.drift_period_s > 0):
            problems.append("drift_fraction must be in [0, 0.5) and drift_period_s > 0")
        if not 0 < self.root_radius_m < self.tip_radius_m < self.camera_distance_m:
            problems.append("need 0 < root_radius_m < tip_radius_m < camera_distance_m")
        if not (self.chord_m > 0 and 0 < self.thickness_ratio < 0.5 and self.focal_length_px > 0
                and self.sticker_diameter_m > 0):
            problems.append("chord_m, thickness_ratio (< 0.5), sticker_diameter_m and focal_length_px must be > 0")
        if not abs(self.coning_rad) < 0.5:
            problems.append(f"coning_rad must be within ±0.5 rad, not {self.coning_rad!r}")
        if not all(0 < f < 1 for f in self.sticker_chord_fractions):
            problems.append("sticker_chord_fractions must lie on the chord, in (0, 1)")
        if problems:
            raise ServoscopeError("rotor rig: " + "; ".join(problems))

    @property
    def n_blades(self) -> int:
        """The blade count N."""
        return len(self.blades)

    def offset_rad(self, blade: int) -> float:
        """Blade ``blade``'s pitch offset (rad)."""
        return self.blade_offsets_rad[blade] if blade < len(self.blade_offsets_rad) else 0.0

    # -- time: azimuth and speed ------------------------------------------------------------------
    def rev_per_s_at(self, time_s: np.ndarray | float) -> np.ndarray:
        """The rotor speed at ``time_s`` (rev/s)."""
        t = np.asarray(time_s, dtype=np.float64)
        return self.rev_per_s * (1.0 + self.drift_fraction * np.sin(2.0 * np.pi * t / self.drift_period_s
                                                                    + self.drift_phase_rad))

    def azimuth_rad(self, time_s: np.ndarray | float, blade: int = 0) -> np.ndarray:
        """Blade ``blade``'s azimuth ψ at ``time_s`` (rad, unwrapped: grows by 2π a revolution; 0 mod 2π: pointing
        at the camera)."""
        t = np.asarray(time_s, dtype=np.float64)
        w = 2.0 * np.pi / self.drift_period_s
        wander = self.drift_fraction / w * (math.cos(self.drift_phase_rad) - np.cos(w * t + self.drift_phase_rad))
        return self.azimuth0_rad + 2.0 * np.pi * self.rev_per_s * (t + wander) - 2.0 * np.pi * blade / self.n_blades

    def mean_rev_per_s(self, t_from_s: float, t_to_s: float) -> float:
        """The rotor's mean speed over ``[t_from_s, t_to_s]`` (rev/s): turns made over the time."""
        turned = float(self.azimuth_rad(t_to_s) - self.azimuth_rad(t_from_s))
        return turned / (2.0 * np.pi * (t_to_s - t_from_s))

    def pass_times_s(self, t_from_s: float, t_to_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Every instant in ``[t_from_s, t_to_s]`` at which a blade points at the camera (ψ_b = 0 mod 2π).

        Returns
        -------
        time_s : ndarray of float
            Sorted.
        blade : ndarray of int
            Which blade passes then.
        """
        times, blades = [], []
        for b in range(self.n_blades):
            k0 = math.ceil(float(self.azimuth_rad(t_from_s, b)) / (2.0 * np.pi))
            k1 = math.floor(float(self.azimuth_rad(t_to_s, b)) / (2.0 * np.pi))
            if k1 < k0:
                continue
            target = 2.0 * np.pi * np.arange(k0, k1 + 1)
            # Newton on the monotonic azimuth from the mean-speed guess: ψ is smooth, a few steps converge.
            t = t_from_s + (target - float(self.azimuth_rad(t_from_s, b))) / (2.0 * np.pi * self.rev_per_s)
            for _ in range(8):
                t = t - (self.azimuth_rad(t, b) - target) / (2.0 * np.pi * self.rev_per_s_at(t))
            times.append(t)
            blades.append(np.full(t.size, b))
        if not times:
            return np.zeros(0), np.zeros(0, dtype=int)
        time = np.concatenate(times)
        blade = np.concatenate(blades)
        order = np.argsort(time, kind="stable")
        return time[order], blade[order]

    def blade_pitch_rad(self, collective_rad: np.ndarray | float, time_s: np.ndarray | float,
                        blade: int) -> np.ndarray:
        """Blade ``blade``'s pitch: the collective plus the cyclic at its azimuth plus its offset (rad)."""
        psi = self.azimuth_rad(time_s, blade)
        return (np.asarray(collective_rad, dtype=np.float64) + self.cyclic_rad * np.cos(psi - self.cyclic_phase_rad)
                + self.offset_rad(blade))

    # -- space: sections, stickers, the camera ---------------------------------------------------
    def section_uv_m(self, n: int = 48) -> np.ndarray:
        """The tip section's outline in its own frame (u along the chord towards the leading edge from the pitch
        axis, v across it), metres, shape (2n − 2, 2): a symmetric NACA 4-digit airfoil, its trailing edge
        closed."""
        xi = 0.5 * (1.0 - np.cos(np.linspace(0.0, np.pi, n)))
        half = 5.0 * self.thickness_ratio * self.chord_m * (
            0.2969 * np.sqrt(xi) - 0.1260 * xi - 0.3516 * xi**2 + 0.2843 * xi**3 - 0.1036 * xi**4)
        u = (self.pivot_chord_fraction - xi) * self.chord_m
        upper = np.stack([u, half], axis=1)
        lower = np.stack([u[::-1], -half[::-1]], axis=1)[1:-1]
        return np.concatenate([upper, lower], axis=0)

    def sticker_centres_uv_m(self) -> tuple[np.ndarray, np.ndarray]:
        """The lead and trail stickers' centres on the tip face, (u, v) in metres."""
        lead, trail = self.sticker_chord_fractions
        return (np.array([(self.pivot_chord_fraction - lead) * self.chord_m, 0.0]),
                np.array([(self.pivot_chord_fraction - trail) * self.chord_m, 0.0]))

    def world_points(self, uv_m: np.ndarray, radius_m: float, azimuth_rad: np.ndarray | float,
                     pitch_rad: np.ndarray | float) -> np.ndarray:
        """Section points ``uv_m`` (n, 2) at span radius ``radius_m`` of a blade at azimuth ψ and pitch θ, world
        metres; ψ and θ of shape (m,) give shape (m, n, 3)."""
        uv = np.asarray(uv_m, dtype=np.float64)
        psi = np.asarray(azimuth_rad, dtype=np.float64)[..., None]
        th = np.asarray(pitch_rad, dtype=np.float64)[..., None]
        x, y, z = self.blade_xyz_m(uv[:, 0], uv[:, 1], radius_m, psi, th)
        return np.stack(np.broadcast_arrays(x, y, z), axis=-1)

    def blade_xyz_m(self, u: np.ndarray, v: np.ndarray, radius_m: np.ndarray | float, psi: np.ndarray,
                    th: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """World x, y, z (m) of section points (u along the chord, v across it, at span ``radius_m``) of a blade at
        azimuths ``psi`` and pitches ``th`` (broadcast together), with the rig's coning."""
        cp, sp, ct, st = np.cos(psi), np.sin(psi), np.cos(th), np.sin(th)
        along_t = u * ct - v * st  # the point's share along e_t
        along_z = u * st + v * ct  # along the blade's normal (e_z without coning)
        if self.coning_rad == 0.0:
            return radius_m * cp - along_t * sp, radius_m * sp + along_t * cp, along_z
        # Coning β: the span is cos β·e_r + sin β·e_z, the normal −sin β·e_r + cos β·e_z.
        cb, sb = math.cos(self.coning_rad), math.sin(self.coning_rad)
        radial = radius_m * cb - along_z * sb
        return radial * cp - along_t * sp, radial * sp + along_t * cp, radius_m * sb + along_z * cb

    def project_px(self, xyz_m: np.ndarray, width: int, height: int) -> np.ndarray:
        """World points (…, 3) to the ideal pinhole picture's pixels (…, 2)."""
        p = np.asarray(xyz_m, dtype=np.float64)
        depth = self.camera_distance_m - p[..., 0]
        f = self.focal_length_px
        return np.stack([0.5 * (width - 1) + f * p[..., 1] / depth, 0.5 * (height - 1) - f * p[..., 2] / depth],
                        axis=-1)

    def sticker_centres_px(self, azimuth_rad: np.ndarray | float, pitch_rad: np.ndarray | float, width: int,
                           height: int) -> tuple[np.ndarray, np.ndarray]:
        """Where the lead and trail stickers' centres project (px), at azimuth ψ and pitch θ (the centres' own
        projections: at ψ = 0 also the projected discs' centroids, the tip face then square to the camera)."""
        lead, trail = self.sticker_centres_uv_m()
        out = []
        for c in (lead, trail):
            xyz = self.world_points(c[None, :], self.tip_radius_m, azimuth_rad, pitch_rad)
            out.append(self.project_px(xyz, width, height)[..., 0, :])
        return out[0], out[1]

    def tip_speed_px_per_s(self) -> float:
        """How fast the tip crosses the picture at ψ = 0 (px/s): what sizes the motion blur."""
        return (self.focal_length_px * self.tip_radius_m * 2.0 * np.pi * self.rev_per_s
                / (self.camera_distance_m - self.tip_radius_m))


def rotor_passes(rig: RotorRig, collective_rad_at: Callable[[np.ndarray], np.ndarray], t_from_s: float,
                 t_to_s: float) -> list[dict]:
    """Each pass in ``[t_from_s, t_to_s]``: ``{"blade", "time_s" (ψ = 0), "pitch_rad"}`` (collective + cyclic +
    offset at that instant), in time order."""
    time, blade = rig.pass_times_s(t_from_s, t_to_s)
    collective = np.asarray(collective_rad_at(time), dtype=np.float64) if time.size else np.zeros(0)
    return [{"blade": int(b), "time_s": float(t),
             "pitch_rad": float(rig.blade_pitch_rad(c, t, int(b)))} for t, b, c in zip(time, blade, collective)]
