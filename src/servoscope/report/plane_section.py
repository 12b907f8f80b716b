"""The report's section on the camera's view of the blade's plane (issue 27)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from .html import ReportSection

if TYPE_CHECKING:  # pragma: no cover
    from ..campaign.result import IdentificationResult

__all__ = ["plane_section"]

#: The starts of the warnings this section repeats (the view's, the plane's, the self-calibration's).
_VIEW_WARNINGS = ("the camera looks at the blade", "in the plane of", "angles corrected for the camera's view",
                  "the gain's interval includes the angle scale's uncertainty")


def _num(value, fmt: str) -> str:
    return "—" if value is None else format(value, fmt)


def plane_section(result: "IdentificationResult", figures_dir: Path | None) -> ReportSection | None:
    """The plane the angles were measured in, and the view the markers show; None without either."""
    view, plane = result.view, result.plane
    if view is None and plane is None:
        return None
    s = ReportSection("Camera view and the blade's plane", figures_dir=figures_dir)
    if plane is None:
        s.text("Angles measured in the picture (no [camera] plane): right for a camera that faces the blade's plane "
               "square-on. A camera off square reads angles small or large (foreshortening, and perspective: the "
               "nearer sticker moves more); the stickers' shapes and sizes tell how far off square it looks (below).")
    elif str(plane.get("source", "")).startswith("self-calibrated"):
        s.text("Angles corrected for the camera's view as the stickers' shapes and sizes tell it "
               "(--self-calibrate-plane: foreshortening and perspective, resting on round or square stickers of one "
               "size); the gain's interval includes the estimate's uncertainty.")
    else:
        s.text(f"Angles, separations, heave and bending measured in the blade's plane from {plane.get('source')} "
               "(servoscope plane: a chessboard held against the blade, photographed by the campaign's camera).")
        s.table(["plane", "view angle", "board photos", "reprojection RMS", "angle gain uncertainty (1σ)"],
                [[plane.get("source"),
                  f"{_num(plane.get('view_angle_deg'), '.1f')}°"
                  + (f" ± {plane['view_angle_std_deg']:.1f}°" if isinstance(plane.get("view_angle_std_deg"), float)
                     and plane["view_angle_std_deg"] == plane["view_angle_std_deg"] else "")
                  + (f" ({plane['view_angle_source']})" if plane.get("view_angle_source") else ""),
                  plane.get("n_views"),
                  f"{_num(plane.get('rms_px'), '.3f')} px, {_num(plane.get('rms_mm'), '.3f')} mm",
                  f"{_num(None if plane.get('angle_gain_std') is None else 100.0 * plane['angle_gain_std'], '.2g')} %"]])
    if view is not None:
        lo, hi = view.view_angle_ci95_deg
        glo, ghi = view.angle_gain_ci95
        where = "the picture" if plane is None else "the plane (a check of it: 0° when it is the blade's)"
        s.text(f"The view the stickers show in {where}: a round or square sticker's image is the view's local "
               "Jacobian, two of them a chord apart in many frames give its foreshortening and its perspective "
               "(docs/accuracy.md, \"Oblique views\"):")
        s.table(["view angle off square", "95 %", "angle gain (image / plane)", "95 %", "swing", "frames",
                 "told by the footage"],
                [[f"{view.view_angle_deg:.1f}°", f"{lo:.1f}–{hi:.1f}°", f"{view.angle_gain:.4f}",
                  f"{glo:.4f}–{ghi:.4f}", f"{view.swing_deg:.1f}°", view.n_frames,
                  "yes" if view.determined else "no (the blade turns too little)"]])
    said = [w for w in result.warnings if w.startswith(_VIEW_WARNINGS)]
    if said:
        s.warnings(said)
    return s
