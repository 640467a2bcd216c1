"""
The parameter files of a gain design: the controller's and the simulator's (config/*.yaml).

:func:`to_yaml` writes the controller's file from the parameter table (``parameter_table``), with
the design's rules and figures in its header; :func:`sim_yaml` writes a ``wrist_sim_node`` file
for the same joints (the simulator itself is not imported). ROS-free.
"""
from math import pi
import textwrap
from typing import Optional, Sequence

import numpy as np

from quat_jt_controller import control_law as cl
from quat_jt_controller import parameter_table as table
from quat_jt_controller.gain_analysis import DELAY_MARGIN, GAIN_MARGIN, sigma_min
from quat_jt_controller.gain_design import (
    CARRIED_SPEED_SHARE, CARRY_STEP, DAMPING_RATIO, Design,
    ESTIMATED_ARMATURE_ACCELERATION_RAD_S2, FRICTION_LEARNING_TIME_S, GRAVITY_RESERVE_SHARE,
    GUIDE_OVER_TASK, LIMIT_OVER_TASK, REGULAR_SIGMA_MIN, REGULAR_TRIES, SAMPLES, SPEED_MARGIN,
    TICK_SPEED_SHARE, TORQUE_SHARE)
from quat_jt_controller.model import RobotModel
from quat_jt_runtime.param_table import Kind, names, row, yaml_lines, yaml_value

ENGINES = ('pybullet', 'mujoco')  # the simulator's engine parameter (sim_yaml)


def _saturation(lam: Sequence[float], task: cl.Task) -> str:
    """Say from which error the tanh force is 96% of K_p (tanh(x) = 0.96 at x = 1.946)."""
    x96 = float(np.arctanh(0.96))
    parts = []
    if task.has_orientation:
        e = x96 / lam[-1]  # ||e|| = sin(theta / 2)
        parts.append(f'{np.degrees(2.0 * np.arcsin(e)):.0f} deg' if e < 1.0
                     else 'no angle (orientation)')
    if task.has_position:
        parts.append(f'{x96 / lam[0]:.2g} m')
    return 'tanh at 96% of K_p from ' + ' / '.join(parts)


def _carried(d: Design) -> str:
    """Say where K_v was raised so that the arm does not carry a joint too fast, and where not."""
    f = d.figures
    raised = [name for name, k in zip(d.joints, f['carry_damping_nms']) if k > 0.0]
    over = [(name, sliding) for name, v, lim, sliding in zip(
        d.joints, f['carried_speed_rad_s'], f['velocity_limits_rad_s'], f['prismatic'])
        if v > CARRY_STEP * CARRIED_SPEED_SHARE * lim]
    above = [name for name, sliding in over if not sliding]
    slides = [name for name, sliding in over if sliding]
    text = (f': K_v raised to bring that towards {CARRIED_SPEED_SHARE:g} x the velocity limit '
            f'on {", ".join(raised)}' if raised else '')
    if above:
        text += (f'{"; " if text else ": "}still above it on {", ".join(above)} (their damping '
                 'at the most the sampled loop allows, or no budget to push them harder)')
    if slides:
        text += (f'{"; " if text else ": "}above it on {", ".join(slides)}, left as they are '
                 '(sliding joints: docs/gain_design.md, section 3)')
    return text


def _regular_note(f: dict) -> str:
    """Say which sigma_min the representative configurations have, if not the usual one."""
    threshold = f.get('regular_sigma_min', REGULAR_SIGMA_MIN)
    if threshold >= REGULAR_SIGMA_MIN:
        return ''
    return (f' (sigma_min(J) >= {threshold:.3g}: none of {REGULAR_TRIES} random ones reached '
            f'{REGULAR_SIGMA_MIN:g})')


def _reserve(f: dict) -> str:
    """Say what is reserved for gravity where it is less than the largest |g(q)|."""
    reserve = f.get('gravity_reserve_nm')
    if reserve is None or np.allclose(reserve, f['gravity_max_nm']):
        return ''
    return (f' (reserved for gravity: at most {GRAVITY_RESERVE_SHARE:g} x the effort limit, '
            f'{_fmt(np.round(reserve, 4))})')


def _fmt(values) -> str:
    return yaml_value(Kind.DOUBLE_ARRAY, values)


def _live_names(specs) -> str:
    """
    Return the names of ``specs``, a run of names with the same first word as ``prefix_*``.

    ``joint_limit_margin, joint_limit_gain`` is written ``joint_limit_*``.
    """
    out, names_ = [], [spec.name for spec in specs]
    i = 0
    while i < len(names_):
        word = names_[i].split('_')[0]
        j = i
        while j + 1 < len(names_) and names_[j + 1].split('_')[0] == word:
            j += 1
        if j == i:
            out.append(names_[i])
        else:
            parts = [name.split('_') for name in names_[i:j + 1]]
            common = []
            for words in zip(*parts):
                if len(set(words)) > 1:
                    break
                common.append(words[0])
            out.append('_'.join(common) + '_*')
        i = j + 1
    return ', '.join(out)


def to_yaml(d: Design, potential: str = 'tanh', command: str = '',
            robot_description_note: str = '') -> str:
    """
    Return a parameter file for controller_node in the format of config/*_controller.yaml.

    Keyed ``/**:`` + ``ros__parameters:`` so it applies to any node name and namespace. The
    comments give the rule behind each value and the design's own figures.
    """
    f = d.figures
    s = d.shaping
    axes = ', '.join((['x, y, z (N/m)'] if d.task.has_position else [])
                     + (['rx, ry, rz (N m)'] if d.task.has_orientation else []))
    rho = f['spectral_radius']
    zeta = f['damping_ratio']
    header = [
        f'quat_jt_controller: {d.task.value} task, {d.base_link} -> {d.tip_link}, joints '
        f'{", ".join(d.joints)}.',
        'Generated by quat_jt_controller.gain_design (docs/gain_design.md gives each rule):',
        f'  {command or "python -m quat_jt_controller.gain_design ..."}',
        f'Live parameters (ros2 param set): {", ".join(names(table.GAINS))} and the '
        f'extensions ({_live_names(table.SHAPING)}; '
        f'docs/lyapunov.md), and the payload ({", ".join(names(table.PAYLOAD))}). The rest is '
        'read-only.',
        'The design, per joint (N m unless said):',
        f'  effort limits {_fmt(f["effort_limits_nm"])}, largest |g(q)| '
        f'{_fmt(np.round(f["gravity_max_nm"], 4))}{_reserve(f)}, friction estimates '
        f'{_fmt(f["friction_nm"])}, rotor inertia (armature, in M(q)) '
        f'{_fmt(d.armature or [0.0] * len(d.joints))} kg m^2'
        + (f', payload {d.payload_kg:g} kg at {_fmt(d.payload_com_tip_m)} m in {d.tip_link} '
           '(in g(q) and M(q))' if d.payload_kg > 0.0 else '') + ';',
        f'  at rest the regulator may learn {f["friction_learning"]:g} x the estimates more, '
        f'and without an estimate {f.get("friction_effort_share", 0.0):g} x the effort limit (a '
        'friction nobody measured; at most what changes the speed of the joint by '
        f'{TICK_SPEED_SHARE:g} x its limit in one tick), in '
        f'{FRICTION_LEARNING_TIME_S:g} s;',
        f'  budget {TORQUE_SHARE:g} x (effort - gravity reserved - friction - learnable '
        'friction) = '
        f'{_fmt(f["budget_nm"])}, of which the task potential may ask at most (a-priori '
        f'bound of the tanh law) {_fmt(f["task_bound_nm"])} and the goal-configuration term '
        f'{_fmt(f["guide_nm"])};',
        f'  joint-limit band torque at a stop {_fmt(f["limit_at_stop_nm"])};',
        f'  sampled loop at {d.rate_hz:g} Hz with {"/".join(str(x) for x in f["delays"])} '
        f'tick(s) of delay and {max(f["delays"]) + DELAY_MARGIN}, and at {GAIN_MARGIN:g} x the '
        f'gains, per joint on the inertia it sees (1 / (M^-1)_jj, smallest '
        f'{_fmt(f["inertia_min"])} kg m^2), linearised at {SAMPLES} regular configurations'
        f'{_regular_note(f)}: '
        'worst spectral '
        f'radius {rho["tanh"]:.6f} (tanh), {rho["quadratic"]:.6f} (quadratic) < 1; median '
        f'damping ratios per joint (without the settling damping) tanh {_fmt(zeta["tanh"])}, '
        f'quadratic {_fmt(zeta["quadratic"])};',
        f'  settling damping {s.settling_damping_rate_per_s:g} M(q) near the goal: the '
        'slowest mode of the tanh loop decays at '
        f'{f["settling_decay_per_s"][1]:.3g} 1/s, {f["settling_decay_per_s"][0]:.3g} without '
        '(median over the configurations);',
        f'  cruising speeds far from the goal {_fmt(f["terminal_speed_rad_s"])} rad/s where '
        'K_v alone damps (the fastest; velocity limits '
        f'{_fmt(f["velocity_limits_rad_s"])}, aimed at '
        f'{f["cruise_fraction"]:g} x them, at most {SPEED_MARGIN:g} x them: K_v is raised where '
        'the cubic damping cannot hold the push there), median over the configurations with '
        f'the inertial damping {_fmt(f["typical_speed_rad_s"])} rad/s;',
        "  speeds the other joints' pushes may give each joint through M(q) (an overestimate) "
        f'{_fmt(np.round(f["carried_speed_rad_s"], 4))} rad/s (m/s on a slide){_carried(d)}.',
        f'Expected time to a goal: about {f["time_to_goal_s"]:.2g} s for a 1 rad move of every '
        'joint (the slowest median cruise, then ln(1000) time constants of the slowest linear '
        'mode).',
    ]
    header += [f'WARNING: {w}' for w in f.get('warnings', ())]
    lines = []
    for entry in header:
        indent = '#   ' if entry.startswith('  ') else '# '
        lines += textwrap.wrap(entry.strip(), width=99, initial_indent=indent,
                               subsequent_indent=indent + '  ', break_on_hyphens=False,
                               break_long_words=False)
    comments = {
        'task': 'read-only',
        'design_options': "design_gains' options no other parameter holds",
        'potential': "'tanh' (Eq. 32/38) or 'quadratic' (Eq. 24/37); one set serves both",
        'kp': f'K_p, {axes}: a-priori torque bound within the budget',
        'kv': f'K_v, N m s/rad: damping ratio {DAMPING_RATIO:.2f} (tanh), from M(q), or '
              'more to hold the speed or where the arm would carry the joint too fast',
        'lambda': f'Lambda: {_saturation(d.lam, d.task)}',
        'gravity_compensation': '+ g(q) from the URDF',
        'joint_limit_margin': 'rad, band inside each limit (joints with less than a full turn)',
        'joint_limit_gain': (f'N m/rad: at the stop {LIMIT_OVER_TASK:g} x the task bound or '
                             f'K_v {SPEED_MARGIN:g} v_lim'),
        'large_error_gain': 'N m; 0: the goal-configuration term carries large errors',
        'friction_compensation': 'N m, the Coulomb estimates (0 = off)',
        'friction_learning_limit': 'N m, the most learned at rest on top (0 = none)',
        'friction_learning_time': 's, to learn it while stuck; it leaks as fast near the goal',
        'armature_estimation_limit': ('kg m^2, the most rotor inertia found from the motion '
                                      'beyond the armature: what the effort limit accelerates '
                                      f'at {ESTIMATED_ARMATURE_ACCELERATION_RAD_S2:g} rad/s^2'),
        'gain_redesign': ('design the gains again for a joint found twice as heavy as designed '
                          'for (with design_options)'),
        'friction_velocity': 'rad/s, v_eps of f tanh(qdot / v_eps)',
        'friction_error_band': '||e|| where the compensation fades out',
        'friction_position_band': 'm, the same for ||p_d - p||',
        'configuration_gain': f'N m: {GUIDE_OVER_TASK:g} x the task bound, more on a joint it '
                              'would leave slow',
        'configuration_radius': 'rad, dead zone around q*',
        'configuration_ramp': 'rad, the torque rises over this (0.25, or --approach-time)',
        'damping_speed': 'rad/s, v_c of the cubic damping (0 = none)',
        'inertial_damping': 'damping at least c sqrt(M_jj(q)): the damping ratio where the '
                            'arm is heavy',
        'inertial_damping_rate': '1/s, ... at most this x 1 / (M(q)^-1)_jj: what the sampled '
                                 'loop tolerates',
        'settling_damping_rate': '1/s, alpha of -alpha M(q) qdot near the goal: the slowest '
                                 'coupled mode decays fastest (0 = off)',
        'goal_velocity_gain': "damping towards a streamed goal's velocity (0 = off)",
        'preferred_configuration': "rad, the posture a redundant arm's q* leans to",
        'posture_weight': 'of that posture against the distance to the arm (no effect without '
                          'self-motion)',
        'armature': 'kg m^2, rotor inertia per joint, in M(q) of the design',
        'payload_mass': 'kg the tip link carries beyond the URDF, in g(q) and M(q)',
        'payload_com': 'm, where, in tip_link',
        'robot_description': "URDF XML; '' = the bundled wrist" + (
            f' ({robot_description_note})' if robot_description_note else ''),
        'state_timeout': 's without valid joint_states -> zero torque (once)',
        'max_state_age': 's; older, future or unstamped states are rejected; 0 = off',
        'state_rate': 'Hz, the joint_states rate designed for (--rate)',
        'publish_rate_divider': 'feedback topics at 100 Hz',
    }
    # The task first (it sizes the gains), the live rows (the design's, or their defaults),
    # then the read-only rows the design gives.
    structure = d.structure()
    context = {'task': d.task, 'dim': d.task.dim, 'n': len(d.joints),
               'preferred_configuration': s.preferred_configuration_rad}
    live = tuple(table.GAINS) + tuple(table.SHAPING)
    values = {spec.name: spec.default_value(context) for spec in live}
    values.update(d.parameters(potential))
    values.update(structure)
    first = row(table.STRUCTURE, 'task')
    rows = (first, *live, *table.PAYLOAD, *(spec for spec in table.STRUCTURE
                                            if spec is not first and spec.name in structure))
    lines += ['/**:  # any node name and namespace', '  ros__parameters:']
    lines += yaml_lines(rows, values, comments)
    return '\n'.join(lines) + '\n'


def sim_yaml(model: RobotModel, rate_hz: float,
             initial_positions_rad: Optional[Sequence[float]],
             coulomb_nm: Optional[Sequence[float]],
             viscous_nm_s_per_rad: Optional[Sequence[float]],
             command: str = '', robot_description_note: str = '',
             armature: Optional[Sequence[float]] = None, engine: str = ENGINES[0]) -> str:
    """
    Return a parameter file for wrist_sim_node in the format of config/*_sim.yaml.

    The joints are the design's; the others of the URDF (a gripper's fingers) are held where
    they are by the simulator. The start defaults to the middle of the ranges, the friction to
    none, the rotor inertia (``armature``) and the payload to the model's. Raises ValueError on
    a list of the wrong length or a start outside the limits.
    """
    n = model.n
    lower, upper = np.array(model.position_lower), np.array(model.position_upper)
    start = (0.5 * (np.maximum(lower, -pi) + np.minimum(upper, pi))
             if initial_positions_rad is None else np.array(initial_positions_rad, float))
    coulomb = np.zeros(n) if coulomb_nm is None else np.array(coulomb_nm, float)
    viscous = (np.zeros(n) if viscous_nm_s_per_rad is None
               else np.array(viscous_nm_s_per_rad, float))
    rotor = np.array(model.armature if armature is None else armature, float)
    if engine not in ENGINES:
        raise ValueError(f'engine must be one of {list(ENGINES)}, got {engine!r}')
    for name, values in (('--initial-positions', start), ('--sim-coulomb', coulomb),
                         ('--sim-viscous', viscous), ('--sim-armature', rotor)):
        if values.size != n or not np.all(np.isfinite(values)):
            raise ValueError(f'{name}: expected {n} finite values, got {values.tolist()}')
    if np.any(rotor < 0.0):
        raise ValueError(f'--sim-armature: values must be >= 0, got {rotor.tolist()}')
    if np.any(start < lower) or np.any(start > upper):
        raise ValueError(f'--initial-positions {start.tolist()} are outside the limits')
    _, _, J = model.kinematics(start.tolist())
    sigma = sigma_min(np.array(J))
    note = f'  # {robot_description_note}' if robot_description_note else ''
    lines = [
        *textwrap.wrap(f'wrist_sim_node for {model.base_link} -> {model.tip_link}, joints '
                       f'{", ".join(model.joint_names)}.', width=97, initial_indent='# ',
                       subsequent_indent='#   ', break_on_hyphens=False),
        '# Generated by quat_jt_controller.gain_design with the controller config:',
        *textwrap.wrap(command or 'python -m quat_jt_controller.gain_design ...',
                       width=95, initial_indent='#   ', subsequent_indent='#     ',
                       break_on_hyphens=False, break_long_words=False),
        '# Joints of the URDF not listed here are held by the simulator where they are (at 0).',
        '# Floats are written as floats: ROS 2 parameters are strictly typed (1 is not 1.0).',
        '/**:  # any node name and namespace',
        '  ros__parameters:',
        f"    robot_description: ''{note}",
        f'    joints: [{", ".join(model.joint_names)}]',
        f'    initial_positions: {_fmt(np.round(start, 4))}  # rad, at rest; sigma_min(J) '
        f'{sigma:.3g}',
        f'    rate_hz: {int(round(rate_hz))}',
        '    use_gui: false                   # true opens the PyBullet window',
        '    publish_clock: false             # real-time pacing',
        '    lockstep_timeout: 0.05',
        '    max_real_time_factor: 0.0',
        f'    viscous_friction: {_fmt(viscous)}  # N m s/rad',
        f'    coulomb_friction: {_fmt(coulomb)}  # N m (stiction level)',
        f'    armature: {_fmt(rotor)}  # kg m^2, rotor inertia per joint (engine mujoco)',
        *([f'    payload_link: {model.tip_link}  # carries the payload of the design',
           f'    payload_mass: {model.payload_kg!r}  # kg',
           f'    payload_com: {_fmt(model.payload_com_tip_m)}  # m, in payload_link']
          if model.payload_kg > 0.0 else []),
        f'    engine: {engine}                 # or '
        + ' or '.join(e for e in ENGINES if e != engine),
        '    command_timeout: 0.5             # s without a valid command -> zero torque',
        '    enforce_velocity_limits: true    # the URDF velocity limits, as a drive holds them',
        '    hold_until_first_command: true   # brakes on until the first command',
        "    stats_file: ''",
    ]
    return '\n'.join(lines) + '\n'
