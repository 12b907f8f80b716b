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


def _board_figure(plane) -> tuple[object, str] | None:
    """The first board photo beside plane.json with its corners found again, and its name; None when not there."""
    import cv2
    import matplotlib.pyplot as plt

    from ..camera.calibrate import detect_corners
    from ..camera.plane import refine_plane_corners

    if plane is None or not plane.views or not plane.source:
        return None
    name = plane.views[0].name.split("#")[0]
    photo = Path(plane.source).parent / name
    bgr = cv2.imread(str(photo), cv2.IMREAD_COLOR) if photo.is_file() else None
    if bgr is None:
        return None
    gray = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
    corners = detect_corners(gray, tuple(plane.board), fast=False)
    if corners is None:
        return None
    corners = refine_plane_corners(gray, corners, tuple(plane.board)).reshape(-1, 2)  # as servoscope plane found them
    h, w = gray.shape
    fig, ax = plt.subplots(figsize=(7.5, 7.5 * h / w + 0.4))
    ax.imshow(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), interpolation="nearest")
    ax.plot(corners[:, 0], corners[:, 1], "+", color="#d62728", ms=7, mew=1.2)
    ax.plot(corners[[0, plane.board[0] - 1], 0], corners[[0, plane.board[0] - 1], 1], "-", color="#17becf", lw=1.5)
    ax.set_title(f"{name}: the board's {len(corners)} corners; the plane's view {plane.view_angle_deg:.1f}° off square")
    ax.set_axis_off()
    fig.tight_layout()
    return fig, name


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
        board = _board_figure(result.campaign.plane)
        if board is not None:
            s.figure(board[0], f"The board photo ({board[1]}) with its corners (red; the first row in cyan), found "
                     "again as servoscope plane found them.", "Board photo with its corners", name="plane_board")
    if view is not None and plane is None and not view.determined:
        s.text(f"The stickers do not tell the camera's view: {view.why}.")
    elif view is not None and plane is None:
        lo, hi = view.view_angle_ci95_deg
        glo, ghi = view.angle_gain_ci95
        s.text("The view the stickers show in the picture: a round or square sticker's image is the view's local "
               "Jacobian, two of them a chord apart in many frames give its foreshortening and its perspective "
               "(docs/accuracy.md, \"Oblique views\"):")
        s.table(["view angle off square", "95 %", "angle gain (image / plane)", "95 %", "swing", "sharp frames"],
                [[f"{view.view_angle_deg:.1f}°", f"{lo:.1f}–{hi:.1f}°", f"{view.angle_gain:.4f}",
                  f"{glo:.4f}–{ghi:.4f}", f"{view.swing_deg:.1f}°", view.n_frames]])
    said = [w for w in result.warnings if w.startswith(_VIEW_WARNINGS)]
    if said:
        s.warnings(said)
    return s
