"""DDS traffic of the project's processes never leaves the loopback interface."""
from __future__ import annotations

import pytest

from test_symbol_array_roundtrip import symbol_array_roundtrip

pytestmark = pytest.mark.ros


def test_no_rtps_packet_outside_loopback(domain_id, dds_sniffer):
    if not dds_sniffer.available:
        pytest.skip(dds_sniffer.reason)
    seen_before = dds_sniffer.packets_seen
    # Real discovery and data exchange between two processes while the watch runs.
    symbol_array_roundtrip(domain_id)
    assert dds_sniffer.packets_seen > seen_before, "the leak watch saw no traffic at all"
    assert dds_sniffer.leaks == []
