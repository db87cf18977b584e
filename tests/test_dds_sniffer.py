"""The leak watch recognises RTPS inside UDP frames (so a silent watch means something)."""
import struct

from dds_sniffer import rtps_payload_offset


def udp_ipv4_frame(payload: bytes) -> bytes:
    ethernet = b"\x01\x00\x5e\x7f\x00\x01" + b"\x02" * 6 + struct.pack("!H", 0x0800)
    ip = struct.pack("!BBHHHBBH4s4s", 0x45, 0, 20 + 8 + len(payload), 0, 0, 1, 17, 0,
                     bytes([10, 0, 0, 2]), bytes([239, 255, 0, 1]))
    udp = struct.pack("!HHHH", 40000, 7400, 8 + len(payload), 0)
    return ethernet + ip + udp + payload


def test_rtps_in_udp_is_found():
    frame = udp_ipv4_frame(b"RTPS\x02\x04\x01\x0f" + b"\x00" * 12)
    offset = rtps_payload_offset(frame)
    assert frame[offset:offset + 4] == b"RTPS"


def test_non_udp_is_ignored():
    frame = bytearray(udp_ipv4_frame(b"RTPS"))
    frame[23] = 6  # TCP
    assert rtps_payload_offset(bytes(frame)) is None
    assert rtps_payload_offset(b"\x00" * 10) is None
