"""
What the controller reports on /diagnostics, computed without ROS.

Each function returns ``(level, message, [(key, value)])`` with levels OK, WARN, ERROR (the
values of diagnostic_msgs/DiagnosticStatus); the node only wraps them into messages.
"""
from dataclasses import dataclass
from math import isfinite, nan
from typing import NamedTuple, Optional, Sequence

from quat_jt_controller.regulator import Goal, Regulator, TickOutput

OK, WARN, ERROR = 0, 1, 2  # diagnostic_msgs/DiagnosticStatus levels
# |eta_e| below this means the error is within ~11.5 degrees of 180 degrees, where
# Q(eta_e, e)^T K_p e can vanish (docs/errata.md, note 6): reported as a warning.
NEAR_180_ETA_E = 0.1
# Saturated ticks above this fraction of a diagnostics window give a warning.
SATURATION_WARN_FRACTION = 0.05
# No state yet from a publisher the graph knows: until this long after start, it may still be
# connecting (discovery took up to 2.8 s on a loaded 2-core VM)
NO_STATE_CONNECTING_S = 5.0

Status = tuple[int, str, list[tuple[str, str]]]


@dataclass
class Counters:
    """Events counted over the node's life, reported with every status."""

    rejected_states: int = 0
    stale_states: int = 0  # of the rejected: unstamped, too old or in the future
    foreign_states: int = 0  # not rejected but ignored: naming none of the controlled joints
    rejected_goals: int = 0
    accepted_goals: int = 0
    nonfinite_torques: int = 0
    prewarm_passes: int = 0  # throwaway ticks run before a state was due (realtime.Prewarm)


def graph_warnings(command_topic: str, command_publishers: int, node_name: str,
                   nodes_with_that_name: int) -> list[str]:
    """Warn of a second commander on the robot, or a second node of the same full name."""
    warnings = []
    if command_publishers > 1:
        warnings.append(f'{command_publishers} publishers on {command_topic}: another '
                        'controller commands this robot too, and they fight')
    if nodes_with_that_name > 1:
        warnings.append(f'{nodes_with_that_name} nodes are named {node_name}: parameters and '
                        'goals reach them both; give each its own name')
    return warnings


def start_warnings(regulator: Regulator) -> list[str]:
    """Return, for the log at start-up, what the URDF leaves out that the guards need."""
    model = regulator.model
    none = [name for name, v in zip(model.joint_names, model.velocity_limits)
            if not (isfinite(v) and v > 0.0)]
    if not none:
        return []
    return [f'no velocity limit in the URDF (0 or none) for joints {none}: the speed guard does '
            "not hold them back (docs/lyapunov.md, section 6). Give the drives' velocity limits "
            'in the URDF']


def gravity_beyond_effort(regulator: Regulator, q: Sequence[float]) -> list[str]:
    """
    Name the joints whose effort limit is below what gravity alone asks of them at ``q``.

    There the arm cannot hold itself (the model's links and payload): the tick's command is
    clamped at the limit (``control_law.saturate``, the regulator's clamp: a joint without a
    usable limit has none) and the joint sags, whatever the potential. Empty with
    ``gravity_compensation`` off (the drives then hold the weight).
    """
    if not regulator.gains.gravity_compensation:
        return []
    model = regulator.model
    joints = zip(model.joint_names, model.gravity(q), regulator.effort_limits_nm)
    return [f'{name} needs {abs(g):.3g} N m against gravity here, above its effort limit '
            f'{limit:g} N m' for name, g, limit in joints if abs(g) > limit]


def command_order_problem(joints: Sequence[str], receiver: str,
                          theirs: Sequence[str]) -> str:
    """
    Say why ``receiver``'s joints cannot take this controller's commands ('' if they can).

    A command is one torque per joint, in the order of the controller's ``joints``; a receiver
    (ros2_control's JointGroupEffortController, the simulator) applies the i-th torque to the
    i-th joint of its own ``joints`` parameter. Any other list sends torques to the wrong
    joints.
    """
    ours, theirs = list(joints), list(theirs)
    if theirs == ours:
        return ''
    if sorted(theirs) == sorted(ours):
        how = 'the same joints in another order'
    else:
        missing = [j for j in ours if j not in theirs]
        extra = [j for j in theirs if j not in ours]
        how = f'other joints (without {missing}, with {extra})'
    return (f'{receiver} applies the commands to joints {theirs}, this controller computes them '
            f'for {ours}: {how}, so torques would go to the wrong joints. Commands stopped '
            '(zero torque published once): give both the same joints in the same order')


def no_state_warning(state_topic: str, waited_s: float, publishers: int, rejected: int,
                     foreign: int = 0) -> str:
    """
    Say that no valid joint state has come since start: on which topic, from how many publishers.

    ``publishers``: the graph's count on the resolved ``state_topic``; ``rejected``: the states
    received and refused so far (each refusal is logged with its reason). A publisher that has
    sent nothing for a few seconds is more than a connection still being made.
    """
    if not publishers:
        detail = ('is the robot driver or simulator running, and publishing on this topic? '
                  '(remap with -r joint_states:=<its topic>)')
    elif rejected or foreign:
        detail = ', '.join(
            ([f'{rejected} received and rejected (see the warnings logged)'] if rejected else [])
            + ([f'{foreign} received naming none of the controlled joints (another '
                "publisher's, or the driver names the joints otherwise: compare the "
                "controller's joints with the names it logged)"] if foreign else []))
    elif waited_s < NO_STATE_CONNECTING_S:
        detail = 'none received yet (still connecting?)'
    else:
        detail = 'none received (a QoS mismatch, or a publisher that publishes nothing?)'
    return (f'no valid joint state on {state_topic} {waited_s:.1f} s after start, {publishers} '
            f'publisher{"" if publishers == 1 else "s"} on it: {detail}; no command is '
            'published until one arrives')


def loop_status(figures: dict, waiting: bool, stopped: bool, counters: Counters,
                graph_warnings: Sequence[str] = (), refusal: str = '',
                unheld: Sequence[str] = ()) -> Status:
    """
    Report the control loop: rate, timing, saturation, timeouts (TickStats.window figures).

    ``refusal``: why commands are stopped ('' when they are not): an ERROR. ``unheld``: the
    joints gravity asks more of than their effort limits where the arm is
    (:func:`gravity_beyond_effort`): a WARN.
    """
    messages = []
    level = OK
    if refusal:
        level = ERROR
        messages.append(refusal)
    if waiting:
        level = max(level, WARN)
        messages.append('waiting for joint_states')
    elif stopped:
        level = ERROR
        messages.append('joint_states timed out: commanding zero torque')
    n, saturated = figures['ticks_in_window'], figures['saturated_ticks']
    if n and saturated > SATURATION_WARN_FRACTION * n:
        level = max(level, WARN)
        messages.append(f'torque saturated in {saturated}/{n} ticks')
    if unheld:
        level = max(level, WARN)
        messages.append(f'the arm cannot hold itself here: {"; ".join(unheld)} (its command is '
                        'clamped and it sags: check the payload and the effort limits, or give '
                        'an intermediate goal the arm can hold)')
    if counters.stale_states:
        level = max(level, WARN)
        messages.append(f'{counters.stale_states} joint states rejected for their stamps '
                        '(unstamped, too old or in the future; see max_state_age)')
    for warning in graph_warnings:
        level = max(level, WARN)
        messages.append(warning)
    if counters.nonfinite_torques:
        level = max(level, WARN)
        messages.append(f'{counters.nonfinite_torques} non-finite torques replaced by zero')
    message = '; '.join(messages) or f'running at {figures["control_rate_hz"]:.0f} Hz'
    values = [(k, f'{v:.1f}' if isinstance(v, float) else str(v)) for k, v in figures.items()]
    values += [('rejected_states_total', str(counters.rejected_states)),
               ('stale_states_total', str(counters.stale_states)),
               ('foreign_states_total', str(counters.foreign_states)),
               ('nonfinite_torques_total', str(counters.nonfinite_torques)),
               ('prewarm_passes_total', str(counters.prewarm_passes)),
               ('state_timeout', str(stopped))]
    return level, message, values


def goal_status(source: str, goal: Optional[Goal], warning: str, last: Optional[TickOutput],
                qdot: Optional[Sequence[float]], with_position: bool, counters: Counters,
                goal_check_unavailable: str = '', goal_check_ready: bool = True,
                configuration: Optional['ConfigurationState'] = None,
                designs: Optional[tuple[bool, str]] = None) -> Status:
    """
    Report the goal: its source, the A1/A2 advice, the errors, a near-180-degree warning.

    ``goal_check_unavailable`` says why goal checks are not being made ('' when they are);
    ``goal_check_ready`` is False while the worker is still building its model ('starting').
    ``configuration`` gives the goal configuration q* and the friction learned at rest.
    ``designs``, where the gains are designed again (``gain_redesign``), is the design
    worker's ``(ready, unavailable_reason)``; None: no key.
    """
    level = OK
    messages = [{'none': 'no goal (no joint state yet)',
                 'hold': 'holding the initial pose (no goal received)',
                 'target_pose': 'regulating to target_pose'}[source]]
    if goal_check_unavailable:
        level = WARN
        messages.append(f'goal checks unavailable: {goal_check_unavailable}')
    if warning:
        level = WARN
        messages.append(warning)
    eta_e = last.eta_e if last is not None else nan
    if abs(eta_e) < NEAR_180_ETA_E:
        level = WARN
        messages.append(f'orientation error near 180 degrees (eta_e = {eta_e:.3f}): the '
                        'orientation torque can vanish there; give an intermediate goal')
    values = [
        ('error_norm', f'{last.orientation_error_norm:.6g}' if last else 'nan'),
        ('eta_e', f'{eta_e:.6g}'),
        ('max_joint_speed_rad_s', f'{max(abs(x) for x in qdot):.4g}' if qdot else 'nan'),
        ('goal_source', source),
        ('goal_check', 'unavailable' if goal_check_unavailable else
         'available' if goal_check_ready else 'starting'),
        ('goal_xyzw', str([round(c, 6) for c in goal.xyzw()]) if goal else ''),
    ]
    if with_position:
        values += [
            ('position_error_m', f'{last.position_error_norm_m:.6g}' if last else 'nan'),
            ('goal_position_m',
             str([round(c, 6) for c in goal.p_desired_base]) if goal else ''),
        ]
    if configuration is not None:
        values += configuration.values()
        note = configuration.note(source)
        if note:
            messages.append(note)
    if designs is not None:
        design_ready, design_unavailable = designs
        if design_unavailable:
            level = WARN
            messages.append(f'designs again unavailable (gain_redesign): {design_unavailable}')
        values.append(('design_worker', 'unavailable' if design_unavailable else
                       'available' if design_ready else 'starting'))
    values += [('accepted_goals_total', str(counters.accepted_goals)),
               ('rejected_goals_total', str(counters.rejected_goals))]
    return level, '; '.join(messages), values


class ConfigurationState(NamedTuple):
    """The goal configuration in force, the friction learned, the rotor inertia found."""

    term_on: bool  # the goal-configuration term has a gain
    q_star_rad: Optional[Sequence[float]]
    in_band: Sequence[str]  # joints whose q* lies in the limit band (the band ends at q*)
    learned_friction_nm: Sequence[float] = ()
    armature_estimate: Sequence[float] = ()  # kg m^2 per joint, while it is estimated

    def values(self) -> list[tuple[str, str]]:
        """Return the key-value pairs."""
        q_star = ('' if self.q_star_rad is None else
                  str([round(x, 6) for x in self.q_star_rad]))
        out = [('goal_configuration_rad', q_star),
               ('goal_configuration_in_band', ', '.join(self.in_band))]
        if self.learned_friction_nm:
            out.append(('learned_friction_nm',
                        str([round(x, 4) for x in self.learned_friction_nm])))
        if self.armature_estimate:
            out.append(('armature_estimate',
                        str([float(f'{x:.3g}') for x in self.armature_estimate])))
        return out

    def note(self, source: str) -> str:
        """Return what the goal's message says of q* ('' if nothing to say)."""
        if not self.term_on or source != 'target_pose':
            return ''
        if self.q_star_rad is None:
            return ('no goal configuration (none found within the limits yet): the '
                    'goal-configuration term is off for this goal')
        if self.in_band:
            return (f'the goal configuration lies in the joint-limit band of '
                    f'{", ".join(self.in_band)}: the band ends there')
        return ''


def configuration_state(regulator: Regulator) -> ConfigurationState:
    """
    Return the goal configuration in force, the friction learned and the rotor inertia found.

    From the regulator; each of the last two only while it is on.
    """
    names = regulator.model.joint_names
    shaping = regulator.shaping
    return ConfigurationState(
        shaping.configuration_on, regulator.goal_configuration,
        [names[j] for j in regulator.goal_in_band()],
        regulator.learned_friction_nm if shaping.learning_on else (),
        regulator.armature_estimate if shaping.armature_estimation_on else ())
