"""Each settings dataclass's validate() reads its table: every range is written once.

For every row with a range of every table the decoder node declares (and the extractor's),
the dataclass accepts both bounds and refuses a value just outside each, naming the field;
the node then declares exactly these ranges (tests/test_parameter_tables.py checks the
running nodes).
"""
import dataclasses

import pytest

from tactile_sl_decoder.nodes.decoder_settings import DECODER_TABLES, declared_names

CASES = [(d, row) for d in DECODER_TABLES for row in d.table if row.range is not None]


def _validate(declared, settings):
    """The dataclass's validate(), or the table's check where it has none."""
    if hasattr(settings, "validate"):
        settings.validate()
    else:
        declared.table.check(settings, declared.prefix)


def _outside(row):
    low, high = row.range
    step = 1 if isinstance(row.default, int) else max(abs(high - low) * 1e-6, 1e-12)
    return low - step, high + step


@pytest.mark.parametrize("declared, row", CASES, ids=[d.prefix + r.name for d, r in CASES])
def test_validate_refuses_what_the_table_refuses(declared, row):
    table = declared.table
    defaults = table.cls()
    for bound in row.range:
        table.check(dataclasses.replace(defaults, **{row.name: type(row.default)(bound)}))
    for value in _outside(row):
        bad = dataclasses.replace(defaults, **{row.name: type(row.default)(value)})
        with pytest.raises(ValueError, match=row.name):
            _validate(declared, bad)


def test_the_decoder_declares_each_name_once_and_every_default_passes():
    names = [d.prefix + row.name for d in DECODER_TABLES for row in d.table]
    assert len(names) == len(set(names)) == len(declared_names())
    for d in DECODER_TABLES:
        defaults = d.table.cls()
        d.table.check(defaults)
        _validate(d, defaults)
