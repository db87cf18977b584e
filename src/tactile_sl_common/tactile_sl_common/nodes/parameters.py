"""One parameter mechanism for every node: described, typed, ranged; live changes validated.

Every parameter is declared with a :class:`~rcl_interfaces.msg.ParameterDescriptor` holding
its description, its range (``FloatingPointRange`` / ``IntegerRange``) and ``read_only``
for what only applies at start (QoS, files, thread counts), so ``ros2 param describe``
tells the truth and rclpy itself refuses an out-of-range value or a change to a start-only
setting, with its reason.  What can change while running goes through one
on-set-parameters callback (:class:`LiveParameters`): every new value of a request is first
checked by its validator, then all are applied together, or the request is refused with the
reason; a parameter that is neither read-only nor live cannot be declared.

Descriptions of dataclass fields come from the field's docstring (:func:`field_docs`), so a
params dataclass documents its node parameters once.
"""
from __future__ import annotations

import ast
import dataclasses
import inspect
import textwrap
from typing import Any, Callable

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    SetParametersResult,
)
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

Apply = Callable[[Any], None]
Check = Callable[[Any], "str | None"]


def descriptor(description: str, value_range: tuple[float, float] | None = None,
               default: Any = None, read_only: bool = False) -> ParameterDescriptor:
    """A descriptor with a range of the default's type (int or float)."""
    d = ParameterDescriptor(description=description, read_only=read_only)
    if value_range is not None:
        low, high = value_range
        if isinstance(default, int) and not isinstance(default, bool):
            d.integer_range = [IntegerRange(from_value=int(low), to_value=int(high), step=1)]
        else:
            d.floating_point_range = [FloatingPointRange(from_value=float(low),
                                                         to_value=float(high))]
    return d


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


class LiveParameters:
    """Declares a node's parameters and applies live changes through one callback."""

    def __init__(self, node: Any) -> None:
        self.node = node
        self._live: dict[str, tuple[Check | None, Apply]] = {}
        self._group_checks: list[Callable[[dict[str, Any]], str | None]] = []
        node.add_on_set_parameters_callback(self._on_set)

    def declare(self, name: str, default: Any, description: str,
                value_range: tuple[float, float] | None = None, read_only: bool = False,
                apply: Apply | None = None, check: Check | None = None) -> Any:
        """Declare one parameter; ``apply`` (live) or ``read_only`` is required.

        Returns the value given at start (after rclpy's type and range checks); ``check``
        is also run on it, and a refusal there raises ValueError (one FATAL line).
        """
        if apply is None and not read_only:
            raise TypeError(f"parameter {name}: give apply= (live) or read_only=True")
        if apply is not None:
            how = ""
        else:
            how = " Applies at start only (read-only)."
        self.node.declare_parameter(name, default, descriptor(description + how, value_range,
                                                              default, read_only))
        value = self.node.get_parameter(name).value
        if check is not None:
            reason = check(value)
            if reason:
                raise ValueError(f"parameter {name}={value!r}: {reason}")
        if apply is not None:
            self._live[name] = (check, apply)
        return value

    def check_together(self, check: Callable[[dict[str, Any]], str | None]) -> None:
        """A check over several parameters: gets {name: new or current value}."""
        self._group_checks.append(check)

    def _on_set(self, params: list[Any]) -> SetParametersResult:
        changes = {p.name: p.value for p in params}
        for name, value in changes.items():
            if name not in self._live:
                continue          # read-only ones are refused by rclpy itself
            check, _ = self._live[name]
            reason = check(value) if check is not None else None
            if reason:
                return SetParametersResult(successful=False, reason=f"{name}: {reason}")
        for group in self._group_checks:
            current = {n: (changes[n] if n in changes else self.node.get_parameter(n).value)
                       for n in self._live}
            reason = group(current)
            if reason:
                return SetParametersResult(successful=False, reason=reason)
        applied = []
        for name, value in changes.items():
            if name in self._live:
                self._live[name][1](value)
                applied.append(f"{name}={value!r}")
        if applied:
            self.node.get_logger().info(f"parameters applied: {', '.join(applied)}")
        return SetParametersResult(successful=True)


def dataclass_fields(obj: Any) -> list[tuple[str, Any]]:
    """(name, default) of the scalar fields of a dataclass instance."""
    return [(f.name, getattr(obj, f.name)) for f in dataclasses.fields(obj)
            if isinstance(getattr(obj, f.name), (bool, int, float, str))]


FRAME_PREFIX_DOC = ("Prepended to every frame id this node publishes (e.g. 'left_hand_'), so "
                    "several sensors on one robot have distinct frames; empty = none.")


def frame_prefix_check(prefix: str) -> str | None:
    """Why ``prefix`` cannot start frame ids (None when it can)."""
    if prefix.startswith("/") or any(c.isspace() for c in prefix):
        return "a frame id prefix has no leading '/' and no spaces (REP 105 frame names)"
    return None


RELIABILITY = {"reliable": ReliabilityPolicy.RELIABLE, "best_effort": ReliabilityPolicy.BEST_EFFORT}
DURABILITY = {"volatile": DurabilityPolicy.VOLATILE,
              "transient_local": DurabilityPolicy.TRANSIENT_LOCAL}


def _choice(options: dict[str, Any]) -> Check:
    return lambda v: None if v in options else f"must be one of {', '.join(options)}"


def declare_qos(live: LiveParameters, name: str, what: str, depth: int,
                reliability: str = "reliable", durability: str = "volatile",
                fixed: tuple[str, ...] = ()) -> QoSProfile:
    """QoS of publishers or subscriptions from ``qos.<name>.reliability|depth|durability``.

    Read-only parameters (QoS is fixed when the endpoint is created); the defaults are the
    node's documented choice (README "QoS").  History is always KEEP_LAST ``depth``.  Names
    in ``fixed`` ('reliability', 'depth') are not declared: the node already has a parameter
    for them (e.g. the decoder's ``input_depth``) and passes its value.
    """
    rel, dep = reliability, int(depth)
    if "reliability" not in fixed:
        rel = str(live.declare(f"qos.{name}.reliability", reliability,
                               f"QoS reliability of {what}: reliable or best_effort.",
                               check=_choice(RELIABILITY), read_only=True))
    if "depth" not in fixed:
        dep = int(live.declare(f"qos.{name}.depth", int(depth),
                               f"QoS history depth (keep last) of {what}.", (1, 10000),
                               read_only=True))
    dur = str(live.declare(f"qos.{name}.durability", durability,
                           f"QoS durability of {what}: volatile or transient_local (late "
                           "joiners get the last messages).", check=_choice(DURABILITY),
                           read_only=True))
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=dep,
                      reliability=RELIABILITY[rel], durability=DURABILITY[dur])
