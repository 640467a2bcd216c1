"""
The parameter machinery of every node: declared once, validated once, applied whole.

:class:`LiveParameters` is the idiom: the live parameters of a node are validated in the on-set
callback by building the node's immutable snapshot from the current values merged with the
incoming ones (a ValueError rejects the whole set, with its message as the reason), and the
post-set callback swaps the snapshot in; the 1 kHz tick reads the snapshot, never
``get_parameter``. Structural parameters are read-only and read once at start-up.
:class:`ChangeLog` logs one line per parameter request. The rows of the tables
(``param_table.Spec``) are ROS-free; :func:`declare` declares them with their descriptors.
"""
from typing import (Any, Callable, Collection, Generic, Mapping, NamedTuple, Optional,
                    Sequence, TypeVar)

from quat_jt_runtime.param_table import Kind, Spec
from quat_jt_runtime.realtime import check_cpus, DEFAULT_THREAD_PRIORITY
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import HistoryPolicy, QoSProfile


def history_qos(simulated_time: bool) -> QoSProfile:
    """
    Return the QoS of the 1 kHz topics (joint_states, effort commands): reliable, a history.

    On simulated time (lockstep), every subscriber gets every message: KEEP_ALL, so a slow
    recorder slows simulated time down instead of losing messages. In real time a late
    subscriber must never stall the loop: KEEP_LAST 1000, which never blocks and lets a
    subscriber that lags for a moment catch up.
    """
    if simulated_time:
        return QoSProfile(history=HistoryPolicy.KEEP_ALL, depth=1000)
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000)


Snapshot = TypeVar('Snapshot')


class LiveParameters(Generic[Snapshot]):
    """
    Live parameters of ``node`` named ``names`` (already declared), as one immutable snapshot.

    ``build`` turns a complete ``{name: value}`` mapping into the snapshot or raises ValueError
    naming the bad value. ``current`` is the snapshot in force; ``on_apply`` is called with
    each new one after a successful set (to push it to a model; :class:`ChangeLog` logs it).
    """

    def __init__(self, node: Node, names: Sequence[str],
                 build: Callable[[Mapping[str, Any]], Snapshot],
                 on_apply: Optional[Callable[[Snapshot], None]] = None) -> None:
        self._node = node
        self._names = frozenset(names)
        self._build = build
        self._on_apply = on_apply
        self.values = {name: node.get_parameter(name).value for name in names}
        self.current: Snapshot = build(self.values)  # a bad start-up value raises here
        self._pending: Optional[tuple[dict, Snapshot]] = None
        node.add_on_set_parameters_callback(self._validate)
        node.add_post_set_parameters_callback(self._apply)

    def _validate(self, params) -> SetParametersResult:
        merged = dict(self.values)
        touched = [p.name for p in params if p.name in self._names]
        if not touched:
            return SetParametersResult(successful=True)
        merged.update({p.name: p.value for p in params if p.name in self._names})
        try:
            self._pending = (merged, self._build(merged))
        except ValueError as exc:
            self._pending = None
            reason = f'rejected, nothing changed: {exc}'
            self._node.get_logger().warn(f'parameter set {touched} {reason}')
            return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def _apply(self, params) -> None:
        if self._pending is None or not any(p.name in self._names for p in params):
            return
        self.values, self.current = self._pending
        self._pending = None
        if self._on_apply is not None:
            self._on_apply(self.current)


class ChangeLog:
    """
    One INFO line per parameter request, however many parameters it sets.

    ``ros2 param load`` sends a whole file in one set-parameters request, which rclpy applies
    one parameter at a time: each is validated and its snapshot applied whole, all within the
    one service callback, so no tick runs in between. Each post-set callback here only notes the
    names and (re)arms a one-shot steady-clock timer, which fires after the request's callback
    and logs the new values of every group touched, once. (The EventsExecutor takes no guard
    conditions.) ``groups`` pairs parameter names with a function that describes their snapshot
    in force.
    """

    def __init__(self, node: Node,
                 groups: Sequence[tuple[Collection[str], Callable[[], str]]]) -> None:
        self._node = node
        self._groups = groups
        self._names: list[str] = []
        self._timer = node.create_timer(1e-3, self._flush, autostart=False,
                                        clock=Clock(clock_type=ClockType.STEADY_TIME))
        node.add_post_set_parameters_callback(self._note)

    def _note(self, params) -> None:
        self._names += [p.name for p in params if p.name not in self._names]
        self._timer.reset()

    def _flush(self) -> None:
        self._timer.cancel()
        if not self._names:
            return
        names, self._names = self._names, []
        parts = [describe() for group, describe in self._groups
                 if any(name in group for name in names)]
        self._node.get_logger().info(
            f'parameters updated ({", ".join(names)})' + (': ' + '; '.join(parts) if parts
                                                          else ''))


def descriptor(spec: Spec, context: Mapping[str, Any]) -> ParameterDescriptor:
    """Return the ``ParameterDescriptor`` of a row (``ros2 param describe``) for this node."""
    d = ParameterDescriptor(
        description=spec.description.format(**context), type=spec.kind.descriptor_type,
        read_only=spec.read_only,
        additional_constraints=(spec.rule_text(context) if spec.kind.is_array
                                else spec.constraints.format(**context)),
        dynamic_typing=False)
    if spec.bounds is not None and spec.kind is Kind.DOUBLE:
        d.floating_point_range = [FloatingPointRange(
            from_value=float(spec.bounds[0]), to_value=float(spec.bounds[1]), step=0.0)]
    elif spec.bounds is not None and spec.kind is Kind.INT:
        d.integer_range = [IntegerRange(
            from_value=int(spec.bounds[0]), to_value=int(spec.bounds[1]), step=1)]
    return d


def rclpy_type(kind: Kind) -> Parameter.Type:
    """Return rclpy's type of a parameter of ``kind``."""
    return Parameter.Type(kind.descriptor_type)


def declare(node: Node, specs: Sequence[Spec],
            context: Optional[Mapping[str, Any]] = None) -> dict[str, Any]:
    """
    Declare every parameter of ``specs`` on ``node``; return ``{name: value}``.

    An array whose default is empty is declared by type, then set to ``[]`` unless given: rclpy
    infers a byte array from an empty default, and an unset parameter has no value (``ros2
    param get`` says "Parameter not set", and ``ros2 param dump`` prints ``{}`` for a node
    that has one). The descriptor (read-only or not) is put in place after.
    """
    context = context or {}
    values = {}
    for spec in specs:
        default = spec.default_value(context)
        described = descriptor(spec, context)
        if isinstance(default, (list, tuple)) and not default:
            ptype = rclpy_type(spec.kind)
            param = node.declare_parameter(
                spec.name, ptype, ParameterDescriptor(type=spec.kind.descriptor_type))
            if param.type_ is Parameter.Type.NOT_SET:
                node.set_parameters([Parameter(spec.name, ptype, [])])
            node.set_descriptor(spec.name, described)
            values[spec.name] = list(node.get_parameter(spec.name).value)
        else:
            values[spec.name] = node.declare_parameter(spec.name, default, described).value
    return values


CPU_AFFINITY = Spec(
    'cpu_affinity', Kind.INT_ARRAY, [],
    'CPUs to pin this process to (all its threads), e.g. [1]; [] (the default) = not pinned. '
    'A 1 kHz node on a CPU of its own keeps its caches warm between ticks (docs/ros.md, '
    'Real-time settings).', read_only=True, constraints='CPUs this process may run on')
THREAD_PRIORITY = Spec(
    'thread_priority', Kind.INT, DEFAULT_THREAD_PRIORITY,
    'SCHED_FIFO priority of every thread of this process (1-99) while it runs in real time; '
    '0 = normal scheduling. Ordinary processes then do not preempt the loop (docs/ros.md, '
    'Real-time settings). Needs CAP_SYS_NICE or an rtprio limit: if refused, a warning and normal '
    'scheduling. Not applied on simulated time (lockstep) or with the PyBullet window.',
    read_only=True, bounds=(0, 99))
REALTIME = (CPU_AFFINITY, THREAD_PRIORITY)  # every node of this package has these rows


class Realtime(NamedTuple):
    """A node's real-time settings (read-only), applied by ``lifecycle.run_node``."""

    cpus: tuple[int, ...]  # empty: not pinned
    thread_priority: int  # 0: normal scheduling
    off_reason: str = ''  # why this node's mode needs normal scheduling ('' if it does not)


def realtime_from(values: Mapping[str, Any], off_reason: str = '') -> Realtime:
    """Return the Realtime of declared ``values``; raise ValueError for an unavailable CPU."""
    return Realtime(check_cpus(values['cpu_affinity']), int(values['thread_priority']),
                    off_reason)


def declare_realtime(node: Node, off_reason: str = '') -> Realtime:
    """
    Declare the read-only ``cpu_affinity`` and ``thread_priority``; return them.

    ``off_reason`` says why the node's mode needs normal scheduling (simulated time, say).
    ``lifecycle.run_node`` applies them once the process's nodes are built
    (``realtime.pin_process``, ``realtime.set_thread_priority``). Raises ValueError if a CPU is
    not available to the process.
    """
    return realtime_from(declare(node, REALTIME), off_reason)
