"""Two network namespaces joined only to each other by a veth pair: two "computers" for tests.

Nothing is attached to the machine's own interfaces: each namespace holds its own `lo` and
one end of the veth pair, addressed in a link-local /30 (169.254.x.y), so DDS traffic
between them never reaches the root namespace (where the leak watch listens) or any real
network. `ip netns exec` gives each process its own mount namespace as well; `in_netns`
mounts a private tmpfs on /dev/shm there, so Fast DDS's shared-memory transport cannot
carry data between the two namespaces either: only the veth link can, as between two
computers.
"""
from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import shutil
import subprocess
from typing import Iterator


@dataclasses.dataclass(frozen=True)
class NetnsPair:
    """Names and addresses of one namespace pair (a and b)."""

    ns_a: str
    ns_b: str
    veth_a: str
    veth_b: str
    addr_a: str
    addr_b: str


def unavailable_reason() -> str | None:
    """Why this process cannot create network namespaces, or None if it can."""
    if shutil.which("ip") is None:
        return "the `ip` command (iproute2) is missing: apt-get install iproute2"
    if os.geteuid() != 0:
        return f"creating network namespaces needs root (running as uid {os.geteuid()})"
    return None


def _ip(*args: str) -> None:
    result = subprocess.run(["ip", *args], capture_output=True, text=True, timeout=10)
    if result.returncode != 0:
        raise RuntimeError(f"`ip {' '.join(args)}` failed: {result.stderr.strip()}")


def _delete(pair: NetnsPair) -> list[str]:
    """Remove both namespaces (their veth ends go with them); returns what failed."""
    problems = []
    for ns in (pair.ns_a, pair.ns_b):
        result = subprocess.run(["ip", "netns", "delete", ns], capture_output=True, text=True,
                                timeout=10)
        if result.returncode != 0 and "No such file" not in result.stderr:
            problems.append(f"ip netns delete {ns}: {result.stderr.strip()}")
    # A veth end left in the root namespace (creation failed half-way) is removed too.
    for veth in (pair.veth_a, pair.veth_b):
        if subprocess.run(["ip", "link", "show", veth], capture_output=True).returncode == 0:
            subprocess.run(["ip", "link", "delete", veth], capture_output=True)
    return problems


@contextlib.contextmanager
def netns_pair(tag: str) -> Iterator[NetnsPair]:
    """Create the pair, yield it, and delete it again, also when the body fails."""
    pid = os.getpid()
    base = f"tsl{tag}{pid % 100000}"          # interface names: at most 15 characters
    subnet = 4 * (pid % 64)                   # a /30 inside 169.254.200.0/24
    pair = NetnsPair(ns_a=f"{base}a", ns_b=f"{base}b", veth_a=f"{base}va", veth_b=f"{base}vb",
                     addr_a=f"169.254.200.{subnet + 1}", addr_b=f"169.254.200.{subnet + 2}")
    try:
        _ip("netns", "add", pair.ns_a)
        _ip("netns", "add", pair.ns_b)
        # Created directly inside namespace a, then one end moved to b: never in the root one.
        _ip("-n", pair.ns_a, "link", "add", pair.veth_a, "type", "veth", "peer", "name",
            pair.veth_b)
        _ip("-n", pair.ns_a, "link", "set", pair.veth_b, "netns", pair.ns_b)
        for ns, veth, addr in ((pair.ns_a, pair.veth_a, pair.addr_a),
                               (pair.ns_b, pair.veth_b, pair.addr_b)):
            _ip("-n", ns, "addr", "add", f"{addr}/30", "dev", veth)
            _ip("-n", ns, "link", "set", "lo", "up")
            _ip("-n", ns, "link", "set", veth, "up")
        yield pair
    finally:
        problems = _delete(pair)
        if problems:
            raise RuntimeError("; ".join(problems))


def veth_counters(ns: str, veth: str) -> tuple[int, int]:
    """(rx bytes, tx bytes) of a veth end inside a namespace."""
    out = subprocess.run(["ip", "-n", ns, "-j", "-s", "link", "show", "dev", veth],
                         capture_output=True, text=True, timeout=10, check=True).stdout
    stats = json.loads(out)[0]["stats64"]
    return int(stats["rx"]["bytes"]), int(stats["tx"]["bytes"])


# Run a command inside a namespace with its own /dev/shm (a computer of its own).
_SHELL = 'mount -t tmpfs -o size=256m tsl_shm /dev/shm || exit 97; exec "$@"'


def in_netns(ns: str, argv: list[str]) -> list[str]:
    """argv run inside namespace ns, with a private /dev/shm."""
    return ["ip", "netns", "exec", ns, "sh", "-c", _SHELL, "sh", *argv]
