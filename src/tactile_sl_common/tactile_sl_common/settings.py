"""Parameter tables: each settings dataclass says once what its fields may be (no rclpy).

A :class:`SettingsTable` lists the fields of one settings dataclass that a user can set, with
per field its default (the dataclass's), its description (the docstring written under the
field, :func:`field_docs`), its range (inclusive, as ROS's ``IntegerRange`` /
``FloatingPointRange``), whether it may change while a node runs, and any check beyond the
range.  The dataclass's ``validate()`` reads the ranges from it, and a node declares its ROS
parameters from it (:meth:`tactile_sl_common.nodes.parameters.LiveParameters.declare_table`),
so a range is written in one place and the library and the node cannot disagree.
"""
from __future__ import annotations

import ast
import dataclasses
import inspect
import textwrap
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Mapping

Check = Callable[[Any], "str | None"]


def field_docs(cls: type) -> dict[str, str]:
    """The docstrings written under the fields of a dataclass (one line each, joined)."""
    try:
        tree = ast.parse(textwrap.dedent(inspect.getsource(cls)))
    except (OSError, TypeError, SyntaxError):
        return {}
    body = tree.body[0].body if tree.body and isinstance(tree.body[0], ast.ClassDef) else []
    docs: dict[str, str] = {}
    for node, nxt in zip(body, body[1:]):
        if (isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name)
                and isinstance(nxt, ast.Expr) and isinstance(nxt.value, ast.Constant)
                and isinstance(nxt.value.value, str)):
            docs[node.target.id] = " ".join(nxt.value.value.split())
    return docs


FRAME_PREFIX_DOC = ("Prepended to every frame id this node publishes (e.g. 'left_hand_'), so "
                    "several sensors on one robot have distinct frames; empty = none.")


def frame_prefix_check(prefix: str) -> str | None:
    """Why ``prefix`` cannot start frame ids (None when it can)."""
    if prefix.startswith("/") or any(c.isspace() for c in prefix):
        return "a frame id prefix has no leading '/' and no spaces (REP 105 frame names)"
    return None


def scalar_fields(cls: type) -> list[str]:
    """The fields of a dataclass whose defaults are plain bool, int, float or str."""
    defaults = cls()
    return [f.name for f in dataclasses.fields(cls)
            if isinstance(getattr(defaults, f.name), (bool, int, float, str))]


@dataclass(frozen=True)
class Setting:
    """One row of a table: a field a user can set."""

    name: str
    default: Any
    description: str
    range: tuple[float, float] | None = None
    live: bool = True
    check: Check | None = None

    def problem(self, value: Any) -> str | None:
        """Why ``value`` is refused (out of range, or the row's own check), or None."""
        if self.range is not None:
            low, high = self.range
            if not low <= value <= high:
                return f"must be in [{low:g}, {high:g}], got {value!r}"
        return self.check(value) if self.check is not None else None


class SettingsTable:
    """The settable fields of one settings dataclass, with their ranges and descriptions."""

    def __init__(self, cls: type, ranges: Mapping[str, tuple[float, float]] | None = None,
                 fields: Iterable[str] | None = None, read_only: Iterable[str] = (),
                 checks: Mapping[str, Check] | None = None) -> None:
        """``fields``: the settable ones (default: every scalar field, in declaration order).

        ``ranges`` and ``checks`` give rows a range or a check; ``read_only`` rows apply at
        start only.  Every field named must exist and have a docstring.
        """
        names = list(fields) if fields is not None else scalar_fields(cls)
        ranges, checks = dict(ranges or {}), dict(checks or {})
        docs, defaults = field_docs(cls), cls()
        named = set(ranges) | set(checks) | set(read_only) | set(names)
        unknown = sorted(named - {f.name for f in dataclasses.fields(cls)})
        if unknown:
            raise TypeError(f"{cls.__name__} has no field {', '.join(unknown)}")
        missing = [n for n in names if n not in docs]
        if missing:
            raise TypeError(f"{cls.__name__}: no docstring under {', '.join(missing)}")
        self.cls = cls
        self.rows = {n: Setting(n, getattr(defaults, n), docs[n], ranges.get(n),
                                n not in set(read_only), checks.get(n)) for n in names}

    def __iter__(self) -> Any:
        return iter(self.rows.values())

    def __getitem__(self, name: str) -> Setting:
        return self.rows[name]

    def check(self, settings: Any, prefix: str = "") -> None:
        """Raise ValueError naming the first field of ``settings`` the table refuses."""
        for row in self.rows.values():
            reason = row.problem(getattr(settings, row.name))
            if reason:
                raise ValueError(f"{prefix}{row.name} {reason}")
