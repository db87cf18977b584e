"""Failures that looked like success or ended in a traceback (issue 28).

Each test reproduces one item of the issue through the command line, in-process
(``tactile_sl_decoder.cli.main``): before the fix it printed a traceback or exited 0 having
produced nothing asked for; now it is one clear line and a failing exit status.
"""
from __future__ import annotations

from pathlib import Path

import pytest
from test_safe_outputs import IMAGE_TOPICS, SOURCE_BAG, run_cli, small_bag

from tactile_sl_decoder.cli import main


def _sensor(path: Path, thickness: float) -> Path:
    path.write_text("tactile_sl_sensor: 1\n"
                    f"elastomer: {{youngs_modulus: 3.0e+5, poisson_ratio: 0.49, "
                    f"thickness: {thickness}}}\npad_frame: tactile_pad\n")
    return path


def test_replay_with_a_layer_too_thin_to_model_is_one_line(tmp_path, capsys):
    """Item 3: thickness 1e-5 m ended in a numpy.linalg.LinAlgError traceback."""
    bag = small_bag(tmp_path / "in.mcap", frames=1)
    sensor = _sensor(tmp_path / "thin.yaml", 1e-5)
    rc, err = run_cli(capsys, "replay", bag, "-o", tmp_path / "out.mcap", "--sensor", sensor,
                      "--no-progress")
    assert rc == 1 and "thin.yaml" in err and "quarter of the cell pitch" in err, err
    assert not (tmp_path / "out.mcap").exists()


def _bag_with_bad_images(path: Path, kind: str, bad_frames: set[int], frames: int = 2) -> Path:
    """The first ``frames`` frames of a shipped bag (with ground truth); ``bad_frames`` get
    images of another ``kind``: 320x240 against the 640x480 CameraInfo, mono16 or yuv422."""
    import cv2
    import numpy as np

    from tactile_sl_common.bag_io import BagReader, BagWriter
    from tactile_sl_common.images import image_to_array

    topics = IMAGE_TOPICS + ["/tactile/ground_truth/points"]
    stamps: list[int] = []
    with BagWriter(path) as out:
        for raw, msg in BagReader(SOURCE_BAG).messages(topics):
            if raw.log_time_ns not in stamps:
                if len(stamps) == frames:
                    break
                stamps.append(raw.log_time_ns)
            if not raw.topic.endswith("image_raw") or len(stamps) - 1 not in bad_frames:
                out.write_raw(raw.topic, raw.schema_name, raw.data, raw.log_time_ns)
                continue
            pixels = image_to_array(msg)
            header = {"stamp": {"sec": msg.header.stamp.sec,
                                "nanosec": msg.header.stamp.nanosec},
                      "frame_id": msg.header.frame_id}
            if kind == "320x240":
                small = cv2.resize(pixels, (320, 240))
                fields = {"height": 240, "width": 320, "encoding": "mono8", "step": 320,
                          "data": small.tobytes()}
            else:
                data = ((pixels.astype("<u2") << 8).tobytes() if kind == "mono16"
                        else np.repeat(pixels, 2).tobytes())
                fields = {"height": msg.height, "width": msg.width, "encoding": kind,
                          "step": 2 * msg.width, "data": data}
            out.write(raw.topic, raw.schema_name,
                      {"header": header, "is_bigendian": 0, **fields}, raw.log_time_ns)
    return path


@pytest.mark.parametrize("kind, why", [
    ("320x240", "left image is 320x240 but its CameraInfo says 640x480"),
    ("mono16", "unsupported image encoding 'mono16'"),
    ("yuv422", "unsupported image encoding 'yuv422'")])
def test_evaluate_skips_unusable_frames_and_fails_when_nothing_is_left(tmp_path, capsys,
                                                                         kind, why):
    """Item 5: PipelineInputError / ImageFormatError tracebacks (exit 0 after them)."""
    bag = _bag_with_bad_images(tmp_path / f"{kind}.mcap", kind, {0, 1})
    rc, err = run_cli(capsys, "evaluate", bag, "--totals-only")
    assert rc == 1 and err.count(why) == 2 and "nothing was evaluated" in err, err


def test_evaluate_reports_the_frames_it_could_use(tmp_path, capsys):
    bag = _bag_with_bad_images(tmp_path / "mixed.mcap", "mono16", {1})
    try:
        rc = main(["evaluate", str(bag), "--totals-only"])
    finally:
        out, err = capsys.readouterr()
    assert rc == 0 and "Traceback" not in err
    assert err.count("skipped: unsupported image encoding 'mono16'") == 1
    assert "1 frame(s) skipped" in err and "mixed" in out


def test_replay_that_writes_no_cloud_fails(tmp_path, capsys):
    """Item 11: every frame skipped (an encoding it cannot read) said '0 clouds written',
    exit 0, and left an empty bag."""
    bag = _bag_with_bad_images(tmp_path / "mono16.mcap", "mono16", {0, 1})
    out = tmp_path / "out.mcap"
    rc, err = run_cli(capsys, "replay", bag, "-o", out, "--no-progress")
    assert rc == 1 and "no point cloud from any of the 2 stereo frame(s)" in err, err
    assert "2 skipped" in err and not out.exists()


def test_replay_whose_reference_takes_every_frame_fails(tmp_path, capsys):
    """Item 11: --reference-frames 99 on a short bag said 'touch outputs for 0 frames', exit
    0; refused before any work now, and a reference that no frame follows fails the run."""
    bag = small_bag(tmp_path / "in.mcap", frames=2)
    out = tmp_path / "out.mcap"
    rc, err = run_cli(capsys, "replay", bag, "-o", out, "--reference-frames", "99",
                      "--no-progress")
    assert rc == 1 and "has 2 stereo frame(s)" in err and not out.exists(), err
    gap = _bag_with_bad_images(tmp_path / "gap.mcap", "mono16", {2}, frames=3)
    rc, err = run_cli(capsys, "replay", gap, "-o", out, "--reference-frames", "2",
                      "--no-progress")
    assert rc == 1 and "no touch output" in err and not out.exists(), err
    rc, err = run_cli(capsys, "replay", gap, "-o", out, "--reference-frames", "2",
                      "--no-touch", "--no-progress")
    assert rc == 0 and out.exists()


def test_replay_warns_when_the_reference_was_pressed(tmp_path, capsys):
    """Item 8: a reference taken while 2 N pressed (190 um RMS fit residual) was accepted
    quietly, and every later wrench was off by the load."""
    from tactile_sl_decoder.tooling.touch_soak import write_phase_bag

    from ros_harness import BAGS

    bag = tmp_path / "pressed_first.mcap"
    write_phase_bag(BAGS / "touch_halfspace.mcap", bag, untouched=[3], pressed=[0],
                    untouched_frames=1, pressed_frames=1)
    rc, err = run_cli(capsys, "replay", bag, "-o", tmp_path / "out.mcap", "--no-progress")
    assert rc == 0 and "WARNING: reference at frame" in err, err
    assert "touched when the reference was taken" in err
    untouched = tmp_path / "untouched_first.mcap"
    write_phase_bag(BAGS / "touch_halfspace.mcap", untouched, untouched=[0], pressed=[3],
                    untouched_frames=1, pressed_frames=1)
    rc, err = run_cli(capsys, "replay", untouched, "-o", tmp_path / "out2.mcap",
                      "--no-progress")
    assert rc == 0 and "WARNING" not in err, err
