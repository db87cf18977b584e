"""Pattern YAML: round trip, and malformed files fail with a message naming the problem."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

from tactile_sl_decoder.pattern import (
    Constraints,
    Pattern,
    PatternFormatError,
    default_pattern_path,
    load_pattern,
    save_pattern,
)
from tactile_sl_decoder.pattern.fileio import dump_pattern


def good_doc() -> dict:
    return {
        "tactile_sl_pattern": 1, "symbols": 3, "window": [3, 3], "min_hamming": 1,
        "pitch_m": 0.0005, "primitives": ["line", "circle", "triangle"], "rows": 3, "cols": 4,
        "array": ["0120", "2011", "1202"],
    }


def write(tmp_path, doc) -> str:
    path = tmp_path / "p.yaml"
    path.write_text(doc if isinstance(doc, str) else yaml.safe_dump(doc))
    return str(path)


def test_round_trip(tmp_path):
    array = np.random.default_rng(0).integers(0, 3, (5, 7))
    pattern = Pattern(array, Constraints(3, (3, 3), 1), extra={"generator": {"seed": 4}})
    path = tmp_path / "rt.yaml"
    save_pattern(pattern, path)
    loaded = load_pattern(path)
    assert np.array_equal(loaded.array, array)
    assert loaded.constraints == pattern.constraints
    assert loaded.primitives == ["line", "circle", "triangle"]
    assert loaded.extra["generator"]["seed"] == 4
    text = dump_pattern(pattern)
    assert text.startswith("tactile_sl_pattern: 1\nsymbols: 3\nwindow: [3, 3]\n")
    assert '  - "' in text  # rows quoted so leading zeros survive


def test_good_document_loads(tmp_path):
    loaded = load_pattern(write(tmp_path, good_doc()))
    assert loaded.rows == 3 and loaded.cols == 4 and loaded.array[1, 0] == 2


def test_shipped_file_follows_contract():
    doc = yaml.safe_load(default_pattern_path().read_text())
    assert doc["tactile_sl_pattern"] == 1
    assert doc["symbols"] == 3 and doc["window"] == [3, 3] and doc["min_hamming"] == 3
    assert doc["primitives"] == ["line", "circle", "triangle"]
    assert doc["pitch_m"] == 0.0005
    assert len(doc["array"]) == doc["rows"]
    assert all(isinstance(r, str) and len(r) == doc["cols"] for r in doc["array"])
    assert default_pattern_path().with_name("pattern.certificate.txt").exists()


@pytest.mark.parametrize("mutate,message", [
    (lambda d: d.pop("symbols"), "missing required key(s): symbols"),
    (lambda d: d.update(tactile_sl_pattern=2), "unsupported tactile_sl_pattern version 2"),
    (lambda d: d.update(rows=4), "'array' has 3 rows but 'rows' says 4"),
    (lambda d: d["array"].__setitem__(1, "201"), "row 1 has 3 characters but 'cols' says 4"),
    (lambda d: d["array"].__setitem__(2, "1232"), "row 2 column 2 has symbol '3'"),
    (lambda d: d["array"].__setitem__(0, "01x0"), "row 0 column 2 has symbol 'x'"),
    (lambda d: d["array"].__setitem__(0, 1201), "is a number, not a string"),
    (lambda d: d.update(primitives=["line", "circle"]), "lists 2 names but symbols is 3"),
    (lambda d: d.update(window=3), "'window' must be a list of two integers"),
    (lambda d: d.update(window=[3, 2]), "window sides must be in 3..7"),
    (lambda d: d.update(symbols=9), "symbols must be in 2..8"),
    (lambda d: d.update(pitch_m=-1.0), "'pitch_m' must be a positive number"),
    (lambda d: d.update(pitch_m=0.5), "pitch is in metres"),
    (lambda d: d.update(min_hamming="3"), "'min_hamming' must be an integer"),
    (lambda d: d.update(rows=2, array=["0120", "2011"]), "smaller than the window"),
])
def test_malformed_files_name_the_problem(tmp_path, mutate, message):
    doc = good_doc()
    mutate(doc)
    with pytest.raises(PatternFormatError) as info:
        load_pattern(write(tmp_path, doc))
    assert message in str(info.value)
    assert "p.yaml" in str(info.value)


def test_not_yaml_and_not_mapping_and_missing_file(tmp_path):
    with pytest.raises(PatternFormatError, match="not valid YAML"):
        load_pattern(write(tmp_path, "a: [1, 2\n"))
    with pytest.raises(PatternFormatError, match="expected a YAML mapping"):
        load_pattern(write(tmp_path, "- 1\n- 2\n"))
    with pytest.raises(PatternFormatError, match="cannot read pattern file"):
        load_pattern(tmp_path / "nope.yaml")
