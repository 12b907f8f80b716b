"""The blade's plane end to end on an oblique twin campaign, through the command line.

One campaign filmed 30° off square (yaw −25°, tilt 17°), uncompressed at 480×384, with its
board photo; the user's commands: ``servoscope plane board.png …``, ``identify`` without the
plane and with ``plane = "plane.json"`` in campaign.toml's [camera] table. Rendered and
identified once per session (~25 s on 2 cores); the numbers it is held to are the issue's
targets (docs/accuracy.md, "Oblique views and the blade's plane").
"""

from __future__ import annotations

import csv
import json
import re
import shutil
from pathlib import Path
from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from servoscope.camera import CameraModel
from servoscope.cli import main
from servoscope.simulate import simulate_campaign

from support import cli as _run  # (exit status, stdout, stderr)

VIEW = (-25.0, 17.0)  # (yaw, tilt), degrees: arccos(cos 25° · cos 17°) = 29.9° off square
PARAMS = ("gain", "natural_frequency_rad_s", "damping_ratio", "dead_time_s")


def _cli(*args) -> int:
    """``servoscope ARGS`` in this process; its exit code."""
    try:
        main([str(a) for a in args])
    except SystemExit as exc:
        return int(exc.code or 0)
    return 0


@pytest.fixture(scope="session")
def oblique(tmp_path_factory) -> SimpleNamespace:
    """The campaign, its plane.json, and result folders without (``res_image``) and with (``res_plane``) the plane."""
    folder = tmp_path_factory.mktemp("oblique")
    toml = simulate_campaign(folder, preset="quick", seed=0, codec="raw", width=480, height=384,
                             view_yaw_deg=VIEW[0], view_tilt_deg=VIEW[1])
    truth = json.loads((folder / "truth.json").read_text())
    square = truth["board"]["square_mm"]
    assert _cli("plane", folder / "board.png", "--board", "9x6", "--square", square, "--calibration",
                folder / "camera.json", "--out", folder / "plane.json") == 0
    assert _cli("identify", toml, "--out", folder / "res_image", "--workers", 1, "--quiet") == 0
    text = toml.read_text()
    toml.write_text(re.sub(r"^\[camera\]\n", '[camera]\nplane = "plane.json"\n', text, count=1, flags=re.M))
    assert 'plane = "plane.json"' in toml.read_text()
    assert _cli("identify", toml, "--out", folder / "res_plane", "--workers", 1, "--quiet") == 0
    return SimpleNamespace(
        folder=folder, truth=truth, square_mm=square,
        image=json.loads((folder / "res_image" / "result.json").read_text()),
        plane=json.loads((folder / "res_plane" / "result.json").read_text()),
    )


def test_with_the_plane_k_and_wn_meet_the_targets_and_every_interval_holds_the_truth(oblique):
    model, true = oblique.plane["model"], oblique.truth["model"]
    # The targets at 30° off square, uncompressed: K and ωn within 0.3 %.
    assert model["gain"] == pytest.approx(true["gain"], rel=0.003)
    assert model["natural_frequency_rad_s"] == pytest.approx(true["natural_frequency_rad_s"], rel=0.003)
    for name in PARAMS:
        low, high = model["ci95"][name]
        assert low <= true[name] <= high, (name, low, true[name], high)


def test_without_the_plane_k_is_off_by_more_than_its_interval_says(oblique):
    model, true = oblique.image["model"], oblique.truth["model"]
    low, high = model["ci95"]["gain"]
    error = model["gain"] - true["gain"]
    # 30° off square reads angles ~8 % large here; the interval (±0.2 %) knows nothing of it.
    assert abs(error) > 0.03 * true["gain"]
    assert abs(error) > 10 * (high - low) / 2 and not low <= true["gain"] <= high
    assert oblique.image.get("plane") is None


def test_result_json_says_which_plane_the_angles_were_measured_in(oblique):
    plane = oblique.plane["plane"]
    assert Path(plane["source"]).name == "plane.json"
    assert plane["image_size"] == [480, 384] and plane["board"] == [9, 6] and plane["n_views"] == 1
    assert plane["square_mm"] == pytest.approx(oblique.square_mm)
    assert plane["calibrated"] is True and plane["view_angle_source"] == "calibration"
    assert plane["view_angle_deg"] == pytest.approx(oblique.truth["view"]["view_angle_deg"], abs=0.3)
    assert plane["rms_px"] < 0.1 and 0 < plane["angle_gain_std"] < 1e-3
    # The gain's interval carries the plane's uncertainty: it is no narrower than without the plane.
    lo_p, hi_p = oblique.plane["model"]["ci95"]["gain"]
    lo_i, hi_i = oblique.image["model"]["ci95"]["gain"]
    assert (hi_p - lo_p) / oblique.plane["model"]["gain"] >= 0.5 * (hi_i - lo_i) / oblique.image["model"]["gain"]


def _rows(path: Path) -> list[dict]:
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


def test_track_csv_gives_the_markers_in_the_planes_millimetres(oblique):
    rows = _rows(oblique.folder / "res_plane" / "tracks" / "step.csv")
    assert {"lead_x_mm", "lead_y_mm", "trail_x_mm", "trail_y_mm"} <= set(rows[0])
    assert "lead_x_mm" not in _rows(oblique.folder / "res_image" / "tracks" / "step.csv")[0]
    ok = [r for r in rows if r["valid"] in ("1", "True")]
    assert len(ok) == len(rows)  # the step's stickers grow and shrink across the view: no frame thrown away
    got = np.array([[float(r[k]) for k in ("lead_x_mm", "lead_y_mm", "trail_x_mm", "trail_y_mm")] for r in ok])
    sep_mm = np.hypot(got[:, 0] - got[:, 2], got[:, 1] - got[:, 3])
    test = next(t for t in oblique.truth["tests"] if t["kind"] == "step")
    lead, trail = np.asarray(test["lead_xy_px"]), np.asarray(test["trail_xy_px"])
    true_mm = oblique.truth["view"]["plane_mm_per_px"] * np.hypot(*(lead - trail).T)
    # The stickers' separation on the blade, in mm, from one board photo: to 0.05 % (0.02 mm of 40).
    assert np.mean(sep_mm) == pytest.approx(np.mean(true_mm), rel=5e-4)
    assert np.std(sep_mm) < 0.01


def test_the_report_has_the_plane_section(oblique):
    html = (oblique.folder / "res_plane" / "report.html").read_text(encoding="utf-8")
    assert "Camera view and the blade&#x27;s plane" in html or "Camera view and the blade's plane" in html
    assert "plane.json" in html and f"{oblique.plane['plane']['view_angle_deg']:.1f}°" in html


# -- bad input through the command line: exit 2, one line, nothing written ----------------------------


def _refused(capsys, tmp_path: Path, args: list, expected: str, out: Path) -> None:
    code, printed, err = _run(capsys, *args)
    assert code == 2, (printed, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("servoscope: error: ") and expected in lines[0], err
    assert "Traceback" not in err and not out.exists()


def test_track_refuses_a_plane_made_from_photos_of_another_size(oblique, tmp_path, capsys):
    photo = cv2.imread(str(oblique.folder / "board.png"))
    cv2.imwrite(str(tmp_path / "board_400.png"), cv2.resize(photo, (400, 320), interpolation=cv2.INTER_AREA))
    code, _, err = _run(capsys, "plane", tmp_path / "board_400.png", "--board", "9x6", "--square", oblique.square_mm,
                        "--out", tmp_path / "plane_400.json")
    assert code == 0, err
    video = oblique.folder / next(t["video"] for t in oblique.truth["tests"] if t["kind"] == "step")
    out = tmp_path / "out" / "step.csv"
    _refused(capsys, tmp_path, ["track", video, "--plane", tmp_path / "plane_400.json", "--out", out],
             "frames are 480x384 but", out)


def test_a_plane_of_another_camera_is_refused(oblique, tmp_path, capsys):
    camera = CameraModel.load(oblique.folder / "camera.json")
    longer = np.array(camera.camera_matrix, dtype=float) * [[1.1], [1.1], [1.0]]  # another focal length
    CameraModel(camera.image_size, longer, camera.dist_coeffs).save(tmp_path / "other_camera.json")
    code, _, err = _run(capsys, "plane", oblique.folder / "board.png", "--board", "9x6", "--square", oblique.square_mm,
                        "--calibration", tmp_path / "other_camera.json", "--out", tmp_path / "other_plane.json")
    assert code == 0, err
    video = oblique.folder / next(t["video"] for t in oblique.truth["tests"] if t["kind"] == "step")
    out = tmp_path / "out" / "step.csv"
    _refused(capsys, tmp_path, ["track", video, "--calibration", oblique.folder / "camera.json",
                                "--plane", tmp_path / "other_plane.json", "--out", out],
             "made with another camera calibration", out)
    # The same plane named in the campaign: identify refuses it before writing anything.
    toml = oblique.folder / "campaign.toml"
    other = tmp_path / "campaign.toml"
    other.write_text(toml.read_text().replace('plane = "plane.json"', f'plane = "{tmp_path / "other_plane.json"}"')
                     .replace('calibration = "camera.json"', f'calibration = "{oblique.folder / "camera.json"}"')
                     .replace('video = "', f'video = "{oblique.folder}/'))
    out_dir = tmp_path / "res"
    _refused(capsys, tmp_path, ["identify", other, "--out", out_dir, "--workers", 1, "--quiet"],
             "made with another camera calibration", out_dir)


def test_without_the_plane_the_stickers_warn_with_the_view_and_the_gain_error(oblique):
    # The view the stickers' shapes and sizes tell (angle/view.py): within 3° of the renderer's, and the
    # gain error it states holds the one K actually shows without the plane (perspective included).
    view, true = oblique.image["view"], oblique.truth
    assert abs(view["view_angle_deg"] - true["view"]["view_angle_deg"]) < 3.0
    lo, hi = view["view_angle_ci95_deg"]
    assert lo <= true["view"]["view_angle_deg"] <= hi
    seen = oblique.image["model"]["gain"] / true["model"]["gain"]
    glo, ghi = view["angle_gain_ci95"]
    assert glo <= seen <= ghi
    said = [w for w in oblique.image["warnings"] if "off square" in w]
    assert len(said) == 1 and "servoscope plane" in said[0]
    # With the board's plane nothing is said of the view: the plane is what the warning asks for.
    assert not any("off square" in w for w in oblique.plane["warnings"])


def test_self_calibrated_from_the_stickers_k_is_nearer_and_its_interval_holds_the_truth(oblique, capsys):
    toml = oblique.folder / "campaign_noplane.toml"
    text = (oblique.folder / "campaign.toml").read_text()
    toml.write_text(re.sub(r'^plane = "plane.json"\n', "", text, flags=re.M))
    out = oblique.folder / "res_self"
    # The tracks without the plane are the ones the correction starts from: found in the cache, as on a rerun.
    shutil.copytree(oblique.folder / "res_image" / ".cache", out / ".cache")
    code, _, err = _run(capsys, "identify", toml, "--out", out, "--workers", 1, "--quiet", "--self-calibrate-plane")
    assert code == 0, err
    result = json.loads((out / "result.json").read_text())
    true = oblique.truth["model"]["gain"]
    low, high = result["model"]["ci95"]["gain"]
    assert low <= true <= high
    assert abs(result["model"]["gain"] / true - 1.0) < 0.5 * abs(oblique.image["model"]["gain"] / true - 1.0)
    assert result["plane"]["source"].startswith("self-calibrated")
    # Refused beside a plane: one line, exit 2, nothing written.
    code, _, err = _run(capsys, "identify", oblique.folder / "campaign.toml", "--out", oblique.folder / "res_both",
                        "--self-calibrate-plane")
    assert code == 2 and err.count("\n") == 1 and err.startswith("servoscope: error:")
    assert not (oblique.folder / "res_both").exists()
