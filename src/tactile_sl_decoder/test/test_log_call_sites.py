"""One severity per log call site (issue 28, item 1).

rclpy remembers the severity of each logging call site (file, function, line) on its first
call and raises ``ValueError: Logger severity cannot be changed between calls`` when the
same site logs at another severity later.  ``(log.info if ok else log.warning)(text)`` is
such a site: the decoder's ``tare`` service died on the second answer that differed from
the first (accepted, then refused), and the caller got no reply.  Every module of both
packages is read with :mod:`ast` and no expression may choose between logger methods.
"""
from __future__ import annotations

import ast

from ros_harness import REPO

LOG_METHODS = {"debug", "info", "warn", "warning", "error", "fatal"}
MODULES = sorted(p for p in REPO.glob("src/*/tactile_sl_*/**/*.py"))


def _log_method(node: ast.AST) -> bool:
    return isinstance(node, ast.Attribute) and node.attr in LOG_METHODS


def severity_switches(source: str) -> list[int]:
    """Lines where an expression picks a logger method by condition (``a.info if c else
    a.warning``), the call site whose severity would change between calls."""
    return [node.lineno for node in ast.walk(ast.parse(source))
            if isinstance(node, ast.IfExp) and _log_method(node.body)
            and _log_method(node.orelse)]


def test_the_check_finds_the_pattern():
    bad = "def f(log, ok):\n    (log.info if ok else log.warning)('tare')\n"
    assert severity_switches(bad) == [2]
    good = ("def f(log, ok):\n    if ok:\n        log.info('tare')\n    else:\n"
            "        log.warning('tare')\n")
    assert severity_switches(good) == []


def test_no_call_site_switches_severity():
    found = [f"{path.relative_to(REPO)}:{line}" for path in MODULES
             for line in severity_switches(path.read_text())]
    assert MODULES and found == [], f"one call site per severity (rclpy refuses a change): {found}"
