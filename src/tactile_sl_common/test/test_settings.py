"""SettingsTable: rows from a dataclass's fields and docstrings; ranges checked inclusively."""
from dataclasses import dataclass

import pytest

from tactile_sl_common.settings import SettingsTable, field_docs, frame_prefix_check


@dataclass
class Demo:
    """A settings dataclass."""

    count: int = 3
    """How many, at least one."""
    gain: float = 0.5
    """A gain
    over two lines."""
    name: str = "x"
    """A name: no spaces."""
    undocumented: float = 1.0


def _no_spaces(value: str) -> str | None:
    return "no spaces" if " " in value else None


def test_rows_come_from_the_fields_and_their_docstrings():
    table = SettingsTable(Demo, {"count": (1, 10), "gain": (0.0, 1.0)},
                          fields=("count", "gain", "name"), read_only=("name",),
                          checks={"name": _no_spaces})
    assert [r.name for r in table] == ["count", "gain", "name"]
    assert table["gain"].description == "A gain over two lines."
    assert (table["count"].default, table["count"].range, table["count"].live) == (3, (1, 10),
                                                                                   True)
    assert not table["name"].live and table["gain"].range == (0.0, 1.0)
    assert field_docs(Demo)["name"] == "A name: no spaces."


def test_check_is_inclusive_and_names_the_field():
    table = SettingsTable(Demo, {"count": (1, 10), "gain": (0.0, 1.0)},
                          fields=("count", "gain", "name"), checks={"name": _no_spaces})
    for ok in (Demo(count=1, gain=0.0), Demo(count=10, gain=1.0)):
        table.check(ok)
    with pytest.raises(ValueError, match=r"demo\.count must be in \[1, 10\], got 0"):
        table.check(Demo(count=0), "demo.")
    with pytest.raises(ValueError, match="gain must be in"):
        table.check(Demo(gain=1.5))
    with pytest.raises(ValueError, match="name no spaces"):
        table.check(Demo(name="a b"))


def test_a_table_refuses_unknown_or_undocumented_fields():
    with pytest.raises(TypeError, match="no field colour"):
        SettingsTable(Demo, {"colour": (0, 1)}, fields=("count",))
    with pytest.raises(TypeError, match="no docstring under undocumented"):
        SettingsTable(Demo)          # every scalar field, one without a docstring


def test_frame_prefix_check():
    assert frame_prefix_check("left_hand_") is None
    assert frame_prefix_check("/left") and frame_prefix_check("a b")
