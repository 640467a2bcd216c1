"""
The controller's ROS parameters, as one table.

One table (``STRUCTURE``, ``GAINS``, ``SHAPING``) of
:class:`~quat_jt_runtime.params.Spec` rows, in the idiom of ``quat_jt_runtime.params``.

Not part of the ROS-free core (it imports rclpy). The declarations, the descriptors and
docs/parameters.md are generated from the table. The structural rows are read once at start-up
into a :class:`StructuralConfig`; the live rows are applied whole as the immutable
:class:`~quat_jt_controller.control_law.Gains` (validated by ``Gains.create``) and
:class:`~quat_jt_controller.shaping.Shaping` (``Shaping.create``, then the robot's check).

Defaults are the paper's wrist experiment (Section 5, Eqs. 43-45, orientation task Eq. 37/38):
K_p = (4.5, 20.5, 17.5) N m, K_v = (1, 1, 1) N m s/rad, Lambda = (30, 30, 30); the extensions
are off (the paper's law).
"""
from dataclasses import dataclass
from typing import Any, Callable, Mapping, Optional, Sequence

from quat_jt_controller import paper
from quat_jt_controller.control_law import gain_ceiling, Gains, MAX_LAMBDA, Potential
from quat_jt_controller.control_law import SATURATING_ERROR, Task
from quat_jt_controller.regulator import Regulator
from quat_jt_controller.shaping import describe as describe_shaping
from quat_jt_controller.shaping import from_parameters as shaping_from_parameters
from quat_jt_controller.shaping import MAX_POSTURE_WEIGHT, Shaping
from quat_jt_runtime.description import robot_description, SOURCES
from quat_jt_runtime.errors import checked_vector
from quat_jt_runtime.joints import check_state_rate, DEFAULT_MAX_STATE_AGE_S
from quat_jt_runtime.joints import DEFAULT_STATE_RATE_HZ, DEFAULT_STATE_TIMEOUT_S
from quat_jt_runtime.joints import STATE_RATE_RANGE_HZ
from quat_jt_runtime.params import ChangeLog, declare, joint_zeros, JOINT_ZEROS_TEXT, Kind
from quat_jt_runtime.params import LiveParameters, markdown_value, names, Spec
from quat_jt_runtime.realtime import DEFAULT_PREWARM_LEAD_S
from quat_jt_runtime.urdf_source import Description
from rclpy.node import Node

# Pose task (Eq. 24/32): position rows (N/m, 1/m) then the paper's orientation rows.
DEFAULT_KP_POSITION = (200.0, 200.0, 200.0)
DEFAULT_LAMBDA_POSITION = (100.0, 100.0, 100.0)

# Declared after ``joints``, whose length is its context's ``n``.
ARMATURE = Spec(
    'armature', Kind.DOUBLE_ARRAY, joint_zeros,
    'Rotor inertia each drive adds about its joint, one per joint ({n}), kg m^2 (kg for a '
    "prismatic joint): added to the diagonal of the URDF's M(q) wherever the controller uses "
    "the inertia (Pinocchio's model.armature). A geared drive reflects its rotor times the "
    'square of the gear ratio, often more than the links; design_gains --armature takes the '
    'same values.', read_only=True, constraints='{n} finite values >= 0',
    default_text=JOINT_ZEROS_TEXT)
STRUCTURE = (
    Spec('task', Kind.STRING, Task.ORIENTATION.value,
         "What is regulated: 'orientation' (y = e, Eqs. 37/38; the paper's wrist) or 'pose' "
         '(y = [p_d - p; e], Eqs. 24/32).', read_only=True,
         constraints="one of 'orientation', 'pose'"),
    Spec('joints', Kind.STRING_ARRAY, ['joint1', 'joint2', 'joint3'],
         'Controlled joints, in the order of effort_controller/commands; joint_states are '
         'matched by name.', read_only=True, constraints='non-empty names'),
    Spec('base_link', Kind.STRING, 'base_link',
         'Frame of goals and published poses (target_pose header.frame_id).', read_only=True),
    Spec('tip_link', Kind.STRING, 'tool0', 'The end-effector link whose pose is regulated.',
         read_only=True),
    Spec('robot_description', Kind.STRING, '',
         'URDF XML of the robot (kinematics, gravity, effort limits), e.g. from a launch or '
         'params file; or robot_description_file, or robot_description_topic; none of them = '
         'the bundled spherical wrist.', read_only=True),
    *SOURCES,
    ARMATURE,
    Spec('state_timeout', Kind.DOUBLE, DEFAULT_STATE_TIMEOUT_S,
         'Seconds without a valid joint_states message after which the command is zeroed '
         '(published once) until states return.', read_only=True, bounds=(0.005, 10.0)),
    Spec('max_state_age', Kind.DOUBLE, DEFAULT_MAX_STATE_AGE_S,
         'A joint state stamped more than this many seconds before (or after) the '
         "node's clock, or not stamped (zero), is rejected: no command is computed from it, "
         'and it counts as no state for state_timeout. 0 = stamps are not checked (e.g. a '
         'driver without time stamps).', read_only=True, bounds=(0.0, 60.0)),
    Spec('state_rate', Kind.DOUBLE, DEFAULT_STATE_RATE_HZ,
         "Hz, the rate of joint_states (the plant's control rate), as design_gains --rate was "
         'given: the time constant of the velocity estimate for states without velocities is '
         'one period of it.', read_only=True, bounds=STATE_RATE_RANGE_HZ),
    Spec('publish_rate_divider', Kind.INT, 10,
         '~/current_pose and the error topics are published every N-th tick (N = 10: 100 Hz '
         'at a 1 kHz state rate).', read_only=True, bounds=(1, 1000)),
    Spec('prewarm_lead', Kind.DOUBLE, DEFAULT_PREWARM_LEAD_S,
         'Seconds before the next joint state is due (from the measured state rate) at which '
         'the controller runs a throwaway tick, so that the real tick finds its code and data '
         'in the CPU caches another process evicted, and its CPU awake; costs one wake-up per '
         'state. 0 = off. Not used on simulated time or composed (docs/ros.md, Real-time '
         'settings).', read_only=True, bounds=(0.0, 0.01)),
)


def _per_task(position: Sequence[float], orientation: Sequence[float]) -> Callable:
    return lambda context: list(
        orientation if context['task'] is Task.ORIENTATION else tuple(position) + orientation)


# The live parameters that make up a Gains. Context: task, dim, axes, n, top (gain_ceiling).
GAINS = (
    Spec('potential', Kind.STRING, Potential.TANH.value,
         "Artificial potential: 'quadratic' (Eq. 23 -> law 24/37) or 'tanh' (Eq. 31 -> law "
         '32/38). Live.', constraints="one of 'quadratic', 'tanh'"),
    Spec('kp', Kind.DOUBLE_ARRAY, _per_task(DEFAULT_KP_POSITION, paper.KP),
         'Diagonal of K_p, {dim} values ({axes}); N/m for position rows, N m for orientation '
         'rows. Finite, > 0, <= {top}. Live.', constraints='{dim} values in (0, {top}]',
         default_text=f'{markdown_value(paper.KP)} (pose: {markdown_value(DEFAULT_KP_POSITION)} '
                      'first)'),
    Spec('kv', Kind.DOUBLE_ARRAY, lambda context: [paper.KV[0]] * context['n'],
         'Diagonal of K_v (joint damping), one per joint ({n}), N m s/rad. Finite, > 0, '
         '<= {top}. Live.', constraints='{n} values in (0, {top}]',
         default_text=f'`{paper.KV[0]:g}` per joint'),
    Spec('lambda', Kind.DOUBLE_ARRAY, _per_task(DEFAULT_LAMBDA_POSITION, paper.LAMBDA),
         'Diagonal of Lambda in tanh(Lambda y) (Eq. 32/38), {dim} values ({axes}); used by the '
         f'tanh potential. Finite, > 0, <= {MAX_LAMBDA:g}. Live.',
         constraints=f'{{dim}} values in (0, {MAX_LAMBDA:g}]',
         default_text=f'{markdown_value(paper.LAMBDA)} (pose: '
                      f'{markdown_value(DEFAULT_LAMBDA_POSITION)} first)'),
    Spec('gravity_compensation', Kind.BOOL, True,
         'Add g(q) from the URDF model to the torque (Eq. 22). Live.'),
)
GAIN_PARAMETERS = names(GAINS)

_DEFAULT_SHAPING = Shaping()


# The extensions of the regulator (shaping.Shaping), live, applied whole. Defaults are all
# off, the paper's law; the robots' configs turn them on with the values of
# quat_jt_controller.gain_design. Context: n, preferred_configuration.
SHAPING = (
    Spec('joint_limit_margin', Kind.DOUBLE, 0.0,
         'Width (rad) of the band inside each joint limit where the joint-limit potential acts '
         '(joints whose range is less than a full turn). 0 = off. Live.', bounds=(0.0, 1.0)),
    Spec('joint_limit_gain', Kind.DOUBLE_ARRAY, joint_zeros,
         'Stiffness (N m/rad) of the joint-limit potential in the band, one per joint ({n}); '
         '0 = no limit term for that joint. Live.', constraints='{n} finite values >= 0',
         default_text=JOINT_ZEROS_TEXT),
    Spec('large_error_gain', Kind.DOUBLE, 0.0,
         'k_L (N m) of the large-error term of the orientation potential, which keeps the '
         'torque from fading towards 180 degrees. 0 = off. Live.', bounds=(0.0, 1000.0)),
    Spec('friction_compensation', Kind.DOUBLE_ARRAY, joint_zeros,
         'Coulomb friction estimates (N m), one per joint ({n}), compensated without exceeding '
         'them: by velocity while moving, in the direction of the potential torque at rest, '
         'all of it fading out near the goal. Zeros = off. Over-estimates break the stability '
         'argument away from the goal (docs/lyapunov.md). Live.',
         constraints='{n} finite values >= 0', default_text=JOINT_ZEROS_TEXT),
    Spec('friction_velocity', Kind.DOUBLE, _DEFAULT_SHAPING.friction_velocity_rad_s,
         'v_eps (rad/s) of the velocity part, f tanh(qdot / v_eps). Live.',
         bounds=(1e-4, 10.0)),
    Spec('friction_error_band', Kind.DOUBLE, _DEFAULT_SHAPING.friction_error_band,
         '||e|| below which the friction compensation fades out (it is off below half of '
         'it). Live.', bounds=(1e-5, 1.0)),
    Spec('friction_position_band', Kind.DOUBLE, _DEFAULT_SHAPING.friction_position_band_m,
         '||p_d - p|| (m) below which the friction compensation fades out (pose task). Live.',
         bounds=(1e-6, 1.0)),
    Spec('friction_learning_limit', Kind.DOUBLE_ARRAY, joint_zeros,
         'The most (N m) the friction compensation may learn on top of the estimate, one per '
         'joint ({n}): it grows while a joint stays stuck away from the goal with the push not '
         'taken by its damping, stops once the joint moves, holds while a friction takes the '
         'push, and leaks away where the damping takes it and near the goal. Zeros = off. '
         'Live.',
         constraints='{n} finite values >= 0', default_text=JOINT_ZEROS_TEXT),
    Spec('friction_learning_time', Kind.DOUBLE, _DEFAULT_SHAPING.friction_learning_time_s,
         'Time (s) to learn friction_learning_limit while stuck; the learned part leaks with '
         'this time constant near the goal, and 5x faster where the damping takes the push. '
         'Live.', bounds=(0.01, 1000.0)),
    Spec('configuration_gain', Kind.DOUBLE_ARRAY, joint_zeros,
         'Most torque (N m) the goal-configuration term asks of each joint ({n}); it pulls '
         'towards a goal configuration within the limits found by the goal check. Zeros = '
         'off. Live.', constraints='{n} finite values >= 0', default_text=JOINT_ZEROS_TEXT),
    Spec('configuration_radius', Kind.DOUBLE, _DEFAULT_SHAPING.configuration_radius_rad,
         'Dead zone (rad, per joint) around the goal configuration where only the '
         "paper's term acts. Live.", bounds=(0.0, 3.2)),
    Spec('configuration_ramp', Kind.DOUBLE, _DEFAULT_SHAPING.configuration_ramp_rad,
         'Width (rad) over which the goal-configuration torque rises to its gain. Live.',
         bounds=(1e-3, 3.2)),
    Spec('damping_speed', Kind.DOUBLE_ARRAY, joint_zeros,
         'v_c (rad/s) of the cubic damping term -k_v qdot (qdot / v_c)^2, one per joint ({n}); '
         '0 = linear damping only. Live.', constraints='{n} finite values >= 0',
         default_text=JOINT_ZEROS_TEXT),
    Spec('goal_velocity_gain', Kind.DOUBLE, 0.0,
         'g_v in [0, 1]: for a stream of stamped goals on ~/target_pose, the joint damping '
         'acts on qdot - g_v qdot*_d, qdot*_d the velocity of the goal configuration (the '
         'velocity of the stream, mapped to the joints by the goal-check worker), so a moving '
         'goal is followed without the lag of the damping. A fixed goal, or a stream that '
         'stops, has qdot*_d = 0. 0 = off. Live.', bounds=(0.0, 1.0)),
    Spec('preferred_configuration', Kind.DOUBLE_ARRAY,
         lambda context: [float(v) for v in context['preferred_configuration']],
         'A comfortable posture (rad), one per joint ({n}), within the limits: of the goal '
         "configurations along a redundant arm's self-motion, the goal check takes the one "
         'nearest the measured joints, then nearest this posture with posture_weight, and out '
         'of the joint-limit bands (docs/lyapunov.md, section 9). Default: the middle of the '
         'ranges. Next goal on. Live.', constraints='{n} finite values within the joint limits',
         default_text='the middle of the ranges'),
    Spec('posture_weight', Kind.DOUBLE, _DEFAULT_SHAPING.posture_weight,
         'Weight of preferred_configuration against the distance to the measured joints when '
         "a redundant arm's goal configuration is chosen (0: the nearest only). No effect on "
         'an arm without self-motion. Next goal on. Live.', bounds=(0.0, MAX_POSTURE_WEIGHT)),
)
SHAPING_PARAMETERS = names(SHAPING)

# The context the docs' table is written with (docs/parameters.md): symbols, not one robot.
DOCS_CONTEXT = {'task': Task.ORIENTATION, 'n': 'n', 'dim': '3 (orientation) or 6 (pose)',
                'axes': 'rx, ry, rz; the pose task has x, y, z first',
                'top': f'max(effort limit) / {SATURATING_ERROR:g}',
                'preferred_configuration': ()}


@dataclass(frozen=True)
class StructuralConfig:
    """The read-only parameters, read once at start-up."""

    task: Task
    joints: tuple[str, ...]
    base_link: str
    tip_link: str
    description: Description  # the URDF in use and where it came from
    armature: tuple[float, ...]  # kg m^2 per joint, finite and >= 0
    state_timeout_s: float
    max_state_age_s: float  # 0: stamps not checked
    state_rate_hz: float
    publish_rate_divider: int
    prewarm_lead_s: float  # 0: no throwaway tick before each state

    @property
    def robot_description(self) -> str:
        """Return the URDF in use (the bundled wrist's if none was given)."""
        return self.description.xml

    @property
    def given_robot_description(self) -> str:
        """Return the URDF as given to the node ('' = none: the bundled wrist)."""
        return self.description.given

    @classmethod
    def create(cls, values: Mapping[str, Any],
               description: Callable[[], Description]) -> 'StructuralConfig':
        """
        Build from the structural parameters; raise ValueError naming a bad value.

        ``description`` returns the URDF; it is called once the other values are checked (it
        may wait for a topic).
        """
        try:
            task = Task(values['task'])
        except ValueError:
            raise ValueError(f"task must be 'orientation' or 'pose', got {values['task']!r}"
                             ) from None
        joints = tuple(values['joints'])
        if not joints or any(not j for j in joints):
            raise ValueError(f'joints must be a non-empty list of names, got {list(joints)}')
        if not values['base_link'] or not values['tip_link']:
            raise ValueError('base_link and tip_link must not be empty')
        armature = checked_vector('armature', values['armature'], len(joints), ValueError,
                                  lower=0.0, per_joint=True)
        state_rate_hz = check_state_rate(values['state_rate'])
        return cls(task=task, joints=joints, base_link=values['base_link'],
                   tip_link=values['tip_link'], armature=armature,
                   description=description(),
                   state_timeout_s=float(values['state_timeout']),
                   max_state_age_s=float(values['max_state_age']),
                   state_rate_hz=state_rate_hz,
                   publish_rate_divider=int(values['publish_rate_divider']),
                   prewarm_lead_s=float(values['prewarm_lead']))


def declare_structural(node: Node) -> StructuralConfig:
    """
    Declare the read-only parameters and return their values, the URDF from its source.

    A ``robot_description_topic`` is waited for here, before the model is built. Raises
    ValueError naming the parameter if a value is unusable (DescriptionError for the URDF).
    """
    values = declare(node, tuple(s for s in STRUCTURE if s is not ARMATURE))
    values.update(declare(node, (ARMATURE,), {'n': len(values['joints'])}))
    return StructuralConfig.create(values, lambda: robot_description(node, values))


def gains_context(config: StructuralConfig, effort_limits_nm: Sequence[float]) -> dict:
    """Return the context of the GAINS rows for this robot (sizes, axes, the ceiling)."""
    return {'task': config.task, 'dim': config.task.dim, 'n': len(config.joints),
            'axes': 'x, y, z, rx, ry, rz' if config.task.dim == 6 else 'rx, ry, rz',
            'top': f'{gain_ceiling(effort_limits_nm):g}'}


def declare_gains(node: Node, config: StructuralConfig, effort_limits_nm: Sequence[float],
                  on_apply: Optional[Callable[[Gains], None]] = None) -> LiveParameters[Gains]:
    """
    Declare the live gain parameters; return them as LiveParameters of a Gains.

    ``on_apply`` is called with each new Gains after a successful parameter set.

    Raises GainsError (naming the bad value) if the start-up values are invalid.
    """
    declare(node, GAINS, gains_context(config, effort_limits_nm))
    return LiveParameters(
        node, GAIN_PARAMETERS, lambda values: build_gains(values, config, effort_limits_nm),
        on_apply)


def describe_start(config: StructuralConfig, regulator: Regulator,
                   state_topic: str = 'joint_states') -> list[str]:
    """Describe the controller at start-up: its extensions, then its task, robot and gains."""
    gains = regulator.gains
    return [f'extensions: {describe_shaping(regulator.shaping)}',
            f'{config.task.value} task, joints {list(config.joints)}, {config.base_link} -> '
            f'{config.tip_link}, potential {gains.potential.value}, kp {list(gains.kp)}, kv '
            f'{list(gains.kv)}, lambda {list(gains.lam)}, effort limits '
            f'{list(regulator.effort_limits_nm)} N m; waiting for joint states on {state_topic}, '
            'then holding the first pose measured until a goal arrives on ~/target_pose']


def change_log(node: Node, regulator: Regulator) -> ChangeLog:
    """Log each parameter request once, with the gains and the extensions then in force."""
    return ChangeLog(node, (
        (GAIN_PARAMETERS, lambda: describe_gains(regulator.gains)),
        (SHAPING_PARAMETERS, lambda: f'extensions: {describe_shaping(regulator.shaping)}')))


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
    declare(node, SHAPING, {'n': n, 'preferred_configuration':
                            preferred_configuration or [0.0] * n})

    def build(values: Mapping[str, Any]) -> Shaping:
        shaping = build_shaping(values, config)
        return shaping if check is None else check(shaping)

    return LiveParameters(node, SHAPING_PARAMETERS, build, on_apply)


def build_shaping(values: Mapping[str, Any], config: StructuralConfig) -> Shaping:
    """Shaping from parameter values keyed by parameter name. Raises ShapingError."""
    return shaping_from_parameters(dict(values), len(config.joints))
