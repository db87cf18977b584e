"""Failures that looked like success or ended in a traceback (issue 28).

Each test reproduces one item of the issue through the command line, in-process
(``tactile_sl_decoder.cli.main``): before the fix it printed a traceback or exited 0 having
produced nothing asked for; now it is one clear line and a failing exit status.
"""
from __future__ import annotations

from pathlib import Path

from test_safe_outputs import run_cli, small_bag


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
