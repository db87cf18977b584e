"""Force calibration recovers the modulus from known loads; bad input writes nothing."""

import os

import numpy as np
import pytest
from test_touch_traction import PITCH, SHAPE, _displacement

from tactile_sl_common.clouds import pack_points
from tactile_sl_common.elasticity import Elastomer
from tactile_sl_decoder.cli import main as cli_main
from tactile_sl_decoder.touch.force_calibration import (
    ForceCalibrationError,
    KnownLoad,
    calibrate_forces,
    load_loads_file,
)
from tactile_sl_decoder.touch.reference import nominal_positions
from tactile_sl_decoder.touch.sensor import SensorConfig, load_sensor

from ros_harness import REPO

BAG = REPO / "bags" / "touch_calibration.mcap"
LOADS = (0.1, 0.3, 0.6, 1.0, 1.5)        # bags/touch_scenes.yaml, touch_calibration


def _frames(true, loads, rng):
    rows, cols = np.divmod(np.arange(SHAPE[0] * SHAPE[1]), SHAPE[1])
    rest = nominal_positions(rows, cols, SHAPE, PITCH) + [0.0, 0.0, 0.015]
    out = [pack_points(rest + _displacement(true, [], 2e-6, rng), rows, cols)]
    for f in loads:
        disp = _displacement(true, [(0.0, 0.0, -f, 3e-3, 0.0, 0.0)], 2e-6, rng)
        out.append(pack_points(rest + disp, rows, cols))
    return out


def test_modulus_from_synthetic_loads():
    true = Elastomer(4.2e5, 0.49, 0.0)
    frames = _frames(true, LOADS, np.random.default_rng(2))
    start = SensorConfig(Elastomer(1e5, 0.49, 0.0))
    fit = calibrate_forces(frames, [KnownLoad(i + 1, f) for i, f in enumerate(LOADS)], start,
                           SHAPE, PITCH)
    assert abs(fit.sensor.elastomer.youngs_modulus / 4.2e5 - 1) < 0.02
    assert fit.rms_error < 0.02 and "RMS error" in fit.report()


def test_degenerate_loads_are_refused():
    start = SensorConfig(Elastomer(1e5, 0.49, 0.0))
    with pytest.raises(ForceCalibrationError, match="at least"):
        calibrate_forces([], [KnownLoad(1, 1.0)], start, SHAPE, PITCH)
    with pytest.raises(ForceCalibrationError, match="all equal"):
        calibrate_forces([], [KnownLoad(1, 1.0), KnownLoad(2, 1.0)], start, SHAPE, PITCH)
    frames = _frames(Elastomer(3e5, 0.49, 0.0), (0.5,), np.random.default_rng(3))
    with pytest.raises(ForceCalibrationError, match="no decoded frame"):
        calibrate_forces(frames, [KnownLoad(1, 0.5), KnownLoad(7, 1.0)], start, SHAPE, PITCH)
    with pytest.raises(ForceCalibrationError, match="reference"):
        calibrate_forces(frames, [KnownLoad(0, 0.5), KnownLoad(1, 1.0)], start, SHAPE, PITCH)


@pytest.mark.parametrize("text, words", [
    ("loads: [{frame: 1, normal_force: 0.1}]", "at least"),
    ("loads: [{frame: 1, normal_force: -0.1}, {frame: 2, normal_force: 1}]", "pressing"),
    ("loads: [{frame: 1}, {frame: 2, normal_force: 1}]", "normal_force"),
    ("loads: [{frame: 1, normal_force: 1}, {frame: 1, normal_force: 2}]", "twice"),
    ("[1, 2]", "mapping"),
])
def test_bad_loads_files(tmp_path, text, words):
    path = tmp_path / "loads.yaml"
    path.write_text(text)
    with pytest.raises(ForceCalibrationError, match=words):
        load_loads_file(path)


@pytest.mark.slow
def test_cli_recovers_the_bag_modulus_within_5_percent(tmp_path):
    loads = tmp_path / "loads.yaml"
    loads.write_text("loads:\n" + "".join(f"  - {{frame: {i + 1}, normal_force: {f}}}\n"
                                          for i, f in enumerate(LOADS)))
    start = tmp_path / "start.yaml"
    start.write_text("tactile_sl_sensor: 1\nelastomer: {youngs_modulus: 1.0e+5, "
                     "poisson_ratio: 0.49, thickness: 0.0}\n")
    out = tmp_path / "out"
    umask = os.umask(0o022)
    try:
        assert cli_main(["calibrate", "--bag", str(BAG), "--loads", str(loads), "--sensor",
                         str(start), "-o", str(out)]) == 0
    finally:
        os.umask(umask)
    fitted = load_sensor(out / "sensor.yaml").elastomer.youngs_modulus
    assert abs(fitted / 3.0e5 - 1) < 0.05          # the scene's true modulus
    # issue 28, item 6: readable by the robot's other users (it was 0600, the temp file's)
    assert (out / "sensor.yaml").stat().st_mode & 0o777 == 0o644
    # a bad loads file: one clear error, nothing written
    bad_out = tmp_path / "bad"
    loads.write_text("loads: [{frame: 1, normal_force: 0.1}]")
    assert cli_main(["calibrate", "--bag", str(BAG), "--loads", str(loads), "-o",
                     str(bad_out)]) == 1
    assert not (bad_out / "sensor.yaml").exists()
