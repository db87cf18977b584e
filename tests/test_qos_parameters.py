"""QoS of every publisher and subscriber overridable by parameters (issue 12).

A decoder started with ``qos.output.*`` / ``qos.input.*`` overrides offers and requests what
they say (read from the DDS graph, as ``ros2 topic info -v`` shows it); one with defaults
offers the documented ones (README "QoS"); an unknown policy name is one FATAL line; QoS
cannot change live (read-only).
"""
from __future__ import annotations

import time

import pytest
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy
from test_node_parameters import Client

from ros_harness import next_domain_id, start_node, stop

pytestmark = pytest.mark.ros



def _endpoints(client: Client, topic: str, publishers: bool, timeout: float = 30.0) -> list:
    get = (client.node.get_publishers_info_by_topic if publishers
           else client.node.get_subscriptions_info_by_topic)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        found = get(topic)
        if found:
            return found
        client.executor.spin_once(timeout_sec=0.1)
    return []


def test_qos_overrides_reach_the_graph_and_bad_names_are_fatal(tmp_path):
    domain = next_domain_id()
    custom = start_node("tactile_sl_decoder", "decoder", domain,
                        ["-r", "__ns:=/custom",
                         "-p", "qos.output.reliability:=best_effort",
                         "-p", "qos.output.durability:=transient_local",
                         "-p", "qos.input.reliability:=reliable",
                         "-p", "qos.pad_pose.durability:=volatile"],
                        tmp_path / "custom.log")
    default = start_node("tactile_sl_decoder", "decoder", domain, ["-r", "__ns:=/tactile"],
                         tmp_path / "default.log")
    bad_log = tmp_path / "bad.log"
    bad = start_node("tactile_sl_decoder", "decoder", next_domain_id(),
                     ["-r", "__ns:=/tactile", "-p", "qos.output.reliability:=sometimes"],
                     bad_log)
    client = Client(domain)
    try:
        expect = {  # topic, publisher?: (reliability, durability)
            ("/custom/points", True): (ReliabilityPolicy.BEST_EFFORT,
                                       DurabilityPolicy.TRANSIENT_LOCAL),
            ("/custom/wrench", True): (ReliabilityPolicy.BEST_EFFORT,
                                       DurabilityPolicy.TRANSIENT_LOCAL),
            ("/custom/pad_pose", True): (ReliabilityPolicy.RELIABLE, DurabilityPolicy.VOLATILE),
            ("/custom/left/image_raw", False): (ReliabilityPolicy.RELIABLE,
                                                DurabilityPolicy.VOLATILE),
            ("/tactile/points", True): (ReliabilityPolicy.RELIABLE, DurabilityPolicy.VOLATILE),
            ("/tactile/pad_pose", True): (ReliabilityPolicy.RELIABLE,
                                          DurabilityPolicy.TRANSIENT_LOCAL),
            ("/tactile/left/image_raw", False): (ReliabilityPolicy.BEST_EFFORT,
                                                 DurabilityPolicy.VOLATILE),
            ("/diagnostics", True): (ReliabilityPolicy.RELIABLE, DurabilityPolicy.VOLATILE),
        }
        for (topic, pub), (rel, dur) in expect.items():
            found = _endpoints(client, topic, pub)
            assert found, f"no endpoint on {topic}"
            got = {(e.qos_profile.reliability, e.qos_profile.durability) for e in found}
            assert got == {(rel, dur)}, (topic, got)
        c = client.client("/custom/decoder")
        (res,) = client.set(c, qos__output__depth=50)
        assert not res.successful and "read-only" in res.reason
        assert bad.wait(60) == 1
        text = bad_log.read_text()
        assert text.count("FATAL") == 1 and "Traceback" not in text
        assert "qos.output.reliability" in text and "best_effort" in text
    finally:
        client.close()
        codes = [stop(p) for p in (custom, default, bad)]
    assert codes[:2] == [0, 0]
