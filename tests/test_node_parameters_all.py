"""The one parameter mechanism on every other node (issue 12): replay, sim_camera,
stereo_camera, symbol_extractor, symbol_classifier.

Per node: a value out of range at start is one FATAL line naming the parameter (status 1, no
traceback); a live change is applied (read back, logged) or refused with the reason
(read-only, out of range, a node's own check).  All nodes of a test run at once.
"""
from __future__ import annotations

import time
from pathlib import Path

import pytest
from test_node_parameters import Client, _bag

from ros_harness import next_domain_id, start_node, stop

pytestmark = pytest.mark.ros

CAMERA, SIM, DECODER = "tactile_sl_camera", "tactile_sl_sim", "tactile_sl_decoder"
PACKAGE_OF = {"replay": CAMERA, "stereo_camera": CAMERA, "sim_camera": SIM,
              "symbol_extractor": DECODER, "symbol_classifier": DECODER}
BAD_AT_START = [  # (package, executable, setting out of range)
    (CAMERA, "replay", "rate:=-1.0"),
    (SIM, "sim_camera", "rate:=-1.0"),
    (CAMERA, "stereo_camera", "width:=-1"),
    (DECODER, "symbol_extractor", "block_size:=-4"),
    (DECODER, "symbol_classifier", "threshold:=5.0"),
]


def test_out_of_range_at_start_is_one_fatal_line(tmp_path):
    procs = []
    for package, exe, setting in BAD_AT_START:
        log = tmp_path / f"{exe}.log"
        procs.append((start_node(package, exe, next_domain_id(),
                                 ["-r", "__ns:=/tactile", "-p", setting], log), log, setting))
    failures = []
    for proc, log, setting in procs:
        try:
            rc = proc.wait(60)
        except Exception:
            rc = stop(proc)
        text = log.read_text()
        if rc != 1 or text.count("FATAL") != 1 or "Traceback" in text \
                or setting.split(":=")[0] not in text:
            failures.append(f"{setting}: rc {rc}\n{text[-800:]}")
    assert not failures, "\n\n".join(failures)


# executable -> (extra start args, applied change, [(refused change, words in the reason)])
LIVE = {
    "replay": (["loop:=true"], {"wait_timeout": 2.0},
               [({"rate": 2.0}, "read-only"), ({"wait_timeout": -1.0}, "range")]),
    "sim_camera": ([], {"rate": 20.0},
                   [({"encoding": "bgr8"}, "read-only"), ({"rate": -1.0}, "range")]),
    "stereo_camera": ([], {"reopen_interval": 0.5},
                      [({"width": 320}, "read-only"), ({"reopen_interval": 0.0}, "range")]),
    "symbol_extractor": ([], {"offset": 10.0},
                         [({"block_size": 30}, "odd"), ({"patch_size": 20}, "read-only")]),
    "symbol_classifier": ([], {"threshold": 0.5},
                          [({"weights": "x.pt"}, "read-only"), ({"threshold": 2.0}, "range")]),
}


def test_live_changes_applied_or_refused_on_every_node(tmp_path):
    domain = next_domain_id()
    bag = _bag(tmp_path)
    procs = {}
    for exe, (extra, _, _) in LIVE.items():
        package = PACKAGE_OF[exe]
        args = ["-r", "__ns:=/tactile"]
        if exe == "replay":
            args += ["-p", f"bag:={bag}"]
        if exe == "stereo_camera":
            args += ["-p", f"left_device:={tmp_path / 'none'}",
                     "-p", f"right_device:={tmp_path / 'none'}"]
        for setting in extra:
            args += ["-p", setting]
        procs[exe] = start_node(package, exe, domain, args, tmp_path / f"{exe}.log")
    client = Client(domain)
    failures = []
    try:
        for exe, (_, applied, refused) in LIVE.items():
            c = client.client(f"/tactile/{exe}")
            results = client.set(c, **applied)
            if not all(r.successful for r in results):
                failures.append(f"{exe}: {applied} refused: {[r.reason for r in results]}")
            got = client.get(c, list(applied))
            if got != applied:
                failures.append(f"{exe}: read back {got} != {applied}")
            for change, words in refused:
                before = client.get(c, list(change))
                (res,) = client.set(c, **change)
                if res.successful or words not in res.reason:
                    failures.append(f"{exe}: {change} -> {res.successful} {res.reason!r}")
                if client.get(c, list(change)) != before:
                    failures.append(f"{exe}: refused {change} still changed the value")
        deadline = time.monotonic() + 10
        for exe, (_, applied, _) in LIVE.items():
            log = Path(tmp_path / f"{exe}.log")
            want = "parameters applied: " + ", ".join(f"{k}={v!r}" for k, v in applied.items())
            while want not in log.read_text() and time.monotonic() < deadline:
                time.sleep(0.1)
            if want not in log.read_text():
                failures.append(f"{exe}: no '{want}' in the log")
    finally:
        client.close()
        codes = {exe: stop(p) for exe, p in procs.items()}
    assert not failures, "\n".join(failures)
    assert all(rc == 0 for rc in codes.values()), codes
