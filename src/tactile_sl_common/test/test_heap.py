"""freeze_long_lived: start-up objects leave the collector's reach, later garbage does not."""
from __future__ import annotations

import gc
import weakref

import pytest

from tactile_sl_common.heap import freeze_long_lived


class _Node:
    def __init__(self) -> None:
        self.other: _Node | None = None


def _cycle() -> weakref.ref:
    a, b = _Node(), _Node()
    a.other, b.other = b, a
    return weakref.ref(a)


@pytest.fixture
def unfrozen():
    gc.unfreeze()
    yield
    gc.unfreeze()


def test_collects_first_then_freezes(unfrozen) -> None:
    garbage = _cycle()            # unreachable already: collected before the freeze
    frozen = freeze_long_lived()
    assert garbage() is None
    assert frozen > 0 and gc.get_freeze_count() > 0
    assert len(gc.get_objects()) < frozen   # the tracked objects left: only those made since


def test_frozen_cycles_survive_later_collections_new_ones_do_not(unfrozen) -> None:
    a, b = _Node(), _Node()
    a.other, b.other = b, a
    old = weakref.ref(a)
    freeze_long_lived(collect=False)
    del a, b                      # unreachable, but frozen: out of the collector's reach
    young = _cycle()              # made after the freeze: collected as before
    gc.collect()
    assert old() is not None
    assert young() is None
    gc.unfreeze()
    gc.collect()
    assert old() is None
