"""One parameter mechanism for every node: described, typed, ranged; live changes validated.

Every parameter is declared with a :class:`~rcl_interfaces.msg.ParameterDescriptor` holding
its description, its range (``FloatingPointRange`` / ``IntegerRange``) and ``read_only``
for what only applies at start (QoS, files, thread counts), so ``ros2 param describe``
tells the truth and rclpy itself refuses an out-of-range value or a change to a start-only
setting, with its reason.  What can change while running goes through
:class:`LiveParameters`, in two steps as rclpy intends (demo_nodes_py's
``set_parameters_callback``): the on-set callback only *validates* every new value of a
request (its own check, and the settings dataclass it belongs to as it would be after the
change) and refuses the whole request with the reason; the post-set callback *applies* the
accepted values, so a refusal never leaves a request half applied.  A parameter that is
neither read-only nor live cannot be declared.

A settings dataclass is declared from its table (:meth:`LiveParameters.declare_table`,
:class:`tactile_sl_common.settings.SettingsTable`): the same ranges its ``validate()``
reads, descriptions from the field docstrings.
"""
from __future__ import annotations

import dataclasses
from typing import Any, Callable

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    SetParametersResult,
)
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from tactile_sl_common.settings import SettingsTable

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


@dataclasses.dataclass
class _TableGroup:
    """The live parameters of one declared table: parameter name -> field, how to validate."""

    table: SettingsTable
    prefix: str
    fields: dict[str, str]
    current: Callable[[], Any]     # the settings object as it is now

    def validate(self, changes: dict[str, Any]) -> str | None:
        """Why the settings would be refused after ``changes`` (field -> value), or None."""
        now = self.current()
        after = dataclasses.replace(now, **{f: type(getattr(now, f))(v)
                                            for f, v in changes.items()})
        try:
            if hasattr(after, "validate"):
                after.validate()
            else:
                self.table.check(after, self.prefix)
        except ValueError as exc:
            return str(exc)
        return None


class LiveParameters:
    """Declares a node's parameters; validates live changes on set, applies them after."""

    def __init__(self, node: Any) -> None:
        self.node = node
        self._live: dict[str, tuple[Check | None, Apply]] = {}
        self._tables: list[_TableGroup] = []
        node.add_on_set_parameters_callback(self._on_set)
        node.add_post_set_parameters_callback(self._post_set)

    def declare(self, name: str, default: Any, description: str,
                value_range: tuple[float, float] | None = None, read_only: bool = False,
                apply: Apply | None = None, check: Check | None = None) -> Any:
        """Declare one parameter; ``apply`` (live) or ``read_only`` is required.

        Returns the value given at start (after rclpy's type and range checks); ``check``
        is also run on it, and a refusal there raises ValueError (one FATAL line).
        """
        if apply is None and not read_only:
            raise TypeError(f"parameter {name}: give apply= (live) or read_only=True")
        how = "" if apply is not None else " Applies at start only (read-only)."
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

    def declare_table(self, table: SettingsTable, settings: Any, prefix: str = "",
                      what: str = "", apply: Callable[[str, Any], None] | None = None,
                      current: Callable[[], Any] | None = None) -> Any:
        """Declare ``<prefix><field>`` for every row of ``table``; return ``settings``.

        ``settings`` (an instance of the table's dataclass) gives the defaults and takes the
        values given at start.  A live change is validated as the settings would be after
        it (the dataclass's ``validate()``, else the table's ranges and checks) and then
        applied: ``apply(field, value)``, by default written into ``settings``; give
        ``current`` when ``apply`` replaces the object (it returns the one in use).
        ``what`` prefixes every description.
        """
        group = _TableGroup(table, prefix, {}, current or (lambda: settings))
        for row in table:
            kind = type(row.default)
            if row.live:
                def write(value: Any, field: str = row.name, kind: type = kind) -> None:
                    if apply is not None:
                        apply(field, kind(value))
                    else:
                        setattr(settings, field, kind(value))
                extra: dict[str, Any] = {"apply": write, "check": row.check}
                group.fields[prefix + row.name] = row.name
            else:
                extra = {"read_only": True, "check": row.check}
            value = self.declare(prefix + row.name, getattr(settings, row.name),
                                 what + row.description, row.range, **extra)
            setattr(settings, row.name, kind(value))
        if group.fields:
            self._tables.append(group)
        return settings

    def _on_set(self, params: list[Any]) -> SetParametersResult:
        """Validate a request: every value, then every settings object as it would become."""
        changes = {p.name: p.value for p in params}
        for name, value in changes.items():
            if name not in self._live:
                continue          # read-only ones are refused by rclpy itself
            check, _ = self._live[name]
            reason = check(value) if check is not None else None
            if reason:
                return SetParametersResult(successful=False, reason=f"{name}: {reason}")
        for group in self._tables:
            touched = {field: changes[name] for name, field in group.fields.items()
                       if name in changes}
            reason = group.validate(touched) if touched else None
            if reason:
                return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def _post_set(self, params: list[Any]) -> None:
        """Apply what :meth:`_on_set` accepted (also called for declarations: skipped)."""
        applied = []
        for p in params:
            if p.name in self._live:
                self._live[p.name][1](p.value)
                applied.append(f"{p.name}={p.value!r}")
        if applied:
            self.node.get_logger().info(f"parameters applied: {', '.join(applied)}")


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
