"""Every parameter the decoder and symbol_extractor declare is a row of its settings table.

Issue 26: a parameter's range, description and read-only flag are written once, in the
table of its settings dataclass (``tactile_sl_common.settings``), which the dataclass's
``validate()`` also reads.  Here the running nodes are asked (``describe_parameters``) and
every answer is compared with its row; the other way round, every row must be declared.
"""
from __future__ import annotations

import pytest
from rclpy.parameter import parameter_value_to_python
from test_node_parameters import Client

from tactile_sl_decoder.extract.extraction import EXTRACTION_SETTINGS
from tactile_sl_decoder.nodes.decoder_settings import DECODER_TABLES, Declared

from ros_harness import next_domain_id, start_node, stop

pytestmark = pytest.mark.ros

READ_ONLY = " Applies at start only (read-only)."
NODES = {  # executable -> the tables it declares, and whether they are all its parameters
    "decoder": (DECODER_TABLES, True),
    "symbol_extractor": ((Declared("extraction", EXTRACTION_SETTINGS),), False),
}
# QoS parameters (declare_qos) and rclpy's own
NOT_IN_TABLES = ("qos.", "use_sim_time", "start_type_description_service")


def _range(descriptor) -> tuple[float, float] | None:
    ranges = list(descriptor.integer_range) + list(descriptor.floating_point_range)
    if not ranges:
        return None
    (r,) = ranges
    return (r.from_value, r.to_value)


def _compare(exe: str, tables: tuple[Declared, ...], complete: bool,
             client: Client) -> list[str]:
    c = client.client(f"/tactile/{exe}")
    names = list(client.wait(c.list_parameters()).result.names)
    described = client.wait(c.describe_parameters(names)).descriptors
    values = client.wait(c.get_parameters(names)).values
    rows = {d.prefix + row.name: (d, row) for d in tables for row in d.table}
    bad = [f"{exe}: table row {name} is not declared" for name in rows if name not in names]
    for name, desc, value in zip(names, described, values):
        if name.startswith(NOT_IN_TABLES):
            continue
        if name not in rows:
            if complete:
                bad.append(f"{exe}: {name} is declared outside the tables")
            continue
        d, row = rows[name]
        want = d.what + row.description + ("" if row.live else READ_ONLY)
        if desc.description != want:
            bad.append(f"{exe}: {name}: description {desc.description!r} != {want!r}")
        if desc.read_only == row.live:
            bad.append(f"{exe}: {name}: read_only {desc.read_only}, table live {row.live}")
        if _range(desc) != (tuple(float(x) for x in row.range) if row.range else None):
            bad.append(f"{exe}: {name}: range {_range(desc)} != table {row.range}")
        if parameter_value_to_python(value) != row.default:
            bad.append(f"{exe}: {name}: default {parameter_value_to_python(value)!r} != "
                       f"table {row.default!r}")
    return bad


def test_declared_parameters_match_their_tables(tmp_path):
    domain = next_domain_id()
    procs = [start_node("tactile_sl_decoder", exe, domain, ["-r", "__ns:=/tactile"],
                        tmp_path / f"{exe}.log") for exe in NODES]
    client = Client(domain)
    try:
        bad = [problem for exe, (tables, complete) in NODES.items()
               for problem in _compare(exe, tables, complete, client)]
    finally:
        client.close()
        codes = [stop(p) for p in procs]
    assert not bad, "\n".join(bad)
    assert codes == [0, 0], codes
