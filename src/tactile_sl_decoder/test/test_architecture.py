"""Dependency rules of the tactile-sl packages (docs/architecture.md), read from the imports.

Packages depend one way: ``tactile_sl_msgs`` <- ``tactile_sl_common`` <- {``tactile_sl_camera``,
``tactile_sl_sim``, ``tactile_sl_decoder``}; in the decoder only ``cli/``, ``tooling/`` and
``calibrate/simulate.py`` use the simulator, and nothing of it uses the camera package.
Inside the decoder, data flows one way, image -> glyphs -> labels -> cells -> points -> touch:
a stage imports no rclpy, no node, no CLI, no tooling, no image source and no simulator, and
never a later stage.  The shared library modules the stages and the pipeline build on follow
the same rule.  Every import counts, including those inside functions (read with
:mod:`ast`, nothing is imported).
"""
from __future__ import annotations

import ast
import pathlib
import re

import pytest

from ros_harness import REPO

PKG = pathlib.Path(__file__).resolve().parents[1] / "tactile_sl_decoder"
NAME = "tactile_sl_decoder"

STAGES = ["extract", "classify", "decode", "stereo", "touch"]   # in data-flow order
SHARED = ["pipeline.py", "glyphs.py", "frames.py", "symbol_array.py", "checks.py",
          "cpu_threads.py", "contract.py", "sensor_step.py"]
FORBIDDEN = ("rclpy", f"{NAME}.nodes", f"{NAME}.cli", f"{NAME}.tooling",
             "tactile_sl_common.nodes", "tactile_sl_camera", "tactile_sl_sim")

# The package graph: the tactile-sl packages each package's modules may import besides itself.
PACKAGE_DEPENDENCIES: dict[str, frozenset[str]] = {
    "tactile_sl_common": frozenset({"tactile_sl_msgs"}),
    "tactile_sl_camera": frozenset({"tactile_sl_msgs", "tactile_sl_common"}),
    "tactile_sl_sim": frozenset({"tactile_sl_msgs", "tactile_sl_common"}),
    "tactile_sl_decoder": frozenset({"tactile_sl_msgs", "tactile_sl_common", "tactile_sl_sim"}),
    "tactile_sl_viewer": frozenset({"tactile_sl_msgs", "tactile_sl_common", "tactile_sl_decoder"}),
}
# Inside the decoder, the simulator is for these only (paths under tactile_sl_decoder/).
SIMULATOR_USERS = ("cli/", "tooling/", "calibrate/simulate.py")
OUR_PACKAGE = re.compile(r"^tactile_sl_[a-z]+")


def _module_name(path: pathlib.Path, package_root: pathlib.Path = PKG.parent) -> str:
    parts = list(path.relative_to(package_root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def imports_of(path: pathlib.Path, module_name: str | None = None) -> set[str]:
    """Absolute names of every module ``path`` imports (relative imports resolved).

    ``module_name``: the dotted name the file has (default: from its place in the package).
    """
    tree = ast.parse(path.read_text(), filename=str(path))
    package = (module_name or _module_name(path)).split(".")
    if path.name != "__init__.py":
        package = package[:-1]
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = ".".join(package[:len(package) - node.level + 1])
                module = f"{base}.{node.module}" if node.module else base
            else:
                module = node.module or ""
            found.add(module)
            # `from pkg import sub` may import a submodule: count pkg.sub too
            found.update(f"{module}.{alias.name}" for alias in node.names)
    return found


def package_graph_violations(src: pathlib.Path) -> list[str]:
    """Imports under ``src`` (a colcon ``src/`` folder) that the package graph forbids.

    A package's modules and its tests may import only the packages it depends on
    (:data:`PACKAGE_DEPENDENCIES`); of the decoder's modules only :data:`SIMULATOR_USERS`
    import the simulator.
    """
    bad = []
    for package, allowed in PACKAGE_DEPENDENCIES.items():
        root = src / package
        for path in sorted(root.rglob("*.py")):
            rel = path.relative_to(root)
            if rel.parts[0] not in (package, "test"):
                continue                         # setup.py, launch files: no imports of ours
            inside = rel.relative_to(package).as_posix() if rel.parts[0] == package else ""
            first: dict[str, str] = {}        # each other package once per file
            for name in sorted(imports_of(path, _module_name(path, root))):
                top = OUR_PACKAGE.match(name)
                if top is not None and top.group(0) != package:
                    first.setdefault(top.group(0), name)
            for other, name in first.items():
                if other not in allowed:
                    bad.append(f"{package}/{rel.as_posix()} imports {name}: {package} does not "
                               f"depend on {other}")
                elif (other == "tactile_sl_sim" and rel.parts[0] == package
                      and not inside.startswith(SIMULATOR_USERS)):
                    bad.append(f"{package}/{rel.as_posix()} imports {name}: only "
                               f"{', '.join(SIMULATOR_USERS)} use the simulator")
    return bad


def test_packages_depend_one_way():
    bad = package_graph_violations(REPO / "src")
    assert not bad, "\n".join(bad)


def _write(path: pathlib.Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)


def test_the_package_graph_checker_fails_on_a_forbidden_import(tmp_path):
    """A tree with one import of each forbidden kind: each is reported, nothing else."""
    src = tmp_path / "src"
    _write(src / "tactile_sl_common/tactile_sl_common/ok.py", "import tactile_sl_msgs.msg\n")
    _write(src / "tactile_sl_common/tactile_sl_common/up.py",
           "def f():\n    from tactile_sl_decoder import pipeline\n")
    _write(src / "tactile_sl_camera/tactile_sl_camera/across.py", "import tactile_sl_sim.render\n")
    _write(src / "tactile_sl_sim/test/test_x.py", "from tactile_sl_camera import replay\n")
    _write(src / "tactile_sl_decoder/tactile_sl_decoder/cli/ok.py",
           "import tactile_sl_sim.render\n")
    _write(src / "tactile_sl_decoder/tactile_sl_decoder/touch/sim.py",
           "from tactile_sl_sim.loads import LoadContact\n")
    _write(src / "tactile_sl_decoder/tactile_sl_decoder/nodes/cam.py",
           "from tactile_sl_camera.replay import ReplayPlan\n")
    bad = package_graph_violations(src)
    assert len(bad) == 5, bad
    for where in ("tactile_sl_common/up.py", "tactile_sl_camera/across.py",
                  "test/test_x.py", "touch/sim.py", "nodes/cam.py"):
        assert any(where in b for b in bad), (where, bad)


def _is_under(name: str, prefix: str) -> bool:
    return name == prefix or name.startswith(prefix + ".")


def _stage_files(stage: str) -> list[pathlib.Path]:
    return sorted((PKG / stage).rglob("*.py"))


def test_the_stages_exist():
    for stage in STAGES:
        assert (PKG / stage / "__init__.py").is_file(), stage
        assert _stage_files(stage), stage


@pytest.mark.parametrize("stage", STAGES)
def test_stages_import_no_rclpy_nodes_cli_or_tooling(stage):
    bad = [f"{path.relative_to(PKG)} imports {name}"
           for path in _stage_files(stage) for name in sorted(imports_of(path))
           if any(_is_under(name, f) for f in FORBIDDEN)]
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("stage", STAGES)
def test_stages_never_reach_up(stage):
    """A stage imports no later stage and not the pipeline that composes them."""
    later = [f"{NAME}.{s}" for s in STAGES[STAGES.index(stage) + 1:]]
    up = later + [f"{NAME}.pipeline", f"{NAME}.calibrate"]
    bad = [f"{path.relative_to(PKG)} imports {name}"
           for path in _stage_files(stage) for name in sorted(imports_of(path))
           if any(_is_under(name, u) for u in up)]
    assert not bad, "\n".join(bad)


def test_shared_library_modules_import_no_rclpy_nodes_cli_or_tooling():
    bad = [f"{name_} imports {name}"
           for name_ in SHARED if (PKG / name_).exists()
           for name in sorted(imports_of(PKG / name_))
           if any(_is_under(name, f) for f in FORBIDDEN)]
    assert not bad, "\n".join(bad)


def test_tooling_is_imported_only_by_cli_tooling_and_tools():
    allowed = ("cli", "tooling")
    bad = []
    for path in sorted(PKG.rglob("*.py")):
        rel = path.relative_to(PKG)
        if rel.parts[0] in allowed:
            continue
        bad += [f"{rel} imports {name}" for name in sorted(imports_of(path))
                if _is_under(name, f"{NAME}.tooling")]
    assert not bad, "\n".join(bad)


def test_the_checker_sees_violations(tmp_path):
    """The reader itself: absolute, relative and function-local imports are all found."""
    probe = tmp_path / "probe.py"
    probe.write_text("import rclpy\n"
                     "from ..tooling import training\n"
                     "def f():\n    from tactile_sl_decoder.nodes import decoder_node\n")
    names = imports_of(probe, f"{NAME}.decode.probe")
    assert "rclpy" in names
    assert f"{NAME}.tooling.training" in names
    assert f"{NAME}.nodes.decoder_node" in names


LAZY_IMPORTS = ("torch", "tactile_sl_decoder.classify.model")
"""What a function may import itself: torch (1-2 s) is for training and old weight files only,
and the nodes and the other commands must not pay for it.  Everything else is imported at the
top of its module (the CLI imports only the module of the command it runs)."""


def function_local_imports(path: pathlib.Path) -> list[tuple[int, str]]:
    """(line, module) of every import inside a function of ``path``."""
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            for sub in ast.walk(node):
                if isinstance(sub, ast.Import):
                    found += [(sub.lineno, alias.name) for alias in sub.names]
                elif isinstance(sub, ast.ImportFrom):
                    found.append((sub.lineno, "." * sub.level + (sub.module or "")))
    return sorted(set(found))


def test_functions_import_only_what_start_up_time_keeps_out_of_the_module_top():
    bad = []
    for package in PACKAGE_DEPENDENCIES:
        root = REPO / "src" / package
        for path in sorted((root / package).rglob("*.py")):
            bad += [f"{path.relative_to(REPO)}:{line} imports {name} in a function"
                    for line, name in function_local_imports(path)
                    if not any(_is_under(name, lazy) for lazy in LAZY_IMPORTS)]
    assert not bad, "\n".join(bad)


def test_the_local_import_reader_sees_nested_and_relative_imports(tmp_path):
    probe = tmp_path / "probe.py"
    probe.write_text("import os\n"
                     "def f():\n    def g():\n        from ..x import y\n    import torch\n")
    assert function_local_imports(probe) == [(4, "..x"), (5, "torch")]


CONTRACT_NAMES = {"LABEL_UNKNOWN", "CELL_UNKNOWN", "PATCH_SIZE", "PATCH", "SLIP_NO_CONTACT",
                  "SLIP_STICK", "SLIP_PARTIAL", "SLIP_GROSS"}


def test_contract_numbers_have_one_definition():
    """LABEL_UNKNOWN, CELL_UNKNOWN, the patch size and the slip states: contract.py only."""
    bad = []
    for path in sorted(PKG.rglob("*.py")):
        if path.name == "contract.py" and path.parent == PKG:
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            targets = node.targets if isinstance(node, ast.Assign) else (
                [node.target] if isinstance(node, ast.AnnAssign) else [])
            bad += [f"{path.relative_to(PKG)}:{node.lineno} defines {t.id}"
                    for t in targets if isinstance(t, ast.Name) and t.id in CONTRACT_NAMES]
    assert not bad, "\n".join(bad)


def test_contract_mirrors_the_symbol_array_message():
    from tactile_sl_decoder import contract
    from tactile_sl_msgs import msg
    assert contract.LABEL_UNKNOWN == msg.SymbolArray.LABEL_UNKNOWN
    assert contract.CELL_UNKNOWN == msg.SymbolArray.CELL_UNKNOWN


def test_contract_mirrors_the_slip_message():
    from tactile_sl_decoder import contract
    from tactile_sl_msgs import msg
    assert (contract.SLIP_NO_CONTACT, contract.SLIP_STICK, contract.SLIP_PARTIAL,
            contract.SLIP_GROSS) == (msg.Slip.STATE_NO_CONTACT, msg.Slip.STATE_STICK,
                                     msg.Slip.STATE_PARTIAL_SLIP, msg.Slip.STATE_GROSS_SLIP)


SOURCE_ROOTS = {name: REPO / "src" / name for name in PACKAGE_DEPENDENCIES}
DOTTED = re.compile(r"\btactile_sl_(?:decoder|camera|common|sim|msgs)(?:\.[A-Za-z_]\w*)+")
RELATIVE_MOD = re.compile(r":mod:`(\.+[A-Za-z_][\w.]*)`")   # :mod:`.solve` in a package module


def _top_level_names(path: pathlib.Path) -> dict[str, ast.AST]:
    """Names a module defines or imports at top level (classes keep their node)."""
    names: dict[str, ast.AST] = {}
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names[node.name] = node
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            names.update((alias.asname or alias.name.split(".")[0], node)
                         for alias in node.names)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names.update((t.id, node) for target in targets for t in ast.walk(target)
                         if isinstance(t, ast.Name))
    return names


def dotted_name_exists(name: str) -> bool:
    """Whether ``tactile_sl_*.a.b`` names a module, or a name a module defines (read, not run).

    Messages: ``tactile_sl_msgs.msg.X`` needs ``src/tactile_sl_msgs/msg/X.msg``.
    """
    parts = name.split(".")
    if parts[0] == "tactile_sl_msgs":
        if parts[1:2] != ["msg"]:
            return len(parts) == 1
        return len(parts) == 2 or (REPO / "src/tactile_sl_msgs/msg" / f"{parts[2]}.msg").is_file()
    root = SOURCE_ROOTS[parts[0]]
    for k in range(len(parts), 0, -1):
        base = root.joinpath(*parts[:k])
        module = base / "__init__.py" if base.is_dir() else base.with_suffix(".py")
        if module.is_file():
            break
    else:
        return False
    rest = parts[k:]
    if not rest:
        return True
    node = _top_level_names(module).get(rest[0])
    if node is None:
        return False
    if len(rest) > 1 and isinstance(node, ast.ClassDef):   # Class.member
        members = {n.name for n in node.body if isinstance(n, (ast.FunctionDef, ast.ClassDef))}
        members |= {t.id for n in node.body if isinstance(n, (ast.Assign, ast.AnnAssign))
                    for t in (n.targets if isinstance(n, ast.Assign) else [n.target])
                    if isinstance(t, ast.Name)}
        return rest[1] in members
    return True


def _text_files() -> list[pathlib.Path]:
    """Docs and Python sources, but not this file (its examples name missing things)."""
    files = sorted(REPO.glob("*.md")) + sorted((REPO / "docs").rglob("*.md"))
    for folder in ("src", "tests", "tools"):
        files += sorted(p for p in (REPO / folder).rglob("*.py") if ".mypy_cache" not in p.parts)
    return [p for p in files if p.resolve() != pathlib.Path(__file__).resolve()]


def test_dotted_names_in_docs_comments_and_code_exist():
    """Every ``tactile_sl_*.x.y`` written in docs, docstrings or comments names real code.

    Modules move (the by-stage layout moved extraction, grid, stereo, ...); a stale path in a
    docstring sends the reader nowhere.
    """
    bad = []
    for path in _text_files():
        package = _package_of(path)
        for lineno, line in enumerate(path.read_text(errors="replace").splitlines(), 1):
            names = DOTTED.findall(line)
            if package:
                names += [_absolute(rel, package) for rel in RELATIVE_MOD.findall(line)]
            bad += [f"{path.relative_to(REPO)}:{lineno}: {name}"
                    for name in names if not dotted_name_exists(name)]
    assert not bad, "names that no module defines:\n" + "\n".join(bad)


def _package_of(path: pathlib.Path) -> list[str]:
    """Dotted package of a library module as a list ([] outside the packages)."""
    for top, root in SOURCE_ROOTS.items():
        if (root / top) in path.parents:
            return list(path.relative_to(root).parent.parts)
    return []


def _absolute(relative: str, package: list[str]) -> str:
    level = len(relative) - len(relative.lstrip("."))
    return ".".join(package[:len(package) - level + 1] + [relative.lstrip(".")])


def test_dotted_name_checker_tells_real_from_stale():
    assert dotted_name_exists("tactile_sl_decoder.decode.grid")
    assert dotted_name_exists("tactile_sl_decoder.pipeline.StereoPipeline.process")
    assert dotted_name_exists("tactile_sl_common.bag_io")
    assert dotted_name_exists("tactile_sl_msgs.msg.SymbolArray")
    assert not dotted_name_exists("tactile_sl_decoder.grid")          # moved to decode/
    assert not dotted_name_exists("tactile_sl_decoder.pipeline.NoSuchThing")
    assert not dotted_name_exists("tactile_sl_decoder.pipeline.StereoPipeline.no_such_method")
    assert not dotted_name_exists("tactile_sl_msgs.msg.NoSuchMessage")
    package = _package_of(PKG / "calibrate" / "solve.py")
    assert _absolute(".health", package) == "tactile_sl_decoder.calibrate.health"
    assert _absolute("..pipeline", package) == "tactile_sl_decoder.pipeline"
