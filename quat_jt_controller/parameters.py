"""
ROS parameters, one idiom for every node: declared once, validated once, applied whole.

Not part of the ROS-free core (it imports rclpy). :class:`LiveParameters` is the idiom: the
live parameters of a node are validated in the on-set callback by building the node's immutable
snapshot from the current values merged with the incoming ones (a ValueError rejects the whole
set, with its message as the reason), and the post-set callback swaps the snapshot in; the
1 kHz tick reads the snapshot, never ``get_parameter``. Structural parameters are read-only and
read once at start-up.

For the controller the snapshot is :class:`~quat_jt_controller.control_law.Gains`, validated by
``Gains.create``.

Defaults are the paper's wrist experiment (Section 5, Eqs. 43-45, orientation task Eq. 37/38):
K_p = (4.5, 20.5, 17.5) N m, K_v = (1, 1, 1) N m s/rad, Lambda = (30, 30, 30).
"""
from dataclasses import dataclass
from typing import Any, Callable, Collection, Generic, Mapping, Optional, Sequence, TypeVar

from quat_jt_controller import paper
from quat_jt_controller.control_law import gain_ceiling, Gains, MAX_LAMBDA, Potential, Task
from quat_jt_controller.joints import DEFAULT_MAX_STATE_AGE_S, DEFAULT_STATE_TIMEOUT_S
from quat_jt_controller.realtime import check_cpus, DEFAULT_PREWARM_LEAD_S
from quat_jt_controller.resources import default_urdf_xml
from quat_jt_controller.shaping import from_parameters as shaping_from_parameters
from quat_jt_controller.shaping import MAX_POSTURE_WEIGHT, Shaping
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rcl_interfaces.msg import ParameterType, SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import HistoryPolicy, QoSProfile

# Pose task (Eq. 24/32): position rows (N/m, 1/m) then the paper's orientation rows.
DEFAULT_KP_POSITION = (200.0, 200.0, 200.0)
DEFAULT_LAMBDA_POSITION = (100.0, 100.0, 100.0)

DEFAULT_JOINTS = ('joint1', 'joint2', 'joint3')
DEFAULT_BASE_LINK = 'base_link'
DEFAULT_TIP_LINK = 'tool0'
DEFAULT_PUBLISH_RATE_DIVIDER = 10

# The live parameters that make up a Gains; everything else here is read-only.
GAIN_PARAMETERS = ('potential', 'kp', 'kv', 'lambda', 'gravity_compensation')


@dataclass(frozen=True)
class StructuralConfig:
    """The read-only parameters, read once at start-up."""

    task: Task
    joints: tuple[str, ...]
    base_link: str
    tip_link: str
    robot_description: str  # the URDF in use (the bundled wrist's if none was given)
    given_robot_description: str  # the parameter as given ('' = none)
    state_timeout_s: float
    max_state_age_s: float  # 0: stamps not checked
    publish_rate_divider: int
    prewarm_lead_s: float  # 0: no throwaway tick before each state


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


def _descriptor(description: str, ptype: int, read_only: bool = False,
                float_range: Optional[tuple[float, float]] = None,
                int_range: Optional[tuple[int, int]] = None,
                constraints: str = '') -> ParameterDescriptor:
    d = ParameterDescriptor(description=description, type=ptype, read_only=read_only,
                            additional_constraints=constraints, dynamic_typing=False)
    if float_range is not None:
        d.floating_point_range = [FloatingPointRange(
            from_value=float_range[0], to_value=float_range[1], step=0.0)]
    if int_range is not None:
        d.integer_range = [IntegerRange(from_value=int_range[0], to_value=int_range[1], step=1)]
    return d


def declare_structural(node: Node) -> StructuralConfig:
    """
    Declare the read-only parameters and return their values.

    Raises ValueError naming the parameter if a value is unusable.
    """
    p = node.declare_parameter(
        'task', Task.ORIENTATION.value,
        _descriptor("What is regulated: 'orientation' (y = e, Eqs. 37/38; the paper's wrist) "
                    "or 'pose' (y = [p_d - p; e], Eqs. 24/32).",
                    ParameterType.PARAMETER_STRING, read_only=True,
                    constraints="one of 'orientation', 'pose'"))
    try:
        task = Task(p.value)
    except ValueError:
        raise ValueError(f"task must be 'orientation' or 'pose', got {p.value!r}") from None
    joints = node.declare_parameter(
        'joints', list(DEFAULT_JOINTS),
        _descriptor('Controlled joints, in the order of effort_controller/commands; '
                    'joint_states are matched by name.',
                    ParameterType.PARAMETER_STRING_ARRAY, read_only=True)).value
    base_link = node.declare_parameter(
        'base_link', DEFAULT_BASE_LINK,
        _descriptor('Frame of goals and published poses (target_pose header.frame_id).',
                    ParameterType.PARAMETER_STRING, read_only=True)).value
    tip_link = node.declare_parameter(
        'tip_link', DEFAULT_TIP_LINK,
        _descriptor('The end-effector link whose pose is regulated.',
                    ParameterType.PARAMETER_STRING, read_only=True)).value
    urdf = node.declare_parameter(
        'robot_description', '',
        _descriptor('URDF XML of the robot (kinematics, gravity, effort limits); '
                    'empty = the bundled spherical wrist.',
                    ParameterType.PARAMETER_STRING, read_only=True)).value
    timeout = node.declare_parameter(
        'state_timeout', DEFAULT_STATE_TIMEOUT_S,
        _descriptor('Seconds without a valid joint_states message after which the command is '
                    'zeroed (published once) until states return.',
                    ParameterType.PARAMETER_DOUBLE, read_only=True,
                    float_range=(0.005, 10.0))).value
    max_age = node.declare_parameter(
        'max_state_age', DEFAULT_MAX_STATE_AGE_S,
        _descriptor('A joint state stamped more than this many seconds before (or after) the '
                    "node's clock, or not stamped (zero), is rejected: no command is computed "
                    'from it, and it counts as no state for state_timeout. 0 = stamps are not '
                    'checked (e.g. a driver without time stamps).',
                    ParameterType.PARAMETER_DOUBLE, read_only=True,
                    float_range=(0.0, 60.0))).value
    divider = node.declare_parameter(
        'publish_rate_divider', DEFAULT_PUBLISH_RATE_DIVIDER,
        _descriptor('~/current_pose and the error topics are published every N-th tick '
                    '(N = 10: 100 Hz at a 1 kHz state rate).',
                    ParameterType.PARAMETER_INTEGER, read_only=True,
                    int_range=(1, 1000))).value
    prewarm = node.declare_parameter(
        'prewarm_lead', DEFAULT_PREWARM_LEAD_S,
        _descriptor('Seconds before the next joint state is due (from the measured state rate) '
                    'at which the controller runs a throwaway tick, so that the real tick finds '
                    'its code and data in the CPU caches another process evicted, and its CPU '
                    'awake; costs one wake-up per state. 0 = off. Not used on simulated time '
                    'or composed (docs/ros.md, Real-time settings).',
                    ParameterType.PARAMETER_DOUBLE, read_only=True,
                    float_range=(0.0, 0.01))).value
    if not joints or any(not j for j in joints):
        raise ValueError(f'joints must be a non-empty list of names, got {list(joints)}')
    if not base_link or not tip_link:
        raise ValueError('base_link and tip_link must not be empty')
    return StructuralConfig(task=task, joints=tuple(joints), base_link=base_link,
                            tip_link=tip_link, robot_description=urdf or default_urdf_xml(),
                            given_robot_description=urdf, state_timeout_s=float(timeout),
                            max_state_age_s=float(max_age), publish_rate_divider=int(divider),
                            prewarm_lead_s=float(prewarm))


def declare_cpu_affinity(node: Node) -> tuple[int, ...]:
    """
    Declare the read-only ``cpu_affinity`` (every node of this package has it) and return it.

    Empty (the default) leaves the process where the OS puts it. ``lifecycle.run_node`` pins
    the process once its nodes are built (``realtime.pin_process``). Raises ValueError if a CPU
    is not available to the process.
    """
    descriptor = _descriptor(
        'CPUs to pin this process to (all its threads), e.g. [1]; [] (the default) = not '
        'pinned. A 1 kHz node on a CPU of its own keeps its caches warm between ticks '
        '(docs/ros.md, Real-time settings).', ParameterType.PARAMETER_INTEGER_ARRAY,
        read_only=True)
    return check_cpus(declare_array(node, 'cpu_affinity', Parameter.Type.INTEGER_ARRAY,
                                    descriptor))


def declare_array(node: Node, name: str, ptype: Parameter.Type,
                  descriptor: ParameterDescriptor) -> list:
    """
    Declare an array parameter whose default is the empty list; return its value.

    rclpy infers a byte array from an empty default, so the parameter is declared by type. An
    unset parameter would have no value: ``ros2 param get`` says "Parameter not set" and the
    get-parameters service answers nothing for a request that names it (``ros2 param dump``
    prints ``{}``). So, unless given, it is set to ``[]``, then the descriptor (read-only or
    not) is put in place.
    """
    writable = ParameterDescriptor()
    writable.type = ptype.value
    param = node.declare_parameter(name, ptype, writable)
    if param.type_ is Parameter.Type.NOT_SET:
        node.set_parameters([Parameter(name, ptype, [])])
    node.set_descriptor(name, descriptor)
    return list(node.get_parameter(name).value)


def default_gains(task: Task, n_joints: int) -> dict[str, Any]:
    """Return the default live values: the paper's experiment for the orientation task."""
    if task is Task.ORIENTATION:
        kp, lam = paper.KP, paper.LAMBDA
    else:
        kp = DEFAULT_KP_POSITION + paper.KP
        lam = DEFAULT_LAMBDA_POSITION + paper.LAMBDA
    return {'potential': Potential.TANH.value, 'kp': list(kp), 'kv': [paper.KV[0]] * n_joints,
            'lambda': list(lam), 'gravity_compensation': True}


def declare_gains(node: Node, config: StructuralConfig, effort_limits_nm: Sequence[float],
                  on_apply: Optional[Callable[[Gains], None]] = None) -> LiveParameters[Gains]:
    """
    Declare the live gain parameters; return them as LiveParameters of a Gains.

    ``on_apply`` is called with each new Gains after a successful parameter set.

    Raises GainsError (naming the bad value) if the start-up values are invalid.
    """
    dim = config.task.dim
    n = len(config.joints)
    axes = 'x, y, z, rx, ry, rz' if dim == 6 else 'rx, ry, rz'
    defaults = default_gains(config.task, n)
    top = f'{gain_ceiling(effort_limits_nm):g}'  # the largest effort limit / SATURATING_ERROR
    descriptors = {
        'potential': _descriptor(
            "Artificial potential: 'quadratic' (Eq. 23 -> law 24/37) or 'tanh' (Eq. 31 -> law "
            '32/38). Live.', ParameterType.PARAMETER_STRING,
            constraints="one of 'quadratic', 'tanh'"),
        'kp': _descriptor(
            f'Diagonal of K_p, {dim} values ({axes}); N/m for position rows, N m for '
            f'orientation rows. Finite, > 0, <= {top}. Live.',
            ParameterType.PARAMETER_DOUBLE_ARRAY, constraints=f'{dim} values in (0, {top}]'),
        'kv': _descriptor(
            f'Diagonal of K_v (joint damping), one per joint ({n}), N m s/rad. Finite, > 0, '
            f'<= {top}. Live.', ParameterType.PARAMETER_DOUBLE_ARRAY,
            constraints=f'{n} values in (0, {top}]'),
        'lambda': _descriptor(
            f'Diagonal of Lambda in tanh(Lambda y) (Eq. 32/38), {dim} values ({axes}); used by '
            f'the tanh potential. Finite, > 0, <= {MAX_LAMBDA:g}. Live.',
            ParameterType.PARAMETER_DOUBLE_ARRAY,
            constraints=f'{dim} values in (0, {MAX_LAMBDA:g}]'),
        'gravity_compensation': _descriptor(
            'Add g(q) from the URDF model to the torque (Eq. 22). Live.',
            ParameterType.PARAMETER_BOOL),
    }
    for name in GAIN_PARAMETERS:
        node.declare_parameter(name, defaults[name], descriptors[name])
    return LiveParameters(
        node, GAIN_PARAMETERS, lambda values: build_gains(values, config, effort_limits_nm),
        on_apply)


def describe_gains(gains: Gains) -> str:
    """Describe the gains in force, as the log lines do."""
    return (f'potential {gains.potential.value}, kp {list(gains.kp)}, kv {list(gains.kv)}, '
            f'lambda {list(gains.lam)}, gravity_compensation {gains.gravity_compensation}')


def build_gains(values: Mapping[str, Any], config: StructuralConfig,
                effort_limits_nm: Optional[Sequence[float]] = None) -> Gains:
    """Gains from parameter values keyed by parameter name. Raises GainsError."""
    return Gains.create(values['potential'], values['kp'], values['kv'], values['lambda'],
                        config.task, len(config.joints), values['gravity_compensation'],
                        effort_limits_nm)


# The extensions of the regulator (shaping.Shaping), live, applied whole. Defaults
# are all off, the paper's law; config/wrist_controller.yaml and config/xarm6_controller.yaml
# turn them on with the values of quat_jt_controller.gain_design.
SHAPING_PARAMETERS = ('joint_limit_margin', 'joint_limit_gain', 'large_error_gain',
                      'friction_compensation', 'friction_velocity', 'friction_error_band',
                      'friction_position_band', 'friction_learning_limit',
                      'friction_learning_time', 'configuration_gain', 'configuration_radius',
                      'configuration_ramp', 'damping_speed', 'goal_velocity_gain',
                      'preferred_configuration', 'posture_weight')


def default_shaping(n_joints: int,
                    preferred_configuration: Optional[Sequence[float]] = None) -> dict[str, Any]:
    """
    Return the extensions' default values: all off (the paper's law).

    ``preferred_configuration`` defaults to zeros; the controller passes the middle of its
    robot's ranges (a ROS parameter needs a typed value, an empty list has none).
    """
    s = Shaping()
    return {'joint_limit_margin': 0.0, 'joint_limit_gain': [0.0] * n_joints,
            'large_error_gain': 0.0, 'friction_compensation': [0.0] * n_joints,
            'friction_velocity': s.friction_velocity_rad_s,
            'friction_error_band': s.friction_error_band,
            'friction_position_band': s.friction_position_band_m,
            'friction_learning_limit': [0.0] * n_joints,
            'friction_learning_time': s.friction_learning_time_s,
            'configuration_gain': [0.0] * n_joints,
            'configuration_radius': s.configuration_radius_rad,
            'configuration_ramp': s.configuration_ramp_rad,
            'damping_speed': [0.0] * n_joints,
            'goal_velocity_gain': 0.0,
            'preferred_configuration': [float(v) for v in (preferred_configuration
                                                           or [0.0] * n_joints)],
            'posture_weight': s.posture_weight}


def declare_shaping(node: Node, config: StructuralConfig,
                    check: Optional[Callable[[Shaping], Shaping]] = None,
                    on_apply: Optional[Callable[[Shaping], None]] = None,
                    preferred_configuration: Optional[Sequence[float]] = None
                    ) -> LiveParameters[Shaping]:
    """
    Declare the live extension parameters (docs/lyapunov.md); return them as a Shaping.

    ``check`` validates a Shaping against the robot (``Regulator.check_shaping``: the margin
    must fit inside the joint ranges) as part of the on-set validation; ``on_apply`` is called
    with each new Shaping after a successful set; ``preferred_configuration`` is that
    parameter's default (the middle of the robot's ranges). Raises ShapingError (naming the bad
    value) if the start-up values are invalid.
    """
    n = len(config.joints)
    joint_vector = ParameterType.PARAMETER_DOUBLE_ARRAY
    number = ParameterType.PARAMETER_DOUBLE
    descriptors = {
        'joint_limit_margin': _descriptor(
            'Width (rad) of the band inside each joint limit where the joint-limit potential '
            'acts (joints whose range is less than a full turn). 0 = off. Live.', number,
            float_range=(0.0, 1.0)),
        'joint_limit_gain': _descriptor(
            f'Stiffness (N m/rad) of the joint-limit potential in the band, one per joint '
            f'({n}); 0 = no limit term for that joint. Live.', joint_vector,
            constraints=f'{n} finite values >= 0'),
        'large_error_gain': _descriptor(
            'k_L (N m) of the large-error term of the orientation potential, which keeps the '
            'torque from fading towards 180 degrees. 0 = off. Live.', number,
            float_range=(0.0, 1000.0)),
        'friction_compensation': _descriptor(
            f'Coulomb friction estimates (N m), one per joint ({n}), compensated without '
            'exceeding them: by velocity while moving, in the direction of the potential '
            'torque at rest, all of it fading out near the goal. Zeros = off. Over-estimates '
            'break the stability argument away from the goal (docs/lyapunov.md). Live.',
            joint_vector,
            constraints=f'{n} finite values >= 0'),
        'friction_velocity': _descriptor(
            'v_eps (rad/s) of the velocity part, f tanh(qdot / v_eps). Live.', number,
            float_range=(1e-4, 10.0)),
        'friction_error_band': _descriptor(
            '||e|| below which the friction compensation fades out (it is off below half of '
            'it). Live.', number, float_range=(1e-5, 1.0)),
        'friction_position_band': _descriptor(
            '||p_d - p|| (m) below which the friction compensation fades out (pose task). '
            'Live.', number, float_range=(1e-6, 1.0)),
        'friction_learning_limit': _descriptor(
            f'The most (N m) the friction compensation may learn on top of the estimate, one '
            f'per joint ({n}): it grows while a joint is stuck away from the goal, stops once '
            'the joint moves, and leaks away near the goal. Zeros = off. Live.', joint_vector,
            constraints=f'{n} finite values >= 0'),
        'friction_learning_time': _descriptor(
            'Time (s) to learn friction_learning_limit while stuck; the learned part leaks '
            'with this time constant near the goal. Live.', number,
            float_range=(0.01, 1000.0)),
        'configuration_gain': _descriptor(
            f'Most torque (N m) the goal-configuration term asks of each joint ({n}); it '
            'pulls towards a goal configuration within the limits found by the goal check. '
            'Zeros = off. Live.', joint_vector, constraints=f'{n} finite values >= 0'),
        'configuration_radius': _descriptor(
            'Dead zone (rad, per joint) around the goal configuration where only the '
            "paper's term acts. Live.", number, float_range=(0.0, 3.2)),
        'configuration_ramp': _descriptor(
            'Width (rad) over which the goal-configuration torque rises to its gain. Live.',
            number, float_range=(1e-3, 3.2)),
        'damping_speed': _descriptor(
            f'v_c (rad/s) of the cubic damping term -k_v qdot (qdot / v_c)^2, one per joint '
            f'({n}); 0 = linear damping only. Live.', joint_vector,
            constraints=f'{n} finite values >= 0'),
        'goal_velocity_gain': _descriptor(
            'g_v in [0, 1]: for a stream of stamped goals on ~/target_pose, the joint damping '
            'acts on qdot - g_v qdot*_d, qdot*_d the velocity of the goal configuration (the '
            'velocity of the stream, mapped to the joints by the goal-check worker), so a moving '
            'goal is followed without the lag of the damping. A fixed goal, or a stream that '
            'stops, has qdot*_d = 0. 0 = off. Live.', number, float_range=(0.0, 1.0)),
        'preferred_configuration': _descriptor(
            f'A comfortable posture (rad), one per joint ({n}), within the limits: of the goal '
            "configurations along a redundant arm's self-motion, the goal check takes the one "
            'nearest the measured joints, then nearest this posture with posture_weight, and '
            'out of the joint-limit bands (docs/lyapunov.md, section 9). Default: the middle '
            'of the ranges. Next goal on. Live.', joint_vector,
            constraints=f'{n} finite values within the joint limits'),
        'posture_weight': _descriptor(
            'Weight of preferred_configuration against the distance to the measured joints '
            "when a redundant arm's goal configuration is chosen (0: the nearest only). No "
            'effect on an arm without self-motion. Next goal on. Live.', number,
            float_range=(0.0, MAX_POSTURE_WEIGHT)),
    }
    defaults = default_shaping(n, preferred_configuration)
    for name in SHAPING_PARAMETERS:
        node.declare_parameter(name, defaults[name], descriptors[name])

    def build(values: Mapping[str, Any]) -> Shaping:
        shaping = build_shaping(values, config)
        return shaping if check is None else check(shaping)

    return LiveParameters(node, SHAPING_PARAMETERS, build, on_apply)


def build_shaping(values: Mapping[str, Any], config: StructuralConfig) -> Shaping:
    """Shaping from parameter values keyed by parameter name. Raises ShapingError."""
    return shaping_from_parameters(dict(values), len(config.joints))
