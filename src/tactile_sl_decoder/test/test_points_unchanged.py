"""The points and touch outputs of every bundled bag are byte-identical to those recorded.

``data/points_digests.json`` holds, per bag and output topic (points, field, wrench, slip,
contact, depth), every message's stamp, size and the SHA-256 of its data as ``tactile-sl
replay`` wrote them (``python tools/points_digest.py --write ...``).  History: recorded on
the tree before the layout change (issue 9, commit 3f1d4a6), again when glyphs split out of
linked regions got a centroid refinement (issue 11: robust_damaged_print and
robust_textured_object moved), when the classifier was retrained with the real-sensor
nuisances (robust_damaged_print lost cell (2, 14) in two frames), when glyphs one camera did
not detect were measured where the other camera's cells put them (edge and harsh_lighting
each gained one point), when the centroid threshold learnt to follow the background at a
dark object's rim (robust_dark_object's points moved); with touch outputs and per CPU model
since 2026-12-02 (issue 29), when the right-sized classifier became the default
(robust_damaged_print gained two cells in two frames, checked against the ground truth:
coverage 99.39 -> 99.48 %, 0 wrong; every other bag byte-identical, and every bag with the
LeNet weights), and when the two slip bags were added (issue 24: slip_halfspace,
slip_two_contacts), and when the contact area came from the support of a non-negative
traction inversion and the largest indentation became robust to wrong cells (issue 25: the
contact topic of every bag; points, field, wrench, depth and slip byte-identical), and
when glyph centres came to weigh the reflectance (issue 25, 2026-12-04: every bag's points
and touch outputs moved; robust_damaged_print gained a point, coverage 99.48 -> 99.53 %,
0 wrong; docs/robustness.md, "Where the clean rows' error comes from"), and when
``max_depth`` came to undo a glyph's average of a curved surface (issue 25, 2026-12-07: the
contact topic of twelve bags; the rest byte-identical), and when a region's centroid came
from the map smoothed by one cell (issue 25, 2026-12-07: the contact topic of thirteen
bags; the rest byte-identical).  A
change that alters any output, even in the last bit, fails here; when a change is *meant*
to alter them (a better decoder), record the digests again and say so in the commit.

Bytes are only comparable on the CPU model they were recorded on: numpy and OpenCV pick
SIMD code paths per CPU, which can move a float's last bit.  The file keeps them per CPU
model and widest vector extension (since 2026-12-03: a virtual machine's "AMD EPYC" covers
CPUs with and without AVX-512, and that entry, recorded once on 2026-12-02, had been kept
through every later change of the outputs; the tool now drops another CPU's digests of an
output the recorded change altered; since 2026-12-07 a CPU's first recording keeps another
CPU's digests only where they equal its own: the AVX-512 EPYC's first one had kept the AVX2
EPYC's and the Xeon's stale bytes, which failed here on an AVX2 EPYC (Zen 3) from that
commit on; recorded there again, the Xeon's moved outputs dropped).  On any machine the test
requires the same messages (stamps) and sizes; on a CPU without digests it says so.
"""
import importlib.util
import json
import warnings
from pathlib import Path

import pytest

from ros_harness import REPO

pytestmark = pytest.mark.slow

DIGESTS = Path(__file__).parent / "data" / "points_digests.json"


def _tool():
    spec = importlib.util.spec_from_file_location("points_digest",
                                                  REPO / "tools" / "points_digest.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_points_and_touch_outputs_of_every_bag_are_unchanged(tmp_path):
    tool = _tool()
    recorded = json.loads(DIGESTS.read_text())
    bags = sorted((REPO / "bags").glob("*.mcap"))
    assert {b.name for b in bags} == set(recorded["frames"]), "bags added or removed: record again"
    mine = recorded["digests"].get(tool.cpu_model(), {})
    if not mine:
        warnings.warn(f"no digests recorded for CPU {tool.cpu_model()!r}: only messages and "
                      f"sizes are compared (record with tools/points_digest.py --write)",
                      stacklevel=1)
    for bag in bags:
        now = tool.replay_digests(bag, tmp_path)
        frames = {topic: [m[:2] for m in msgs] for topic, msgs in now.items()}
        assert frames == recorded["frames"][bag.name], (
            f"{bag.name}: messages or their sizes changed")
        for topic, hashes in mine.get(bag.name, {}).items():
            changed = [i for i, (m, h) in enumerate(zip(now[topic], hashes)) if m[2] != h]
            assert not changed, f"{bag.name}: {topic} of frames {changed} are not byte-identical"


def test_recording_drops_other_cpus_digests_of_outputs_it_changed(monkeypatch):
    """Recording on one CPU keeps another CPU's digests only of the outputs it left
    unchanged here: a change meant to alter an output leaves no stale bytes behind."""
    tool = _tool()
    monkeypatch.setattr(tool, "cpu_model", lambda: "A [avx2]")
    old = {"frames": {"b.mcap": {"points": [[1, 5]], "wrench": [[1, 1]]}},
           "digests": {"A [avx2]": {"b.mcap": {"points": ["p0"], "wrench": ["w0"]}},
                       "B [avx512f]": {"b.mcap": {"points": ["P0"], "wrench": ["W0"]}}}}
    now = {"b.mcap": {"points": [[1, 5, "p0"]], "wrench": [[1, 1, "w1"]]}}
    new = tool.record(now, old)
    assert new["digests"]["A [avx2]"] == {"b.mcap": {"points": ["p0"], "wrench": ["w1"]}}
    assert new["digests"]["B [avx512f]"] == {"b.mcap": {"points": ["P0"]}}
    # a first recording here cannot tell a change from another CPU's own bits: it keeps
    # only the digests equal to its own
    monkeypatch.setattr(tool, "cpu_model", lambda: "C [avx2]")
    third = tool.record(now, new)
    assert third["digests"]["B [avx512f]"] == {"b.mcap": {}}
    assert third["digests"]["A [avx2]"] == new["digests"]["A [avx2]"]
