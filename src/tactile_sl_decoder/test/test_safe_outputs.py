"""Safe files (issue 12, findings 1, 4, 7, 8): outputs never destroy inputs, bad data is refused.

Each test reproduces one finding of the issue: before the fix it destroyed a file, printed a
traceback, accepted bad data or exited 0; now it refuses with one line and leaves files as
they were.  The commands run in-process (``tactile_sl_decoder.cli.main``) to stay quick.
"""
from __future__ import annotations

import os
from pathlib import Path

import pytest
import yaml

from tactile_sl_common.bag_io import BagError, BagReader, BagWriter
from tactile_sl_decoder.cli import main
from tactile_sl_decoder.pattern import default_pattern_path, load_pattern
from tactile_sl_decoder.pattern.fileio import PatternInvalidError

from ros_harness import REPO

SOURCE_BAG = REPO / "bags" / "edge.mcap"
IMAGE_TOPICS = ["/tactile/left/image_raw", "/tactile/right/image_raw",
                "/tactile/left/camera_info", "/tactile/right/camera_info"]


def small_bag(path: Path, frames: int = 2, compression: str = "zstd",
              topics: list[str] | None = None, garble: str | None = None) -> Path:
    """The first ``frames`` stereo frames of a shipped bag; ``garble`` breaks one message."""
    reader = BagReader(SOURCE_BAG)
    stamps: list[int] = []
    with BagWriter(path, compression=compression) as out:
        for raw in reader.raw_messages(topics or IMAGE_TOPICS):
            if raw.log_time_ns not in stamps:
                if len(stamps) == frames:
                    break
                stamps.append(raw.log_time_ns)
            data = raw.data
            if garble == raw.topic and raw.log_time_ns == stamps[-1] and len(stamps) == 2:
                data = data[:40]           # a truncated Image: cannot be deserialised
            out.write_raw(raw.topic, raw.schema_name, data, raw.log_time_ns)
    return path


@pytest.fixture(scope="module")
def bag(tmp_path_factory) -> Path:
    return small_bag(tmp_path_factory.mktemp("bag") / "in.mcap")


def run_cli(capsys, *argv: str) -> tuple[int, str]:
    try:
        rc = main([str(a) for a in argv])
    except SystemExit as exc:          # argparse refusals
        rc = int(exc.code)
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return rc, err


# ---------------------------------------------------------------- finding 1: replay's input


def test_replay_onto_a_hard_link_of_its_input_is_refused(tmp_path, bag, capsys):
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    a.write_bytes(bag.read_bytes())
    os.link(a, b)
    before = a.read_bytes()
    rc, err = run_cli(capsys, "replay", a, "-o", b, "--no-progress")
    assert rc == 2 and "input file" in err
    assert a.read_bytes() == before


def test_replay_into_its_own_bag_directory_is_refused(tmp_path, bag, capsys):
    d = tmp_path / "d"
    d.mkdir()
    inside = d / "d_0.mcap"
    inside.write_bytes(bag.read_bytes())
    before = inside.read_bytes()
    rc, err = run_cli(capsys, "replay", d, "-o", inside, "--no-progress")
    assert rc == 2 and inside.read_bytes() == before
    rc, err = run_cli(capsys, "replay", d, "-o", d / "new.mcap", "--no-progress")
    assert rc == 2 and "inside the input bag directory" in err
    assert sorted(p.name for p in d.iterdir()) == ["d_0.mcap"]


def test_a_bag_without_images_leaves_an_existing_output_alone(tmp_path, capsys):
    empty = tmp_path / "noimages.mcap"
    with BagWriter(empty) as w:
        w.write("/tactile/other", "std_msgs/msg/String", {"data": "x"}, 1)
    out = tmp_path / "out.mcap"
    out.write_bytes(b"precious")
    rc, err = run_cli(capsys, "replay", empty, "-o", out, "--no-progress")
    assert rc == 1 and "missing topic" in err
    assert out.read_bytes() == b"precious"
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


# ---------------------------------------------------------------- finding 7: one line


def test_unwritable_replay_output_is_one_line(tmp_path, bag, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    rc, err = run_cli(capsys, "replay", bag, "-o", blocker / "out.mcap", "--no-progress")
    assert rc == 1 and "not a directory" in err and len(err.strip().splitlines()) == 1


def test_train_checks_its_output_before_training(tmp_path, capsys, monkeypatch):
    import tactile_sl_decoder.tooling.training as training

    monkeypatch.setattr(training, "render_dataset",
                        lambda *a, **k: pytest.fail("rendered before checking the output"))
    rc, err = run_cli(capsys, "train", "--frames", "1", "-o", tmp_path / "nodir" / "w.pt")
    assert rc == 1 and "does not exist" in err


def test_evaluate_json_checked_before_work_and_frames_range_checked(tmp_path, bag, capsys):
    rc, err = run_cli(capsys, "evaluate", bag, "--json", tmp_path / "nodir" / "x.json")
    assert rc == 2 and "does not exist" in err
    rc, err = run_cli(capsys, "evaluate", bag, "--max-frames", "-1")
    assert rc == 2 and "--max-frames: must be in [0," in err


def test_huge_render_is_refused_before_allocating(tmp_path, capsys):
    rc, err = run_cli(capsys, "pattern", "render", default_pattern_path(),
                      "--png", tmp_path / "a.png", "--pitch-px", "100000")
    assert rc == 2 and "Mpx" in err and not (tmp_path / "a.png").exists()


def test_render_is_atomic_and_unwritable_render_is_one_line(tmp_path, capsys):
    rc, _ = run_cli(capsys, "pattern", "render", default_pattern_path(),
                    "--png", tmp_path / "a.png", "--pitch-px", "8", "--svg", tmp_path / "a.svg")
    assert rc == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.png", "a.png.yaml", "a.svg"]
    assert yaml.safe_load((tmp_path / "a.png.yaml").read_text())["image"] == "a.png"
    rc, err = run_cli(capsys, "pattern", "render", default_pattern_path(),
                      "--svg", tmp_path / "a.png" / "x.svg")
    assert rc == 2 and len(err.strip().splitlines()) == 1


def test_verify_of_a_binary_file_is_unreadable(tmp_path, capsys):
    binary = tmp_path / "weights.pt"
    binary.write_bytes(bytes(range(256)) * 4)
    rc, err = run_cli(capsys, "pattern", "verify", binary)
    assert rc == 2 and "not a text file" in err


# ---------------------------------------------------------------- finding 8: bad data


def test_flipped_payload_bytes_fail_the_chunk_crc(tmp_path, capsys):
    path = small_bag(tmp_path / "crc.mcap", frames=1, compression="none")
    data = bytearray(path.read_bytes())
    middle = len(data) // 3                    # inside the first image's pixels
    data[middle:middle + 16] = bytes(16)
    path.write_bytes(bytes(data))
    with pytest.raises(BagError, match="CRC"):
        BagReader(path).verify()
    with pytest.raises(BagError, match="CRC"):
        list(BagReader(path).raw_messages())
    rc, err = run_cli(capsys, "replay", path, "-o", tmp_path / "out.mcap", "--no-progress")
    assert rc == 1 and "CRC" in err and not (tmp_path / "out.mcap").exists()


def test_written_bags_carry_chunk_crcs(bag):
    assert BagReader(bag).verify() >= 1


def test_undecodable_message_skips_its_frame_with_a_warning(tmp_path, capsys):
    path = small_bag(tmp_path / "bad.mcap", frames=3, garble="/tactile/right/image_raw")
    reader = BagReader(path)
    got = [raw.topic for raw, _ in reader.messages(IMAGE_TOPICS)]
    err = capsys.readouterr().err
    assert got.count("/tactile/right/image_raw") == 2 and got.count("/tactile/left/image_raw") == 3
    assert "/tactile/right/image_raw" in err and "skipped" in err
    with pytest.raises(BagError, match="cannot decode"):
        list(reader.messages(IMAGE_TOPICS, strict=True))


def test_pattern_breaking_its_own_min_hamming_is_refused(tmp_path, bag, capsys):
    doc = yaml.safe_load(default_pattern_path().read_text())
    doc["min_hamming"] = 7                      # the array does not have this distance
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump(doc))
    with pytest.raises(PatternInvalidError, match="minimum distance"):
        load_pattern(bad)
    assert load_pattern(bad, verify=False).constraints.min_hamming == 7
    rc, err = run_cli(capsys, "replay", bag, "-o", tmp_path / "o.mcap", "--pattern", bad,
                      "--no-progress", "--no-touch")
    assert rc == 1 and "breaks its own constraints" in err
    rc, err = run_cli(capsys, "replay", tmp_path / "missing.mcap", "-o", tmp_path / "o.mcap",
                      "--pattern", bad, "--allow-invalid-pattern", "--no-progress")
    assert rc == 1 and "breaks its own" not in err and "missing.mcap" in err


def test_classifier_for_another_alphabet_is_refused(tmp_path, bag, capsys):
    import torch

    from tactile_sl_decoder.classify.classifier import default_weights_path

    blob = torch.load(default_weights_path(), map_location="cpu", weights_only=True)
    state = blob["state_dict"]
    state["out.bias"] = torch.cat([state["out.bias"], state["out.bias"][:1]])
    state["out.weight"] = torch.cat([state["out.weight"], state["out.weight"][:1]])
    blob["primitives"] = list(blob.get("primitives", [])) + ["extra"]
    four = tmp_path / "four.pt"
    torch.save(blob, four)
    rc, err = run_cli(capsys, "replay", bag, "-o", tmp_path / "o.mcap", "--classifier", four,
                      "--no-progress")
    assert rc == 1 and "4 classes" in err and "3 symbols" in err


def test_generate_rejects_a_negative_pitch(tmp_path, capsys):
    rc, err = run_cli(capsys, "pattern", "generate", "-k", "3", "--window", "3x3",
                      "--min-hamming", "1", "--size", "6x6", "--pitch-m", "-1",
                      "-o", tmp_path / "p.yaml")
    assert rc == 2 and "--pitch-m" in err and not (tmp_path / "p.yaml").exists()
