"""Touch figures (tactile_sl_decoder.tooling.touch_metrics): metrics with known errors, pictures
(tooling.pictures), and the `tactile-sl evaluate` touch section on a bundled touch bag."""
import argparse
import json
import shutil

import numpy as np
import pytest

from tactile_sl_common.clouds import pack_field
from tactile_sl_decoder.cli.evaluate_cmd import touch_section
from tactile_sl_decoder.tooling.pictures import render_depth, render_pressure
from tactile_sl_decoder.tooling.touch_metrics import (
    CHECKS,
    bag_totals,
    compare_frame,
    displacement_rmse,
    format_report,
    format_shape_report,
    resolve_sensor,
    shape_checks,
)
from tactile_sl_decoder.touch.contact import ContactState
from tactile_sl_decoder.touch.stage import TouchResult
from tactile_sl_sim.loads import TouchTruth

from ros_harness import REPO

PITCH = 5e-4


def _grid(n=6):
    rows, cols = np.divmod(np.arange(n * n), n)
    rest = np.column_stack([(cols - (n - 1) / 2) * PITCH, (rows - (n - 1) / 2) * PITCH,
                            np.zeros(n * n)])
    return rows, cols, rest


def _truth(force=(0.1, 0.0, -1.0), mz=1e-3, area=4e-5, centroid=(1e-3, 0.0), depth=2e-4):
    rows, cols, rest = _grid()
    disp = np.zeros_like(rest)
    disp[:, 2] = -1e-4
    return TouchTruth(force=np.array(force), moment=np.array([0.0, 0.0, mz]),
                      in_contact=True, area=area, centroid=np.array([*centroid, 0.0]),
                      max_depth=depth, normal_force=-force[2], rows=rows, cols=cols,
                      position=rest + disp, displacement=disp)


def _result(truth, dforce=(0.0, 0.0, 0.0), dmz=0.0, darea=0.0, dcen=(0.0, 0.0), ddisp=0.0,
            ddepth=0.0, in_contact=True, drop=0):
    keep = slice(drop, None)
    rows, cols = truth.rows[keep], truth.cols[keep]
    disp = truth.displacement[keep] + np.array([ddisp, 0.0, 0.0])
    contact = ContactState(in_contact=in_contact, area=truth.area + darea,
                           centroid=(truth.centroid[0] + dcen[0], truth.centroid[1] + dcen[1],
                                     0.0), max_depth=truth.max_depth + ddepth)
    force = np.zeros((len(rows), 3))
    force[:, 2] = (truth.force[2] + dforce[2]) / len(rows)
    return TouchResult(rows, cols, truth.position[keep], disp, lambda: force,
                       np.asarray(truth.force) + dforce,
                       np.array([0.0, 0.0, truth.moment[2] + dmz]), contact.in_contact,
                       lambda: contact, np.zeros((5, 5)), lambda indent: indent)


def test_displacement_rmse_matches_cells_by_row_and_col():
    rows, cols, rest = _grid()
    order = np.random.default_rng(0).permutation(len(rows))
    est = rest + np.array([3e-6, 0.0, 4e-6])               # 5 um everywhere
    rmse, n = displacement_rmse(rows[order][3:], cols[order][3:], est[order][3:],
                                rows[:-2], cols[:-2], rest[:-2])
    assert n == len(set(order[3:]) & set(range(len(rows) - 2)))
    assert rmse == pytest.approx(5e-6)
    assert np.isnan(displacement_rmse(rows[:0], cols[:0], rest[:0], rows, cols, rest)[0])


def test_known_errors_and_limits():
    truth = _truth()
    m = compare_frame(_result(truth, dforce=(0.003, 0.004, -0.03), dmz=5e-5, darea=4e-6,
                              dcen=(6e-5, 8e-5), ddisp=2e-6, ddepth=-1e-5, drop=4), truth)
    assert m.cells == 32 and m.disp_rmse == pytest.approx(2e-6)
    assert m.normal_err == pytest.approx(0.03) and m.normal_err_pct == pytest.approx(3.0)
    assert m.tangential_err == pytest.approx(0.005)
    assert m.tangential_err_pct == pytest.approx(5.0)
    assert m.moment_z_err_pct == pytest.approx(5.0)
    assert m.centroid_err == pytest.approx(1e-4)
    assert m.area_err_pct == pytest.approx(10.0)
    assert m.depth_err == pytest.approx(-1e-5)
    assert m.passed, m.failed()
    bad = compare_frame(_result(truth, dforce=(0.0, 0.0, -0.06), dmz=2e-4, darea=8e-6,
                                dcen=(2e-4, 0.0), ddisp=6e-6), truth)
    assert set(bad.failed()) == {"disp", "normal", "moment_z", "centroid", "area"}
    # 5 % + 5 mN: 1 N may be off by 55 mN, not by 56 mN
    assert compare_frame(_result(truth, dforce=(0, 0, -0.0549)), truth).checks()["normal"]
    assert not compare_frame(_result(truth, dforce=(0, 0, -0.0551)), truth).checks()["normal"]


def test_shape_limits_and_report():
    """Issue 25's indenter limits: area within 15 %, largest indentation within 10 um."""
    truth = _truth()
    good = compare_frame(_result(truth, darea=0.14 * truth.area, ddepth=-9.9e-6), truth)
    deep = compare_frame(_result(truth, darea=-0.16 * truth.area, ddepth=10.1e-6), truth)
    assert shape_checks(good) == [] and shape_checks(deep) == ["area", "depth"]
    text = format_shape_report([("shape_sphere_small", [good, deep])])
    assert "shape_sphere_small" in text and "FAIL area,depth" in text
    assert "|dDep|  10.1 um, 1/2 frames within the limits" in text


def test_in_contact_rules():
    truth = _truth()
    assert compare_frame(_result(truth, in_contact=False), truth).failed() == [
        "centroid", "area", "in_contact"]
    small = _truth(force=(0.0, 0.0, -0.015))             # below 20 mN: either answer is fine
    assert compare_frame(_result(small, in_contact=False), small).checks()["in_contact"] is None
    rest = _truth(force=(0.0, 0.0, 0.0), mz=0.0)
    rest.in_contact, rest.area = False, 0.0
    m = compare_frame(_result(rest, in_contact=True), rest)
    assert m.untouched and m.failed() == ["in_contact"]
    # control bags: no truth = untouched pad, zero displacement of every decoded cell
    control = compare_frame(_result(rest, in_contact=False, ddisp=3e-6), None)
    assert control.untouched and control.disp_rmse == pytest.approx(np.hypot(3e-6, 1e-4))
    assert control.failed() == ["disp"]                  # 100 um on an untouched pad
    # no touch output after the reference fails every check
    assert set(compare_frame(None, truth).failed()) == set(CHECKS)


def test_report_and_totals():
    truth = _truth()
    frames = [compare_frame(_result(truth, ddisp=d, dforce=(0, 0, f)), truth, "bag", i)
              for i, (d, f) in enumerate([(3e-6, 0.01), (4e-6, -0.2)])]
    t = bag_totals(frames, "bag")
    assert t["frames"] == 2 and t["passed"] == 1
    assert t["disp_rmse_m"] == pytest.approx(np.sqrt((9e-12 + 16e-12) / 2))
    assert t["normal_err_max_n"] == pytest.approx(0.2)
    assert t["failed_checks"]["normal"] == 1
    text, totals = format_report([("bag", "test sensor", frames)])
    assert "FAIL normal" in text and "all bags" in text and "normal 1" in text
    assert totals[-1]["bag"] == "all bags"
    json.dumps(totals)
    json.dumps([f.summary() for f in frames])


def test_pictures():
    rows, cols, rest = _grid(12)
    r = np.hypot(rest[:, 0], rest[:, 1])
    force = np.zeros_like(rest)
    force[:, 2] = -np.clip(1 - (r / 2e-3) ** 2, 0, None) * 1e-2
    force[:, 0] = 1e-3 * (r < 2e-3)
    field = pack_field(rest, np.zeros_like(rest), rows, cols, force)
    img = render_pressure(field, PITCH, "test")
    assert img.ndim == 3 and img.shape[2] == 3 and (img != 255).any()
    depth = np.full((45, 45), 1e-4, np.float32)
    depth[:5] = np.nan
    img = render_depth(depth, -2.75e-3, -2.75e-3, 1.25e-4)
    assert (img == 128).all(axis=2).any()                 # NaN drawn grey


def test_sensor_resolution(tmp_path):
    layer, where = resolve_sensor(REPO / "bags" / "touch_layer.mcap", None)
    assert layer.elastomer.thickness == pytest.approx(0.002) and "touch_scenes.yaml" in where
    copy = tmp_path / "touch_layer.mcap"
    shutil.copy(REPO / "bags" / "touch_layer.mcap", copy)
    shipped, where = resolve_sensor(copy, None)
    assert shipped.elastomer.thickness == 0.0 and "shipped" in where
    path = tmp_path / "s.yaml"
    path.write_text("tactile_sl_sensor: 1\nelastomer: {youngs_modulus: 2.0e+5, "
                    "poisson_ratio: 0.45, thickness: 0.001}\n")
    given, where = resolve_sensor(copy, path)
    assert given.elastomer.youngs_modulus == 2e5 and "--sensor" in where


@pytest.mark.slow
def test_evaluate_touch_section_on_a_touch_bag(tmp_path):
    bag = REPO / "bags" / "touch_calibration.mcap"
    args = argparse.Namespace(sensor=None, reference_frames=1, pattern=None, weights=None,
                              namespace="/tactile", max_frames=3, totals_only=False,
                              json=tmp_path / "ev.json")
    text = touch_section(args, [bag, REPO / "bags" / "no_contact.mcap"])
    assert "touch_calibration" in text and "no touch ground truth" in text
    doc = json.loads((tmp_path / "ev.touch.json").read_text())
    frames = doc["frames"]
    assert len(frames) == 2                                # frame 0 is the reference
    for f in frames:
        assert f["output"] and f["cells"] > 500
        assert f["disp_rmse_m"] < 10e-6
        assert abs(f["normal_err_n"]) < 0.05 and f["in_contact_est"]
    assert doc["bags"][0]["frames"] == 2 and doc["bags"][-1]["bag"] == "all bags"
