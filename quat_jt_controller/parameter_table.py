"""
The controller's parameters, as one table, ROS-free.

The table (``STRUCTURE``, ``GAINS``, ``SHAPING``, rows of
:class:`~quat_jt_runtime.param_table.Spec`) is the only source of each parameter's type,
default, range, size rule and description. From it come the node's declarations and descriptors
(``parameters.py``), the validation of the :class:`~quat_jt_controller.shaping.Shaping` snapshot
by the node and by ``controller_from_config`` alike (``Shaping.create`` checks every row), the
snapshot's defaults, docs/parameters.md (``make docs``) and the parameter files ``gain_output``
writes. Read the groups through this module at the time of use (``parameter_table.SHAPING``),
so that a row added here is seen everywhere.

Defaults are the paper's wrist experiment (Section 5, Eqs. 43-45, orientation task Eq. 37/38):
K_p = (4.5, 20.5, 17.5) N m, K_v = (1, 1, 1) N m s/rad, Lambda = (30, 30, 30); the extensions
are off (the paper's law).
"""
from math import inf
from typing import Any, Callable, Sequence

from quat_jt_controller import paper
from quat_jt_controller.control_law import MAX_LAMBDA, Potential, SATURATING_ERROR, Task
from quat_jt_runtime.joints import DEFAULT_MAX_STATE_AGE_S, DEFAULT_STATE_RATE_HZ
from quat_jt_runtime.joints import DEFAULT_STATE_TIMEOUT_S, STATE_RATE_RANGE_HZ
from quat_jt_runtime.param_table import joint_zeros, JOINT_ZEROS_TEXT, Kind, markdown_value
from quat_jt_runtime.param_table import row, Spec
from quat_jt_runtime.payload import PAYLOAD_MASS_MAX_KG
from quat_jt_runtime.realtime import DEFAULT_PREWARM_LEAD_S
from quat_jt_runtime.urdf_source import SOURCES

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
    'same values.', read_only=True, size='n', bounds=(0.0, inf),
    default_text=JOINT_ZEROS_TEXT)
# Declared after ``joints``, as ARMATURE.
POSITION_RESOLUTION = Spec(
    'position_resolution', Kind.DOUBLE_ARRAY, joint_zeros,
    "One count of each joint's position as joint_states report it ({n} values), rad (m for "
    'a prismatic joint), e.g. 2 pi / 2^17 for a 17-bit encoder on the joint; 0 = exact. Read '
    'only where the states carry no velocities: any count > 0 estimates them on the longest '
    'window the counts allow, and 0 while a joint stays within one count of its last 16 '
    'states (the one-period low-pass used for exact positions moves by 0.63 count per period '
    'at each step of a count, and the damping shakes the torque with it; docs/ros.md, "On a '
    'real robot").', read_only=True,
    size='n', bounds=(0.0, inf), default_text=JOINT_ZEROS_TEXT)
PER_JOINT_STRUCTURE = (ARMATURE, POSITION_RESOLUTION)
# Live, applied whole as one Payload (quat_jt_runtime.payload) to the model's tip body
PAYLOAD = (
    Spec('payload_mass', Kind.DOUBLE, 0.0,
         'Mass the tip link carries that the URDF does not list (a tool, a grasped part), kg: '
         'a point mass at payload_com, in g(q) and M(q) wherever the controller uses them, '
         'from the next tick. Without it gravity compensation leaves its weight to the '
         'potential, and the tip settles where the stiffness holds it, short of the goal; the '
         'friction learning takes up a light one (docs/reach.md, "An untold payload"). Set it '
         'when a part is grasped or let go; design_gains --payload-mass takes the tool the arm '
         'always carries. Live.', bounds=(0.0, PAYLOAD_MASS_MAX_KG)),
    Spec('payload_com', Kind.DOUBLE_ARRAY, [0.0, 0.0, 0.0],
         "Where payload_mass is, x y z in m in tip_link's frame (design_gains --payload-com). "
         'Live.', constraints='3 finite values'),
)
STRUCTURE = (
    Spec('task', Kind.STRING, Task.ORIENTATION.value,
         "What is regulated: 'orientation' (y = e, Eqs. 37/38; the paper's wrist), 'pose' "
         "(y = [p_d - p; e], Eqs. 24/32) or 'position' (y = p_d - p, the position rows of "
         "Eqs. 24/32: any reachable point, e.g. on an arm of 4 or 5 joints; a goal's "
         'orientation is not read, so any quaternion, all zeros too, is accepted).',
         read_only=True, choices=tuple(t.value for t in Task)),
    Spec('joints', Kind.STRING_ARRAY, ['joint1', 'joint2', 'joint3'],
         'Controlled joints, in the order of effort_controller/commands; joint_states are '
         'matched by name.', read_only=True, constraints='non-empty names'),
    ARMATURE,
    POSITION_RESOLUTION,
    Spec('base_link', Kind.STRING, 'base_link',
         'Frame of goals and published poses (target_pose header.frame_id).', read_only=True),
    Spec('tip_link', Kind.STRING, 'tool0', 'The end-effector link whose pose is regulated.',
         read_only=True),
    Spec('robot_description', Kind.STRING, '',
         'URDF XML of the robot (kinematics, gravity, effort limits), e.g. from a launch or '
         'params file; or robot_description_file, or robot_description_topic; none of them = '
         'the bundled spherical wrist.', read_only=True),
    *SOURCES,
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
    Spec('design_options', Kind.STRING_ARRAY, [],
         'The design_gains options the file was designed with that no other parameter holds '
         '(--effort-limits, --delays, --friction-learning, --friction-effort-share, '
         '--cruise-fraction, --approach-time), as design_gains takes them, one word an entry '
         '(e.g. --delays, 1, 2); empty = its defaults. design_gains writes them; a design again '
         'for the rotor inertia found from the motion (gain_redesign) reads them.', read_only=True,
         empty_ok=True, constraints='design_gains options'),
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
        (tuple(position) if context['task'].has_position else ())
        + (tuple(orientation) if context['task'].has_orientation else ()))


# The live parameters that make up a Gains (checked by Gains.create). Context: task, dim, axes,
# n, top (the gain ceiling, as text), ceiling and lambda_ceiling (the bounds: numbers, or the
# docs' text).
CEILING_WHY = (f'its term alone would ask for more than the largest effort limit '
               f'({{effort_max}} N m) at an error of {SATURATING_ERROR:g} (rad, m or rad/s): the '
               'joints would only saturate')
GAINS = (
    Spec('potential', Kind.STRING, Potential.TANH.value,
         "Artificial potential: 'quadratic' (Eq. 23 -> law 24/37) or 'tanh' (Eq. 31 -> law "
         '32/38). Live.', choices=tuple(p.value for p in Potential)),
    Spec('kp', Kind.DOUBLE_ARRAY, _per_task(DEFAULT_KP_POSITION, paper.KP),
         'Diagonal of K_p, {dim} values ({axes}); N/m for position rows, N m for orientation '
         'rows. Finite, > 0, <= {top}. Live.', size='dim', bounds=(0.0, 'ceiling'), strict=True,
         why=CEILING_WHY,
         default_text=f'{markdown_value(paper.KP)} (pose: {markdown_value(DEFAULT_KP_POSITION)} '
                      'first; position: those alone)'),
    Spec('kv', Kind.DOUBLE_ARRAY, lambda context: [paper.KV[0]] * context['n'],
         'Diagonal of K_v (joint damping), one per joint ({n}), N m s/rad. Finite, > 0, '
         '<= {top}. Live.', size='n', bounds=(0.0, 'ceiling'), strict=True, why=CEILING_WHY,
         default_text=f'`{paper.KV[0]:g}` per joint'),
    Spec('lambda', Kind.DOUBLE_ARRAY, _per_task(DEFAULT_LAMBDA_POSITION, paper.LAMBDA),
         'Diagonal of Lambda in tanh(Lambda y) (Eq. 32/38), {dim} values ({axes}); used by the '
         f'tanh potential. Finite, > 0, <= {MAX_LAMBDA:g}. Live.', size='dim',
         bounds=(0.0, 'lambda_ceiling'), strict=True,
         why='tanh(lambda y) would switch like sign(y) within sensor noise (chatter)',
         default_text=f'{markdown_value(paper.LAMBDA)} (pose: '
                      f'{markdown_value(DEFAULT_LAMBDA_POSITION)} first; position: those '
                      'alone)'),
    Spec('gravity_compensation', Kind.BOOL, True,
         'Add g(q) from the URDF model to the torque (Eq. 22). Live.'),
)

# beta of the inertial damping at 1 kHz with 1 and 2 ticks of delay (3 checked): what
# gain_design.inertial_damping_rate gives there (a test checks it)
DEFAULT_INERTIAL_DAMPING_RATE = 222.5
MAX_SETTLING_RATE = 40.0  # 1/s, alpha of the settling damping; design_gains' grid tops at 20
MAX_POSTURE_WEIGHT = 100.0  # of the preferred posture against the distance to the arm
PER_JOINT = {'size': 'n', 'bounds': (0.0, inf)}  # one finite value >= 0 per joint

# The extensions of the regulator (shaping.Shaping: ``field`` names its attribute), live,
# applied whole. Defaults are all off, the paper's law; the robots' configs turn them on with
# the values of quat_jt_controller.gain_design. Context: n, preferred_configuration.
SHAPING = (
    Spec('joint_limit_margin', Kind.DOUBLE, 0.0,
         'Width (rad) of the band inside each joint limit where the joint-limit potential acts '
         '(joints whose range is less than a full turn). 0 = off. Live.', bounds=(0.0, 1.0),
         field='joint_limit_margin_rad'),
    Spec('joint_limit_gain', Kind.DOUBLE_ARRAY, joint_zeros,
         'Stiffness (N m/rad) of the joint-limit potential in the band, one per joint ({n}); '
         '0 = no limit term for that joint. Live.', default_text=JOINT_ZEROS_TEXT, **PER_JOINT),
    Spec('large_error_gain', Kind.DOUBLE, 0.0,
         'k_L (N m) of the large-error term of the orientation potential, which keeps the '
         'torque from fading towards 180 degrees. 0 = off. Live.', bounds=(0.0, 1000.0)),
    Spec('friction_compensation', Kind.DOUBLE_ARRAY, joint_zeros,
         'Coulomb friction estimates (N m), one per joint ({n}), compensated without exceeding '
         'them: by velocity while moving, in the direction of the potential torque at rest, '
         'all of it fading out near the goal. Zeros = off. Over-estimates break the stability '
         'argument away from the goal (docs/lyapunov.md). Live.',
         default_text=JOINT_ZEROS_TEXT, field='friction_compensation_nm', **PER_JOINT),
    Spec('friction_learning_limit', Kind.DOUBLE_ARRAY, joint_zeros,
         'The most (N m) the friction compensation may learn on top of the estimate, one per '
         'joint ({n}): it grows while a joint stays stuck, or creeps slower than its creep '
         'speed, away from the goal with the push not taken by its damping, holds while a '
         'friction takes the push, and leaks away where the damping takes it and near the '
         'goal; along a motion faster than the creep it fades out. Zeros = off. Live.',
         default_text=JOINT_ZEROS_TEXT, field='friction_learning_limit_nm', **PER_JOINT),
    Spec('friction_learning_time', Kind.DOUBLE, 1.0,
         'Time (s) to learn friction_learning_limit while stuck; the learned part leaks with '
         'this time constant near the goal, and 5x faster where the damping takes the push. '
         'Live.', bounds=(0.01, 1000.0),
         field='friction_learning_time_s'),
    Spec('friction_velocity', Kind.DOUBLE, 0.05,
         'v_eps (rad/s) of the velocity part, f tanh(qdot / v_eps); the learning creeps a held '
         'joint at 2 v_eps or more (less on a light joint that has learned much) and fades its '
         'learned push out over 6 v_eps. Live.',
         bounds=(1e-4, 10.0), field='friction_velocity_rad_s'),
    Spec('friction_error_band', Kind.DOUBLE, 0.004,
         '||e|| below which the friction compensation fades out (it is off below half of '
         'it). Live.', bounds=(1e-5, 1.0)),
    Spec('friction_position_band', Kind.DOUBLE, 0.0005,
         '||p_d - p|| (m) below which the friction compensation fades out (pose and position '
         'tasks). Live.',
         bounds=(1e-6, 1.0), field='friction_position_band_m'),
    Spec('configuration_gain', Kind.DOUBLE_ARRAY, joint_zeros,
         'Most torque (N m) the goal-configuration term asks of each joint ({n}); it pulls '
         'towards a goal configuration within the limits found by the goal check, fading in '
         'over 0.1 s when that configuration is new. Zeros = off. Live.',
         default_text=JOINT_ZEROS_TEXT, **PER_JOINT),
    Spec('configuration_radius', Kind.DOUBLE, 0.05,
         'Dead zone (rad, per joint) around the goal configuration where only the '
         "paper's term acts. Live.", bounds=(0.0, 3.2), field='configuration_radius_rad'),
    Spec('configuration_ramp', Kind.DOUBLE, 0.25,
         'Width (rad) over which the goal-configuration torque rises to its gain. Live.',
         bounds=(1e-3, 3.2), field='configuration_ramp_rad'),
    Spec('damping_speed', Kind.DOUBLE_ARRAY, joint_zeros,
         'v_c (rad/s) of the cubic damping term -k_v qdot (qdot / v_c)^2, one per joint ({n}); '
         '0 = linear damping only. Live.', default_text=JOINT_ZEROS_TEXT,
         field='damping_speed_rad_s', **PER_JOINT),
    Spec('inertial_damping', Kind.DOUBLE_ARRAY, joint_zeros,
         'c_j, one per joint ({n}), N m s/rad per sqrt(kg m^2): the damping of joint j is '
         'max(k_v,j, min(c_j sqrt(M_jj(q)), inertial_damping_rate I_j(q))), M_jj(q) its own '
         'inertia and I_j(q) = 1 / (M(q)^-1)_jj the inertia it sees while the others move '
         'freely, at the measured configuration (armature included): it keeps the damping '
         'ratio zeta of a stiffness k_j (c_j = 2 zeta sqrt(k_j)) where the arm is heavy, within '
         'what the sampled loop tolerates where it is light; with it on, no mode of '
         'M(q)^-1 times the damping (k_v included) is faster than inertial_damping_rate '
         '(docs/lyapunov.md, section 10). Zeros = k_v alone. Live.',
         default_text=JOINT_ZEROS_TEXT, **PER_JOINT),
    Spec('inertial_damping_rate', Kind.DOUBLE, DEFAULT_INERTIAL_DAMPING_RATE,
         'beta (1/s): the inertial damping of a joint is at most beta I_j(q), half the damping '
         'per kg m^2 of seen inertia that the sampled loop tolerates, and no mode of the '
         'damping coupled through M(q) is faster than beta (design_gains writes it for the '
         'rate and delays designed for; the default is for 1 kHz and up to 2 ticks of delay, '
         'checked with 3). Live.', bounds=(1.0, 1e6),
         field='inertial_damping_rate_per_s'),
    Spec('settling_damping_rate', Kind.DOUBLE, 0.0,
         'alpha (1/s): near the goal, the damping torque -psi alpha M(q) qdot on top of the '
         "joint damping, M(q) the whole mass matrix: it damps the arm's coupled modes, which "
         'a damping per joint leaves underdamped, so the final approach settles instead of '
         'swinging about the goal. psi is 1 where every task row is within the linear range '
         'of its tanh (|lambda_i y_i| <= 1) and fades to 0 at twice that (docs/lyapunov.md, '
         'section 11). 0 = off. Live.', bounds=(0.0, MAX_SETTLING_RATE),
         why=('alpha M alone would damp faster than a sampled loop of 100 Hz follows (at 1 '
              'kHz with 3 ticks of delay it goes unstable near 450/s, at 100 Hz near 45/s); '
              'design_gains checks the value it writes at the rate designed for'),
         field='settling_damping_rate_per_s'),
    Spec('armature_estimation_limit', Kind.DOUBLE_ARRAY, joint_zeros,
         'The most rotor inertia (kg m^2, kg for a prismatic joint) the controller may find '
         'beyond the armature told, one per joint ({n}): while the arm moves, the torque that '
         'accelerates each joint beyond what M(q) accounts for is fitted, and a fit known to '
         '20% is added to the diagonal of M(q) wherever the damping, the speed guard and the '
         'friction learning use it (the potential and g(q) hold no inertia). /diagnostics '
         'reports it as armature_estimate. Zeros = off. Live.',
         default_text=JOINT_ZEROS_TEXT, field='armature_estimation_limit_kg_m2', **PER_JOINT),
    Spec('gain_redesign', Kind.BOOL, False,
         'Design the gains again when the rotor inertia estimate (armature_estimation_limit) '
         'shows a joint more than twice as heavy as its model, settled or still rising (then: '
         "1.5 times the inertia its gains were designed for): design_gains' rules, with the "
         'robot, design_options and the armature told plus half the inertia found, in a worker '
         'process; the live parameters that change are then set, and logged, as ros2 param '
         'set would (docs/gain_design.md, section 6). A few times at most: each design '
         'multiplies what some joint is designed for by more than 1.5. false = never (the '
         'gains stay as set). Live.'),
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
         'nearest the measured joints (in the time they take to get there at their velocity '
         'limits), then nearest this posture with posture_weight, and out '
         'of the joint-limit bands (docs/lyapunov.md, section 9). Default: the middle of the '
         'ranges. Next goal on. Live.', constraints='{n} finite values within the joint limits',
         default_text='the middle of the ranges', size='n', empty_ok=True,
         field='preferred_configuration_rad'),
    Spec('posture_weight', Kind.DOUBLE, 0.0,
         'Weight of preferred_configuration against the distance to the measured joints when '
         "a redundant arm's goal configuration is chosen (0: the nearest only). No effect on "
         'an arm without self-motion. Next goal on. Live.', bounds=(0.0, MAX_POSTURE_WEIGHT)),
)

# The context the docs' table is written with (docs/parameters.md): symbols, not one robot.
DOCS_CONTEXT = {'task': Task.ORIENTATION, 'n': 'n',
                'dim': '3 (orientation, position) or 6 (pose)',
                'axes': 'rx, ry, rz; the pose task has x, y, z first, the position task x, y, z '
                        'only',
                'top': f'max(effort limit) / {SATURATING_ERROR:g}',
                'ceiling': f'max(effort limit) / {SATURATING_ERROR:g}',
                'lambda_ceiling': MAX_LAMBDA, 'preferred_configuration': ()}


def shaping_default(name: str) -> Any:
    """Return the default of the SHAPING row ``name`` (a scalar's; for the snapshot's fields)."""
    return row(SHAPING, name).default


def shaping_context(n_joints: int) -> dict[str, Any]:
    """Return the context of the SHAPING rows for ``n_joints`` joints, without a posture."""
    return {'n': n_joints, 'preferred_configuration': ()}
