"""Sensor files: the shipped one loads; every kind of bad file is one clear error."""
import pytest

from tactile_sl_decoder.touch.sensor import (
    SensorFileError,
    load_sensor,
    parse_sensor,
    sensor_yaml_text,
)

GOOD = {"tactile_sl_sensor": 1, "pad_frame": "tactile_pad",
        "elastomer": {"youngs_modulus": 3e5, "poisson_ratio": 0.49, "thickness": 0.0}}


def _with(**elastomer):
    doc = {**GOOD, "elastomer": {**GOOD["elastomer"], **elastomer}}
    return doc


def test_shipped_sensor_file_loads():
    s = load_sensor()
    assert s.elastomer.youngs_modulus == 3e5 and s.elastomer.poisson_ratio == 0.49
    assert s.elastomer.thickness == 0.0 and s.pad_frame == "tactile_pad"


@pytest.mark.parametrize("doc, words", [
    (_with(youngs_modulus=0.0), "youngs_modulus"),
    (_with(youngs_modulus=-3e5), "youngs_modulus"),
    (_with(poisson_ratio=0.6), "poisson"),
    (_with(poisson_ratio=-0.1), "poisson"),
    (_with(thickness=-0.001), "thickness"),
    (_with(youngs_modulus="soft"), "must be a number"),
    ({**GOOD, "elastomer": {"youngs_modulus": 3e5, "poison_ratio": 0.49, "thickness": 0}},
     "did you mean 'poisson_ratio'"),
    ({**GOOD, "pad_fram": "x"}, "did you mean 'pad_frame'"),
    ({**GOOD, "tactile_sl_sensor": 2}, "format version"),
    ({"elastomer": GOOD["elastomer"]}, "tactile_sl_sensor"),
    ([1, 2], "mapping"),
])
def test_bad_sensor_files_are_clear_errors(doc, words):
    with pytest.raises(SensorFileError) as err:
        parse_sensor(doc, "s.yaml")
    assert words.lower() in str(err.value).lower() and "s.yaml" in str(err.value)


def test_missing_and_unreadable_files(tmp_path):
    with pytest.raises(SensorFileError, match="no such sensor file"):
        load_sensor(tmp_path / "none.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_bytes(b"\xff\xfe: [")
    with pytest.raises(SensorFileError, match="not a YAML sensor file"):
        load_sensor(bad)


def test_other_keys_are_allowed_and_text_round_trips(tmp_path):
    s = parse_sensor({**GOOD, "serial": "pad-007", "notes": {"shore": "00-30"}})
    path = tmp_path / "out.yaml"
    path.write_text(sensor_yaml_text(s, "written by a test"))
    assert load_sensor(path).elastomer == s.elastomer


def test_overrides_are_validated():
    s = parse_sensor(GOOD)
    assert s.with_overrides(youngs_modulus=1e6).elastomer.youngs_modulus == 1e6
    with pytest.raises(SensorFileError):
        s.with_overrides(poisson_ratio=0.7)
