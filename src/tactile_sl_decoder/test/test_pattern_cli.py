"""`tactile-sl pattern ...`: exit codes, reproducibility, outputs."""
from __future__ import annotations

from pathlib import Path

import yaml

from tactile_sl_decoder.cli import main
from tactile_sl_decoder.pattern import default_pattern_path, load_pattern

GEN = ["pattern", "generate", "--symbols", "3", "--window", "3x3", "--min-hamming", "3", "-q"]


def test_verify_exit_codes(tmp_path, capsys):
    assert main(["pattern", "verify", str(default_pattern_path())]) == 0
    assert "VALID" in capsys.readouterr().out
    doc = yaml.safe_load(default_pattern_path().read_text())
    rows = doc["array"]
    rows[10] = rows[10][:5] + rows[0][:3] + rows[10][8:]
    rows[11] = rows[11][:5] + rows[1][:3] + rows[11][8:]
    rows[12] = rows[12][:5] + rows[2][:3] + rows[12][8:]
    bad = tmp_path / "dup.yaml"
    bad.write_text(yaml.safe_dump(doc))
    assert main(["pattern", "verify", str(bad)]) == 1
    assert "INVALID" in capsys.readouterr().err
    doc["array"][3] = doc["array"][3][:-1]
    ragged = tmp_path / "ragged.yaml"
    ragged.write_text(yaml.safe_dump(doc))
    assert main(["pattern", "verify", str(ragged)]) == 2
    assert "ragged" in capsys.readouterr().err


def test_generate_is_reproducible(tmp_path):
    a, b = tmp_path / "a.yaml", tmp_path / "b.yaml"
    for out in (a, b):
        assert main(GEN + ["--size", "14x13", "--algorithm", "dfs", "--seed", "5",
                           "-o", str(out)]) == 0
    pa, pb = load_pattern(a), load_pattern(b)
    assert (pa.array == pb.array).all()
    assert pa.extra["generator"]["algorithm"] == "dfs"
    assert main(["pattern", "verify", "-q", str(a)]) == 0


def test_generate_failure_exits_non_zero(tmp_path, capsys):
    out = tmp_path / "x.yaml"
    code = main(GEN + ["--size", "29x29", "--algorithm", "fill-and-test", "--time-limit",
                       "0.3", "-o", str(out)])
    assert code == 1
    assert "time limit" in capsys.readouterr().err
    assert not out.exists()


def test_bound_mentions_known_code_and_42x42(capsys):
    assert main(["pattern", "bound", "--symbols", "3", "--window", "3x3",
                 "--min-hamming", "3"]) == 0
    out = capsys.readouterr().out
    assert "1035" in out and "729 <= A <= 937" in out and "impossible" in out


def test_render_writes_svg_png_and_sidecar(tmp_path):
    svg, png = tmp_path / "a.svg", tmp_path / "a.png"
    assert main(["pattern", "render", str(default_pattern_path()), "--svg", str(svg),
                 "--png", str(png), "--dpi", "600"]) == 0
    assert svg.exists() and png.exists() and Path(str(png) + ".yaml").exists()
    assert main(["pattern", "render", str(default_pattern_path())]) == 2
    assert main(["pattern", "render", str(default_pattern_path()), "--png", str(png)]) == 2


def test_bad_arguments(capsys):
    assert main(GEN + ["--size", "10x10", "--algorithm", "linear", "-o", "/dev/null",
                       "--symbols", "9"]) == 2
    assert "symbols must be in 2..8" in capsys.readouterr().err
