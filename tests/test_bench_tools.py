"""The benchmark scripts still run (figures are not checked: they are machine-dependent).

They are scripts started as processes, so this lives with the process tests (no ROS graph:
the in-process benchmark only).
"""
import subprocess
import sys

import pytest

from ros_harness import REPO, next_domain_id, ros_env

pytestmark = [pytest.mark.ros, pytest.mark.slow]


def test_bench_pipeline_in_process_runs_with_floor_touch_and_both_carry_settings():
    """A short in-process run on one bag: every section is printed (a renamed attribute
    once broke the floor's touch products and with them `make bench`)."""
    out = subprocess.run(
        [sys.executable, str(REPO / "tools" / "bench_pipeline.py"),
         str(REPO / "bags" / "no_contact.mcap"), "--repeat", "1", "--warmup", "0",
         "--carry", "both"],
        capture_output=True, text=True, timeout=300, env=ros_env(next_domain_id()))
    assert out.returncode == 0, out.stderr[-3000:]
    for section in ("labels carried from the previous frame: on",
                    "labels carried from the previous frame: off",
                    "floor, serial", "floor, parallel", "touch mat-vec",
                    "total+touch  / floor serial", "accuracy, carry on", "accuracy, carry off"):
        assert section in out.stdout, section
    assert "no_contact" in out.stdout
    assert "\nslip " in out.stdout                   # the slip estimate's part of touch


def test_bench_touch_prints_the_slip_table_and_times():
    """The touch bags, one slip scene and the lighting scenes (rendered on the fly): the
    slip table with its acceptance lines, the lighting table with its per-draw rows and the
    slip estimate's time beside the pipeline's (the shape scenes' table: test_touch_metrics)."""
    out = subprocess.run(
        [sys.executable, str(REPO / "tools" / "bench_touch.py"), "--repeat", "1",
         "--only", "slip_halfspace", "--no-shapes", "--per-draw"],
        capture_output=True, text=True, timeout=300, env=ros_env(next_domain_id()))
    assert out.returncode == 0, out.stderr[-3000:]
    for section in ("slip_halfspace", "gross slip:", "slip margin |error|",
                    "friction coefficient |error|", "of which slip", "pipeline (total)",
                    "light_harsh_mjpeg", "dCen worst mm",      # the lighting table
                    "per draw: signed normal force error %", "columns: the file's draw"):
        assert section in out.stdout, section
    # --per-draw: each loaded frame of each lighting scene, the file's one draw
    assert out.stdout.count("  Fn  0.10 N  dFn %") == 3, out.stdout[-3000:]


def test_bench_sweep_runs_a_row_writes_its_figures_and_its_picture(tmp_path):
    """One sweep row of one frame: the JSON figures and the picture of both images (the
    sweep is only run by `make bench` otherwise)."""
    import json

    import cv2

    out = subprocess.run(
        [sys.executable, str(REPO / "tools" / "bench_sweep.py"), "--only", "jpeg",
         "--levels", "mild", "--frames", "1", "--no-write", "--json", str(tmp_path / "f.json"),
         "--pictures", str(tmp_path), "--picture-rows", "jpeg", "--bound"],
        capture_output=True, text=True, timeout=300, env=ros_env(next_domain_id()))
    assert out.returncode == 0, out.stderr[-3000:]
    assert "| jpeg | mild |" in out.stdout
    (row,) = json.loads((tmp_path / "f.json").read_text())
    assert row["nuisance"] == "jpeg" and row["visible"] > 500
    assert row["wrong"] == 0 and row["coverage"] > 0.99      # mild MJPEG: nearly all
    img = cv2.imread(str(tmp_path / "jpeg_mild.png"))
    assert img.shape == (480, 1280, 3)
    # green marks (measured glyphs) on both halves
    green = (img[:, :, 1] == 200) & (img[:, :, 0] == 0) & (img[:, :, 2] == 0)
    assert green[:, :640].sum() > 1000 and green[:, 640:].sum() > 1000
    # --bound: the Cramer-Rao bound, below what the decoder reaches, its column and picture
    assert "| CRLB, best 97 % |" in out.stdout
    assert 0 < row["bound_best_m"] <= row["bound_all_m"] < row["rmse_m"]
    # the efficiency: RMSE over the bound of the share of glyphs the decoder kept
    assert row["bound_best_m"] <= row["bound_kept_m"] <= row["bound_all_m"]
    assert row["efficiency"] == pytest.approx(row["rmse_m"] / row["bound_kept_m"])
    assert "| RMSE / CRLB (kept share) |" in out.stdout
    assert cv2.imread(str(tmp_path / "jpeg_mild_bound.png")).shape == (520, 1280, 3)


def test_bench_touch_bound_needs_five_lighting_draws():
    """--bound takes each cell's noise from the draws' scatter: refused (exit 2, before any
    rendering) without five or more seeds (fewer: each cell's variance is too uncertain to
    invert)."""
    for extra in ([], ["--light-seeds", "11", "12", "13", "14"],
                  ["--no-light", "--light-seeds", "1", "2", "3", "4", "5"]):
        out = subprocess.run(
            [sys.executable, str(REPO / "tools" / "bench_touch.py"), "--bound", *extra],
            capture_output=True, text=True, timeout=120, env=ros_env(next_domain_id()))
        assert out.returncode == 2, out.stderr[-2000:]
        assert "--bound needs the lighting scenes with --light-seeds of 5 or more" in out.stderr
    out = subprocess.run(
        [sys.executable, str(REPO / "tools" / "bench_touch.py"), "--bound-pictures", "pics"],
        capture_output=True, text=True, timeout=120, env=ros_env(next_domain_id()))
    assert out.returncode == 2 and "--bound-pictures needs --bound" in out.stderr
