"""Watch every non-loopback interface for RTPS (DDS) packets while the tests run.

An AF_PACKET socket sees all frames on all interfaces; any UDP payload starting with the
RTPS magic on an interface other than `lo` means discovery or data left the machine.
Needs CAP_NET_RAW (root); without it, `available` is False and the reason says why.
"""
from __future__ import annotations

import select
import socket
import struct
import threading

ETH_P_ALL = 0x0003
ETH_P_IP = 0x0800
ETH_P_IPV6 = 0x86DD


def rtps_payload_offset(frame: bytes) -> int | None:
    """Offset of the UDP payload if the Ethernet frame carries IPv4/IPv6 UDP, else None."""
    if len(frame) < 14:
        return None
    ethertype = struct.unpack_from("!H", frame, 12)[0]
    if ethertype == ETH_P_IP and len(frame) >= 34:
        ihl = (frame[14] & 0x0F) * 4
        if frame[23] != 17:  # not UDP
            return None
        return 14 + ihl + 8
    if ethertype == ETH_P_IPV6 and len(frame) >= 62:
        if frame[20] != 17:
            return None
        return 14 + 40 + 8
    return None


class DdsSniffer:
    """Counts RTPS packets seen on interfaces other than loopback."""

    def __init__(self) -> None:
        self.leaks: list[str] = []
        self.packets_seen = 0
        self.available = False
        self.reason = ""
        self._stop = threading.Event()
        try:
            self._sock = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(ETH_P_ALL))
            self.available = True
        except (PermissionError, OSError, AttributeError) as exc:
            self.reason = f"cannot open a raw packet socket ({exc})"
            self._sock = None
        self._thread = threading.Thread(target=self._run, daemon=True)

    def start(self) -> "DdsSniffer":
        if self.available:
            self._thread.start()
        return self

    def _run(self) -> None:
        assert self._sock is not None
        while not self._stop.is_set():
            ready, _, _ = select.select([self._sock], [], [], 0.2)
            if not ready:
                continue
            frame, address = self._sock.recvfrom(65535)
            self.packets_seen += 1
            interface = address[0]
            if interface == "lo":
                continue
            offset = rtps_payload_offset(frame)
            if offset is not None and frame[offset:offset + 4] == b"RTPS":
                if len(self.leaks) < 20:
                    self.leaks.append(f"RTPS packet on interface {interface}")

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(2)
        if self._sock is not None:
            self._sock.close()
