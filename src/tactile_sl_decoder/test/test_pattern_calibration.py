"""Calibration with the printed pattern as target, its health check, and bad input.

Views are rendered by the simulator (flat artwork at known poses, 30 % hidden, blur and
noise) with supersampling off to keep the suite fast; the true calibration is the rig's.
"""
import argparse
import os
import pathlib

import cv2
import numpy as np
import pytest

from tactile_sl_common.camera_info import (
    CameraCalibration,
    load_camera_info_yaml,
    save_camera_info_yaml,
)
from tactile_sl_decoder.calibrate import (
    CalibrationOptions,
    PatternTarget,
    ViewDecoder,
    calibrate_pattern_stereo,
)
from tactile_sl_decoder.calibrate.health import calibration_health, refine_extrinsics
from tactile_sl_decoder.calibrate.simulate import (
    PlanePose,
    artwork_of,
    random_poses,
    render_pattern_views,
    simulated_board_views,
    write_untouched_bag,
    write_views,
)
from tactile_sl_decoder.cli import calibrate_cmd
from tactile_sl_decoder.stereo.stereo import StereoRig
from tactile_sl_sim.artwork import Artwork, draw_artwork, random_values
from tactile_sl_sim.render import Renderer

# Renders and calibrates from simulated views (seconds per fixture): `make test`, not
# `make unit`.
pytestmark = pytest.mark.slow


def _cli(*argv):
    parser = argparse.ArgumentParser()
    calibrate_cmd.register(parser.add_subparsers())
    args = parser.parse_args(["calibrate", *map(str, argv)])
    return args.func(args)


@pytest.fixture(scope="module")
def artwork():
    return artwork_of()


@pytest.fixture(scope="module")
def renderer(artwork):
    return Renderer(artwork, supersample=1)


@pytest.fixture(scope="module")
def target():
    return PatternTarget.load()


@pytest.fixture(scope="module")
def decoder(target):
    d = ViewDecoder(target)
    yield d
    d.close()


@pytest.fixture(scope="module")
def view_dir(tmp_path_factory, renderer, artwork):
    """Seven simulated view pairs of the pattern (30 % hidden each) and the truth."""
    poses = random_poses(7, artwork, seed=3, hide_fraction=0.3)
    views = render_pattern_views(renderer, artwork, poses, seed=3)
    return write_views(tmp_path_factory.mktemp("views"), views, renderer, poses)


@pytest.fixture(scope="module")
def calibrated(view_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("calib")
    assert _cli("--folder", view_dir, "--target", "-o", out) == 0
    return out


def _bad_rig(rig, rotate_deg=(0.0, 0.0, 0.0), focal=(1.0, 1.0)):
    """Calibration files of the simulator's rig with the right camera turned / a focal off."""
    K1 = rig.left.K.copy()
    K1[0, 0] *= focal[0]
    K1[1, 1] *= focal[1]
    dR = cv2.Rodrigues(np.radians(np.asarray(rotate_deg, float)))[0]
    R, T = dR @ rig.R, dR @ rig.T
    R1, R2, P1, P2, *_ = cv2.stereoRectify(K1, rig.left.D, rig.right.K, rig.right.D, (640, 480),
                                           R, T.reshape(3, 1), flags=cv2.CALIB_ZERO_DISPARITY,
                                           alpha=0.0)
    return (CameraCalibration(640, 480, K1, rig.left.D, R1, P1, camera_name="tactile_left"),
            CameraCalibration(640, 480, rig.right.K, rig.right.D, R2, P2,
                              camera_name="tactile_right"))


def _assert_no_yaml(out: pathlib.Path):
    assert not list(out.glob("*.yaml")) and not list(out.glob(".*tmp")), list(out.iterdir())


# --------------------------------------------------------------------------- calibration


def test_pattern_calibration_recovers_the_truth(calibrated, view_dir, renderer):
    left = load_camera_info_yaml(calibrated / "left.yaml")
    right = load_camera_info_yaml(calibrated / "right.yaml")
    rig = renderer.rig
    for est, true in ((left, rig.left), (right, rig.right)):
        assert est.K[0, 0] == pytest.approx(true.K[0, 0], rel=0.002)
        assert est.K[1, 1] == pytest.approx(true.K[1, 1], rel=0.002)
        assert np.abs(est.K[:2, 2] - true.K[:2, 2]).max() < 0.5
    baseline = -right.P[0, 3] / right.P[0, 0]
    assert baseline == pytest.approx(np.linalg.norm(rig.T), rel=0.002)
    assert (calibrated / "coverage.png").is_file()
    assert cv2.imread(str(calibrated / "coverage.png")).shape[1] > 640


def test_reprojection_and_per_view_report(view_dir, target, decoder, renderer):
    views = [decoder.decode(cv2.imread(str(view_dir / f"left_{i:03d}.png"), 0),
                            cv2.imread(str(view_dir / f"right_{i:03d}.png"), 0), f"{i:03d}")
             for i in range(7)]
    cal = calibrate_pattern_stereo(views, target)
    assert cal.result.rms_stereo <= 0.1
    assert len(cal.views) == 7 and all(v.cells_stereo > 100 for v in cal.views)
    assert "view 000: cells L" in cal.report()
    # a view with too few cells is skipped and said so; the rest still calibrates
    empty = type(views[0].left)(np.zeros(0, np.int32), np.zeros(0, np.int32), np.zeros((0, 2)))
    views.append(type(views[0])("blank", empty, empty, views[0].image_size))
    cal = calibrate_pattern_stereo(views, target)
    assert "view blank" in cal.report() and "skipped: left: 0 cells decoded" in cal.report()


def test_checkerboard_mode_of_the_cli_still_works(tmp_path, capsys):
    blank = Artwork(np.ones((8, 8), np.float32), (3.5, 3.5), 4.0, 0.0005, 1, 1)
    views = simulated_board_views(Renderer(blank, supersample=1), (9, 6), 0.001, views=6, seed=1)
    for i, (left, right) in enumerate(views):
        cv2.imwrite(str(tmp_path / f"left_{i:03d}.png"), left)
        cv2.imwrite(str(tmp_path / f"right_{i:03d}.png"), right)
    out = tmp_path / "calib"
    assert _cli("--folder", tmp_path, "--pattern", "9x6", "--square", "0.001", "-o", out) == 0
    right = load_camera_info_yaml(out / "right.yaml")
    assert -right.P[0, 3] / right.P[0, 0] == pytest.approx(0.004, rel=0.01)
    # the wrong pattern size finds no board: a clear failure, not a crash
    assert _cli("--folder", tmp_path, "--pattern", "7x7", "-o", tmp_path / "none") == 1
    assert "checkerboard was found" in capsys.readouterr().err


# --------------------------------------------------------------------------- health


@pytest.fixture(scope="module")
def untouched_bag(tmp_path_factory, renderer):
    return write_untouched_bag(tmp_path_factory.mktemp("bag") / "rest.mcap", renderer, frames=1)


@pytest.mark.parametrize("case", ["truth", "right turned 0.2 deg about x",
                                  "right turned 0.2 deg about y",
                                  "right turned 0.2 deg about z", "left fx off 1 %",
                                  "left fx and fy off 1 %", "swapped files"])
def test_check_passes_the_truth_and_flags_bad_calibrations(case, untouched_bag, renderer,
                                                           tmp_path, capsys):
    rig = renderer.rig
    files = {"truth": (rig.left_info, rig.right_info),
             "swapped files": (rig.right_info, rig.left_info),
             "left fx off 1 %": _bad_rig(rig, focal=(1.01, 1.0)),
             "left fx and fy off 1 %": _bad_rig(rig, focal=(1.01, 1.01))}
    for axis in range(3):
        rot = [0.0, 0.0, 0.0]
        rot[axis] = 0.2
        files[f"right turned 0.2 deg about {'xyz'[axis]}"] = _bad_rig(rig, tuple(rot))
    left, right = files[case]
    save_camera_info_yaml(tmp_path / "left.yaml", left)
    save_camera_info_yaml(tmp_path / "right.yaml", right)
    rc = _cli("--check", untouched_bag, "--calibration", tmp_path, "--target")
    out = capsys.readouterr().out
    assert ("verdict: PASS" in out) == (case == "truth"), out
    assert rc == (0 if case == "truth" else 1)
    if case == "swapped files":
        assert "swapped" in out


def test_health_library_and_refinement_in_place(untouched_bag, renderer, target, decoder):
    frame = renderer.render([], seed=1)
    gl, gr = decoder.decode_glyphs(frame.left, frame.right)
    rig = renderer.rig
    assert calibration_health(gl, gr, StereoRig(rig.left_info, rig.right_info), target).ok
    knocked = _bad_rig(rig, (0.2, 0.0, 0.0))
    report = calibration_health(gl, gr, StereoRig(*knocked), target)
    assert not report.ok and report.reprojection_rms_px > 0.5
    assert set(report.as_dict()) >= {"reprojection_rms_px", "flatness_rms_m", "pitch_error"}
    view = decoder.decode(frame.left, frame.right)
    refined = refine_extrinsics([view], *knocked, target)
    assert calibration_health(gl, gr, StereoRig(refined.left, refined.right), target).ok
    assert np.linalg.norm(refined.T) == pytest.approx(np.linalg.norm(rig.T), rel=0.003)


# --------------------------------------------------------------------------- bad input


def _write(views, folder):
    folder.mkdir(parents=True, exist_ok=True)
    for i, (left, right) in enumerate(views):
        cv2.imwrite(str(folder / f"left_{i:03d}.png"), left)
        cv2.imwrite(str(folder / f"right_{i:03d}.png"), right)
    return folder


def _bad(folder, out, capsys, *extra):
    rc = _cli("--folder", folder, "--target", "-o", out, *extra)
    err = capsys.readouterr().err
    assert rc == 1
    _assert_no_yaml(out) if out.exists() else None
    return err


def test_views_of_another_pattern_are_refused(tmp_path, renderer, capsys):
    png, meta = draw_artwork(random_values(30, 28, seed=5), pitch_px=40)
    other = Artwork(png.astype(np.float32) / 255, tuple(meta["cell00_px"]), 40.0, 0.0005, 30, 28)
    poses = random_poses(4, other, seed=4)
    views = render_pattern_views(Renderer(other, supersample=1), other, poses)
    folder = _write(views, tmp_path / "v")
    err = _bad(folder, tmp_path / "out", capsys)
    assert "are these views of this pattern" in err


def test_mirrored_views_with_the_wrong_setting_are_refused(tmp_path, renderer, artwork, capsys):
    poses = random_poses(4, artwork, seed=6)
    folder = _write(render_pattern_views(renderer, artwork, poses, mirrored=True), tmp_path / "v")
    err = _bad(folder, tmp_path / "out", capsys)
    assert "mirrored=false" in err and "pass --mirrored" in err


def test_too_few_views_are_refused(tmp_path, view_dir, capsys):
    folder = tmp_path / "v"
    folder.mkdir()
    for name in ("left_000.png", "right_000.png", "left_001.png", "right_001.png"):
        (folder / name).write_bytes((view_dir / name).read_bytes())
    err = _bad(folder, tmp_path / "out", capsys)
    assert "only 2 of 2 views are usable" in err and "need at least 4" in err


def test_views_all_at_one_pose_are_degenerate(tmp_path, renderer, artwork, capsys):
    pose = random_poses(1, artwork, seed=8, tilt_deg=(20.0, 20.0))[0]
    poses = [PlanePose(pose.R, pose.t) for _ in range(5)]
    folder = _write(render_pattern_views(renderer, artwork, poses, seed=9), tmp_path / "v")
    err = _bad(folder, tmp_path / "out", capsys)
    assert "degenerate" in err


def test_calibration_options_are_checked_for_view_count(target):
    with pytest.raises(Exception, match="no image pairs"):
        calibrate_pattern_stereo([], target, CalibrationOptions())


def test_refine_cli_repairs_a_knocked_camera(untouched_bag, renderer, tmp_path, capsys):
    knocked = _bad_rig(renderer.rig, (0.2, 0.0, 0.0))
    save_camera_info_yaml(tmp_path / "left.yaml", knocked[0])
    save_camera_info_yaml(tmp_path / "right.yaml", knocked[1])
    out = tmp_path / "refined"
    assert _cli("--refine", untouched_bag, "--calibration", tmp_path, "--target", "-o", out) == 0
    assert _cli("--check", untouched_bag, "--calibration", out, "--target") == 0
    assert "verdict: PASS" in capsys.readouterr().out


# --------------------------------------------------------------------------- outputs (issue 28)


@pytest.mark.parametrize("blocked, mode", [("right.yaml", "target"), ("coverage.png", "target"),
                                           ("right.yaml", "board")])
def test_outputs_are_written_all_or_none(view_dir, tmp_path, capsys, blocked, mode):
    """Item 6: with right.yaml (or coverage.png) a folder, left.yaml (and right.yaml) were
    written although the command failed; now it refuses before any work."""
    out = tmp_path / "out"
    (out / blocked).mkdir(parents=True)
    args = ["--target"] if mode == "target" else ["--pattern", "9x6"]
    assert _cli("--folder", view_dir, *args, "-o", out) == 1
    err = capsys.readouterr().err
    assert f"{out / blocked}: it exists and is not a regular file" in err, err
    assert sorted(p.name for p in out.iterdir()) == [blocked]


def test_outputs_are_readable_by_everyone_under_umask_022(view_dir, tmp_path):
    """Item 6: every output was created 0600 (its temporary file's mode)."""
    umask = os.umask(0o022)
    try:
        assert _cli("--folder", view_dir, "--target", "-o", tmp_path / "out") == 0
    finally:
        os.umask(umask)
    modes = {p.name: p.stat().st_mode & 0o777 for p in (tmp_path / "out").iterdir()}
    assert modes == {"left.yaml": 0o644, "right.yaml": 0o644, "coverage.png": 0o644}


def test_unpaired_images_are_named(view_dir, tmp_path, capsys):
    """Item 9: 6 left and 4 right images said 'pairs used 4/4' and nothing of the other two."""
    folder = tmp_path / "v"
    folder.mkdir()
    for i in range(6):
        for side in ("left", "right"):
            if side == "left" or i < 4:
                name = f"{side}_{i:03d}.png"
                (folder / name).write_bytes((view_dir / name).read_bytes())
    assert _cli("--folder", folder, "--target", "-o", tmp_path / "out") == 0
    err = capsys.readouterr().err
    assert "2 image(s) without a partner, not used: left_004.png, left_005.png" in err, err


def test_check_and_refine_take_the_calibration_files_for_a_bag_without_camera_info(
        untouched_bag, renderer, tmp_path, capsys):
    """Item 10: --check / --refine demanded the bag's camera_info topics although
    --calibration DIR (or --left-info / --right-info) gave the calibration."""
    from tactile_sl_common.bag_io import BagReader, BagWriter

    bag = tmp_path / "images_only.mcap"
    with BagWriter(bag) as out:
        for raw in BagReader(untouched_bag).raw_messages():
            if raw.topic.endswith("image_raw"):
                out.write_raw(raw.topic, raw.schema_name, raw.data, raw.log_time_ns)
    save_camera_info_yaml(tmp_path / "left.yaml", renderer.rig.left_info)
    save_camera_info_yaml(tmp_path / "right.yaml", renderer.rig.right_info)
    assert _cli("--check", bag, "--calibration", tmp_path, "--target") == 0
    assert _cli("--check", bag, "--left-info", tmp_path / "left.yaml", "--right-info",
                tmp_path / "right.yaml", "--target") == 0
    assert "verdict: PASS" in capsys.readouterr().out
    assert _cli("--refine", bag, "--calibration", tmp_path, "--target",
                "-o", tmp_path / "refined") == 0
    assert (tmp_path / "refined" / "right.yaml").is_file()
    assert _cli("--check", bag, "--target") == 1          # no calibration anywhere
    err = capsys.readouterr().err
    assert "camera_info" in err, err
