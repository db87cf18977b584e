"""LiveParameters: the on-set callback only validates, the post-set callback applies.

rclpy's order (node._set_parameters_atomically_common): every on-set callback validates the
request; only if all accept are the values stored and the post-set callbacks called.  The
stand-in node below keeps the callbacks and runs them in that order, without rclpy's runtime.
"""
from dataclasses import dataclass
from types import SimpleNamespace

import pytest

from tactile_sl_common.nodes.parameters import LiveParameters
from tactile_sl_common.settings import SettingsTable


@dataclass
class Band:
    """Two thresholds with a rule between them."""

    high: float = 1.0
    """Upper threshold."""
    low: float = 0.5
    """Lower threshold (at most high)."""
    size: int = 4
    """Fixed at start."""

    def validate(self) -> "Band":
        BAND.check(self, "band.")
        if self.low > self.high:
            raise ValueError(f"band.low ({self.low}) must not exceed band.high ({self.high})")
        return self


BAND = SettingsTable(Band, {"high": (0.0, 10.0), "low": (0.0, 10.0), "size": (1, 8)},
                     read_only=("size",))


class StandInNode:
    """Declares, stores and sets parameters in rclpy's order of callbacks."""

    def __init__(self, given: dict | None = None) -> None:
        self.values, self.descriptors, self.given = {}, {}, dict(given or {})
        self.on_set, self.post_set, self.logged = [], [], []

    def add_on_set_parameters_callback(self, cb):
        self.on_set.insert(0, cb)

    def add_post_set_parameters_callback(self, cb):
        self.post_set.insert(0, cb)

    def declare_parameter(self, name, default, descriptor):
        self.values[name] = self.given.get(name, default)
        self.descriptors[name] = descriptor
        for cb in self.post_set:
            cb([SimpleNamespace(name=name, value=self.values[name])])

    def get_parameter(self, name):
        return SimpleNamespace(value=self.values[name])

    def get_logger(self):
        return SimpleNamespace(info=self.logged.append)

    def set(self, **changes):
        params = [SimpleNamespace(name=k.replace("__", "."), value=v) for k, v in changes.items()]
        for cb in self.on_set:
            result = cb(params)
            if not result.successful:
                return result
        for p in params:
            self.values[p.name] = p.value
        for cb in self.post_set:
            cb(params)
        return SimpleNamespace(successful=True, reason="")


def _declared(given=None):
    node = StandInNode(given)
    live = LiveParameters(node)
    band = live.declare_table(BAND, Band(), "band.", "Band: ")
    return node, live, band


def test_declared_from_the_table_with_start_values():
    node, _, band = _declared({"band.high": 2.0})
    assert band.high == 2.0 and band.low == 0.5
    d = node.descriptors["band.size"]
    assert d.read_only and d.description == "Band: Fixed at start. Applies at start only " \
        "(read-only)."
    assert d.integer_range[0].from_value == 1 and d.integer_range[0].to_value == 8
    assert node.descriptors["band.low"].floating_point_range[0].to_value == 10.0
    assert node.logged == []          # declaring applies nothing live


def test_on_set_only_validates_and_post_set_applies():
    node, _, band = _declared()
    (on_set,) = node.on_set
    request = [SimpleNamespace(name="band.low", value=0.8)]
    assert on_set(request).successful and band.low == 0.5      # validated, not applied
    assert node.set(band__low=0.8).successful and band.low == 0.8
    assert node.logged == ["parameters applied: band.low=0.8"]


def test_a_refused_request_changes_nothing():
    node, _, band = _declared()
    result = node.set(band__high=0.9, band__low=0.95)           # low would exceed high
    assert not result.successful and "must not exceed" in result.reason
    assert (band.high, band.low) == (1.0, 0.5) and node.logged == []


def test_a_later_refusal_by_another_callback_leaves_nothing_half_applied():
    node = StandInNode()
    node.add_on_set_parameters_callback(          # registered first: runs after ours
        lambda params: SimpleNamespace(successful=False, reason="not now"))
    band = LiveParameters(node).declare_table(BAND, Band(), "band.")
    assert len(node.on_set) == 2
    assert not node.set(band__high=3.0).successful
    assert band.high == 1.0 and node.logged == []


def test_a_live_parameter_needs_apply_or_read_only():
    _, live, _ = _declared()
    with pytest.raises(TypeError, match="apply"):
        live.declare("orphan", 1.0, "Neither live nor read-only.")
