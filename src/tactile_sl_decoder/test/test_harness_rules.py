"""One process-test harness (issue 9): no test file invents domains, executables or paths.

``tests/ros_harness.py`` alone sets ROS_DOMAIN_ID, starts rclpy, finds executables (through
the ament index, never an ``install/`` path) and knows where the workspace root is.  Tests
that start node processes or rclpy nodes live in ``tests/`` and are marked ``ros``; the unit
tests in ``src/<pkg>/test/`` start neither, so ``make unit`` stays fast.  Every file is read
with :mod:`ast`; nothing is imported or run.  (A workspace rule, kept here with the
decoder's import rules so that ``make unit`` runs it.)
"""
from __future__ import annotations

import ast
import pathlib
import re

import pytest

from ros_harness import REPO

HARNESS = REPO / "tests" / "ros_harness.py"
RULES = REPO / "src" / "tactile_sl_decoder" / "test" / "test_harness_rules.py"  # names them
UNIT_TEST_FILES = sorted(p for p in REPO.glob("src/*/test/**/*.py") if p != RULES)
PROCESS_TEST_FILES = sorted(p for p in (REPO / "tests").glob("*.py") if p != HARNESS)
INSTALL_PATH = re.compile(r"(^|/)install(/|$)")
PROCESS_MODULES = {"rclpy", "subprocess"}
PROCESS_HELPERS = {"Probe", "start_node", "running_node", "executable"}


def _parents(tree: ast.AST) -> dict[ast.AST, ast.AST]:
    return {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}


def _docstrings(tree: ast.AST) -> set[ast.AST]:
    return {node.body[0].value for node in ast.walk(tree)
            if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef,
                                 ast.AsyncFunctionDef))
            and node.body and isinstance(node.body[0], ast.Expr)
            and isinstance(node.body[0].value, ast.Constant)}


def _call_name(node: ast.AST) -> str:
    """``a.b.c`` for a call to a.b.c(...), else ''."""
    if not isinstance(node, ast.Call):
        return ""
    parts, func = [], node.func
    while isinstance(func, ast.Attribute):
        parts.append(func.attr)
        func = func.value
    if isinstance(func, ast.Name):
        parts.append(func.id)
    return ".".join(reversed(parts))


def directories_climbed(name: ast.Name, parents: dict[ast.AST, ast.AST],
                        walked: set[ast.AST] | None = None) -> int:
    """How far up from a test file an expression on ``__file__`` reaches (1: its folder).

    Counts ``.parent``, ``.parents[k]`` and ``os.path.dirname``; ``Path(...)``,
    ``.resolve()``, ``.absolute()`` and ``os.path.abspath/realpath`` keep the level.  The
    nodes of the expression go into ``walked``.
    """
    node, levels = name, 0
    walked = set() if walked is None else walked
    while node in parents:
        up = parents[node]
        if isinstance(up, ast.Attribute) and up.attr == "parent":
            levels += 1
        elif isinstance(up, ast.Attribute) and up.attr in ("resolve", "absolute", "parents"):
            pass
        elif isinstance(up, ast.Subscript) and isinstance(up.value, ast.Attribute) \
                and up.value.attr == "parents" and up.value is node:
            index = up.slice
            levels += index.value + 1 if isinstance(index, ast.Constant) else 99
        elif isinstance(up, ast.Call) and _call_name(up).split(".")[-1] in (
                "Path", "PurePath", "abspath", "realpath", "resolve", "absolute"):
            pass
        elif isinstance(up, ast.Call) and _call_name(up).endswith("dirname"):
            levels += 1
        else:
            break
        node = up
        walked.add(node)
    return levels


def harness_violations(path: pathlib.Path, source: str | None = None) -> list[str]:
    """What ``path`` does itself that only the harness may do."""
    source = path.read_text() if source is None else source
    tree = ast.parse(source)
    parents, docstrings = _parents(tree), _docstrings(tree)
    from_file: set[ast.AST] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Name) and node.id == "__file__":
            directories_climbed(node, parents, from_file)
    own_root = (REPO / "tests" if path.parent.name == "tests"
                else path.parents[len(path.relative_to(REPO).parts) - 3])  # src/<pkg>
    found = []
    for node in ast.walk(tree):
        where = f"{path.relative_to(REPO)}:{getattr(node, 'lineno', '?')}"
        if isinstance(node, ast.keyword) and node.arg == "ROS_DOMAIN_ID" \
                or isinstance(node, ast.Constant) and node.value == "ROS_DOMAIN_ID":
            found.append(f"{where} sets ROS_DOMAIN_ID (use ros_harness.ros_env/next_domain_id)")
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) \
                and node not in docstrings and INSTALL_PATH.search(node.value):
            found.append(f"{where} builds an install/ path (use ros_harness.executable)")
        elif _call_name(node).endswith("get_package_prefix"):
            found.append(f"{where} finds an executable itself (use ros_harness.executable)")
        elif _call_name(node) in ("rclpy.init", "init") and path.name.startswith("test_"):
            found.append(f"{where} starts rclpy itself (use ros_harness.Probe)")
        elif isinstance(node, ast.Name) and node.id == "__file__":
            levels = directories_climbed(node, parents)
            if levels and not path.parents[levels - 1].is_relative_to(own_root):
                found.append(f"{where} reaches {path.parents[levels - 1].relative_to(REPO)}/ "
                             f"from __file__ (use ros_harness.REPO or BAGS)")
        elif isinstance(node, ast.Subscript) and isinstance(node.value, ast.Attribute) \
                and node.value.attr == "parents" and node not in from_file:
            found.append(f"{where} climbs with .parents[...] from a path of its own "
                         f"(use ros_harness.REPO or BAGS)")
    return found


def _imports(tree: ast.AST) -> set[str]:
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module:
            names |= {node.module} | {a.name for a in node.names}
    return names


def starts_processes(tree: ast.AST) -> bool:
    """The file imports rclpy or subprocess, or the harness's process helpers."""
    names = _imports(tree)
    return bool(names & PROCESS_HELPERS) or any(n.split(".")[0] in PROCESS_MODULES
                                                for n in names)


def marked_ros(tree: ast.AST) -> bool:
    """A module-level ``pytestmark`` that includes ``pytest.mark.ros``."""
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
                isinstance(t, ast.Name) and t.id == "pytestmark" for t in node.targets):
            return any(isinstance(n, ast.Attribute) and n.attr == "ros"
                       for n in ast.walk(node.value))
    return False


@pytest.mark.parametrize("path", UNIT_TEST_FILES + PROCESS_TEST_FILES,
                         ids=lambda p: str(p.relative_to(REPO)))
def test_only_the_harness_sets_domains_finds_executables_and_the_root(path):
    assert harness_violations(path) == []


@pytest.mark.parametrize("path", UNIT_TEST_FILES, ids=lambda p: str(p.relative_to(REPO)))
def test_unit_tests_start_no_processes_and_no_rclpy(path):
    assert not starts_processes(ast.parse(path.read_text())), \
        f"{path.relative_to(REPO)} starts processes or rclpy: it belongs in tests/"


@pytest.mark.parametrize("path", [p for p in PROCESS_TEST_FILES if p.name.startswith("test_")
                                  and starts_processes(ast.parse(p.read_text()))],
                         ids=lambda p: p.name)
def test_process_tests_are_marked_ros(path):
    assert marked_ros(ast.parse(path.read_text())), \
        f"{path.name} starts processes: pytestmark = pytest.mark.ros (make unit skips it)"


def test_the_rules_catch_each_way_of_doing_it_alone():
    """The checks themselves: each of the old schemes is reported, the harness way is not."""
    probe = REPO / "tests" / "test_probe.py"
    bad = ("import os, pathlib, rclpy\n"
           "from ament_index_python.packages import get_package_prefix\n"
           "ROOT = pathlib.Path(__file__).resolve().parents[1]\n"
           "TOP = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))\n"
           "EXE = ROOT / 'install' / 'tactile_sl_decoder' / 'lib'\n"
           "LIB = get_package_prefix('tactile_sl_decoder')\n"
           "env = dict(os.environ, ROS_DOMAIN_ID='7')\n"
           "os.environ['ROS_DOMAIN_ID'] = '8'\n"
           "rclpy.init(domain_id=100 + os.getpid() % 100)\n"
           "TOOLS = (ROOT / 'src').parents[0] / 'tools'\n")
    found = harness_violations(probe, bad)
    for line, what in ((3, "reaches ./"), (4, "reaches ./"), (5, "builds an install/ path"),
                       (6, "finds an executable"), (7, "sets ROS_DOMAIN_ID"),
                       (8, "sets ROS_DOMAIN_ID"), (9, "starts rclpy"), (10, "climbs")):
        assert any(f.startswith(f"tests/test_probe.py:{line} {what}") for f in found), \
            (line, found)
    assert len(found) == 8, found
    good = ('"""Runs the node installed under install/."""\n'
            "import pathlib\nfrom ros_harness import BAGS, REPO, next_domain_id\n"
            "HERE = pathlib.Path(__file__).parent\n")
    assert harness_violations(probe, good) == []
    unit = REPO / "src" / "tactile_sl_decoder" / "test" / "test_probe.py"
    own_package = "import pathlib\nPKG = pathlib.Path(__file__).resolve().parents[1]\n"
    assert harness_violations(unit, own_package) == []
    assert harness_violations(unit, own_package.replace("[1]", "[3]")) != []
    assert starts_processes(ast.parse("from ros_harness import Probe\n"))
    assert starts_processes(ast.parse("from rclpy.qos import QoSProfile\n"))
    assert not starts_processes(ast.parse("from tactile_sl_msgs.msg import SymbolArray\n"))
    assert marked_ros(ast.parse("import pytest\npytestmark = [pytest.mark.ros]\n"))
    assert not marked_ros(ast.parse("import pytest\npytestmark = pytest.mark.slow\n"))
