"""One parameter mechanism (issue 12, findings 2, 3, 4): YAML in any namespace, live changes
applied or refused with a reason, out-of-range values refused at start with one FATAL line."""
from __future__ import annotations

import time
from pathlib import Path

import pytest
import yaml
from rclpy.parameter import Parameter, parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient

from ros_harness import REPO, Probe, next_domain_id, start_node, stop

pytestmark = pytest.mark.ros

CONFIGS = {  # config file -> (package, executable, extra -p overrides)
    "src/tactile_sl_camera/config/replay.yaml": ("tactile_sl_camera", "replay", "replay"),
    "src/tactile_sl_sim/config/sim_camera.yaml": ("tactile_sl_sim", "sim_camera", ""),
    "src/tactile_sl_camera/config/stereo_camera.yaml": ("tactile_sl_camera", "stereo_camera",
                                                        ""),
    "src/tactile_sl_decoder/config/decoder.yaml": ("tactile_sl_decoder", "decoder", ""),
    "src/tactile_sl_decoder/config/symbol_extractor.yaml": ("tactile_sl_decoder",
                                                            "symbol_extractor", ""),
    "src/tactile_sl_decoder/config/symbol_classifier.yaml": ("tactile_sl_decoder",
                                                             "symbol_classifier", ""),
}


class Client(Probe):
    """A parameter client in its own context and domain."""

    def __init__(self, domain: int) -> None:
        super().__init__("param_test_client", domain)

    def _answered(self, future, timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while not future.done() and time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.05)
        return future.done()

    def wait(self, future, timeout: float = 20.0):
        assert self._answered(future, timeout), "no answer from the node's parameter services"
        return future.result()

    def client(self, fqn: str, timeout: float = 40.0) -> AsyncParameterClient:
        c = AsyncParameterClient(self.node, fqn)
        deadline = time.monotonic() + timeout
        while not c.services_are_ready() and time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.1)
        assert c.services_are_ready(), f"{fqn}: parameter services never appeared"
        return c

    def get(self, c: AsyncParameterClient, names: list[str]) -> dict:
        # A read is asked again if its answer is lost: a node still starting (a decoder
        # spawning its workers on two busy cores) can answer before the middleware has
        # matched this client's response reader ("failed to send response (timeout)")
        future = c.get_parameters(names)
        for _ in range(2):
            if self._answered(future, 10.0):
                break
            future = c.get_parameters(names)
        res = self.wait(future)
        return {n: parameter_value_to_python(v) for n, v in zip(names, res.values)}

    def set(self, c: AsyncParameterClient, **values) -> list:
        params = [Parameter(k.replace("__", "."), value=v) for k, v in values.items()]
        return self.wait(c.set_parameters(params)).results


def _bag(tmp_path: Path) -> Path:
    from tactile_sl_common.bag_io import BagReader, BagWriter

    path = tmp_path / "one.mcap"
    with BagWriter(path) as out:
        first = None
        for raw in BagReader(REPO / "bags" / "edge.mcap").raw_messages():
            first = first or raw.log_time_ns
            if raw.log_time_ns != first:
                break
            out.write_raw(raw.topic, raw.schema_name, raw.data, raw.log_time_ns)
    return path


def test_every_config_applies_in_namespace_tactile(tmp_path):
    domain = next_domain_id()
    procs = []
    expected = {}
    bag = _bag(tmp_path)
    for rel, (package, exe, _) in CONFIGS.items():
        args = ["-r", "__ns:=/tactile", "--params-file", str(REPO / rel)]
        if exe == "replay":
            args += ["-p", f"bag:={bag}", "-p", "loop:=true"]
        if exe == "stereo_camera":
            args += ["-p", f"left_device:={tmp_path / 'none'}",
                     "-p", f"right_device:={tmp_path / 'none'}"]
        procs.append(start_node(package, exe, domain, args, tmp_path / f"{exe}.log"))
        doc = yaml.safe_load((REPO / rel).read_text())
        (key,) = doc
        assert key == f"/**/{exe}", f"{rel}: keyed {key!r}, not '/**/{exe}'"
        values = dict(doc[key]["ros__parameters"])
        for skip in ("bag", "loop", "left_device", "right_device"):
            values.pop(skip, None)
        expected[exe] = values
    client = Client(domain)
    try:
        for exe, values in expected.items():
            c = client.client(f"/tactile/{exe}")
            got = client.get(c, list(values))
            assert got == values, f"{exe}: {got} != {values}"
    finally:
        client.close()
        for p in procs:
            stop(p)


def test_live_changes_are_applied_or_refused_with_a_reason(tmp_path):
    domain = next_domain_id()
    proc = start_node("tactile_sl_decoder", "decoder", domain, ["-r", "__ns:=/tactile"],
                      tmp_path / "decoder.log")
    client = Client(domain)
    try:
        c = client.client("/tactile/decoder")
        (ok,) = client.set(c, min_votes=3)
        assert ok.successful
        assert client.get(c, ["min_votes"]) == {"min_votes": 3}
        for change, words in [({"input": "bogus"}, "read-only"),
                              ({"max_reprojection_px": -1.0}, "range"),
                              ({"classifier_threshold": 5.0}, "range"),
                              ({"extraction__block_size": 30}, "odd"),
                              ({"outliers__mad_factor": 0.1}, "range"),
                              ({"carry__radius": 0.9}, "range"),
                              ({"contact_force_off": 50.0}, "must not exceed")]:
            (res,) = client.set(c, **change)
            assert not res.successful and words in res.reason, (change, res.reason)
        assert client.get(c, ["input", "max_reprojection_px"]) == {
            "input": "images", "max_reprojection_px": 1.5}
        assert all(r.successful for r in client.set(c, max_reprojection_px=0.5, mirrored=True))
        (ok,) = client.set(c, outliers__passes=2)
        assert ok.successful and client.get(c, ["outliers.passes"]) == {"outliers.passes": 2}
        (ok,) = client.set(c, carry__enabled=False)
        assert ok.successful and client.get(c, ["carry.enabled"]) == {"carry.enabled": False}
        deadline = time.monotonic() + 10
        while "parameters applied: max_reprojection_px=0.5" not in \
                (tmp_path / "decoder.log").read_text() and time.monotonic() < deadline:
            time.sleep(0.1)
        log = (tmp_path / "decoder.log").read_text()
        assert "parameters applied: max_reprojection_px=0.5" in log
        assert "touch reference is taken again" in log
    finally:
        client.close()
        assert stop(proc) == 0


@pytest.mark.parametrize("setting", ["extraction.block_size:=-4", "max_age:=-1.0",
                                     "threads:=-1", "queue_size:=-1",
                                     "classifier_threshold:=5.0"])
def test_out_of_range_settings_are_one_fatal_line(tmp_path, setting):
    log = tmp_path / "decoder.log"
    proc = start_node("tactile_sl_decoder", "decoder", next_domain_id(),
                      ["-r", "__ns:=/tactile", "-p", setting], log)
    assert proc.wait(60) == 1
    text = log.read_text()
    assert text.count("FATAL") == 1 and "Traceback" not in text
    assert setting.split(":=")[0] in text
