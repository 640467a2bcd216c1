"""The controller around the law (quat_jt_controller.controller), ROS-free: states and goals in."""
import math

import pytest
from quat_jt_controller import control_law as cl
from quat_jt_controller import diagnostics
from quat_jt_controller import paper
from quat_jt_controller import quaternion as quat
from quat_jt_controller.controller import (
    Controller, DIAGNOSTICS_WAIT_NS, GoalRequest, NO_STATE_REPEAT_NS, NO_STATE_WARN_NS, Severity)
from quat_jt_controller.regulator import Goal, Regulator
from robots import wrist_model

pytestmark = pytest.mark.unit

MS = 1_000_000  # ns
JOINTS = ('joint1', 'joint2', 'joint3')
REST = (0.0, 0.0, 0.0)
GAINS = cl.Gains.create('tanh', paper.KP, paper.KV, paper.LAMBDA, cl.Task.ORIENTATION, 3)


def regulator() -> Regulator:
    return Regulator(wrist_model(), cl.Task.ORIENTATION, GAINS)


def controller(divider: int = 3, checker=None, started_ns: int = 0, **kwargs) -> Controller:
    return Controller(regulator(), 0.5, divider, checker=checker, started_ns=started_ns,
                      **kwargs)


def tick(ctl: Controller, q, steady_ns: int, qdot=REST, stamp_ns: int = 0):
    """One state of the wrist's joints, unstamped unless told (max_state_age off)."""
    return ctl.on_state(JOINTS, q, qdot, stamp_ns, stamp_ns, steady_ns)


def turned(angle: float) -> Goal:
    s = math.sin(0.5 * angle)
    return Goal(quat.multiply((math.cos(0.5 * angle), 0.0, 0.0, s), paper.Q_DESIRED))


def request(goal: Goal, stamp_s: float = 0.0, frame: str = 'base_link') -> GoalRequest:
    return GoalRequest(frame, goal.xyzw(), (0.0, 0.0, 0.0), stamp_s)


def texts(logs, severity: Severity) -> list[str]:
    return [text for level, text in logs if level == severity]


def test_a_goal_then_states_give_the_regulators_torques():
    ctl = controller()
    reply = ctl.on_goal(request(Goal(paper.Q_DESIRED)), 0)
    assert reply.accepted and reply.new
    assert texts(reply.logs, Severity.INFO)[0].startswith('new goal: quaternion (x, y, z, w)')
    reference = Regulator(wrist_model(), cl.Task.ORIENTATION, GAINS, goal=Goal(paper.Q_DESIRED))
    for k, (q, qdot) in enumerate((((0.1, 0.2, 0.3), (0.3, -0.1, 0.2)),
                                   ((0.0, 0.5, 0.0), REST), ((-0.4, 1.0, 0.7), (0.0, 0.1, 0.0)))):
        cmd = tick(ctl, q, (k + 1) * MS, qdot)
        assert cmd.tau_nm == pytest.approx(reference.update(q, qdot).tau_nm)
        assert cmd.out.finite and not cmd.logs
    assert ctl.goal_source == 'target_pose' and ctl.counters.accepted_goals == 1
    assert not ctl.on_goal(request(Goal(paper.Q_DESIRED)), 5 * MS).new  # the same goal again


def test_the_first_state_holds_its_pose_until_a_goal():
    ctl = controller()
    assert ctl.goal is None and ctl.goal_source == 'none'
    cmd = tick(ctl, (0.1, 0.5, 0.2), 1500 * MS)
    assert ctl.goal_source == 'hold'
    assert ctl.regulator.goal_configuration == (0.1, 0.5, 0.2)
    [line] = texts(cmd.logs, Severity.INFO)
    assert line.startswith('first joint state, 1.50 s after start: holding the measured pose')
    held = ctl.goal
    assert cmd.tau_nm == pytest.approx(Regulator(
        wrist_model(), cl.Task.ORIENTATION, GAINS, goal=held).update((0.1, 0.5, 0.2), REST).tau_nm)
    assert not tick(ctl, (0.3, 0.5, 0.2), 1501 * MS).logs and ctl.goal is held  # held once
    assert ctl.on_goal(request(Goal(paper.Q_DESIRED)), 1502 * MS).new
    assert ctl.goal_source == 'target_pose'


def test_a_bad_goal_is_refused_with_its_reason_and_the_last_stays():
    ctl = controller()
    tick(ctl, (0.0, 0.5, 0.0), MS)
    held = ctl.goal
    bad = ctl.on_goal(GoalRequest('base_link', (0.0, 0.0, 0.0, 2.0), (0.0, 0.0, 0.0)), 2 * MS)
    assert not bad.accepted and ctl.goal is held and ctl.goal_source == 'hold'
    [line] = texts(bad.logs, Severity.WARN)
    assert line.startswith('target_pose rejected, previous goal stays in force:'), line
    assert '(x, y, z, w) = (0.0, 0.0, 0.0, 2.0)' in line, line
    nan = ctl.on_goal(GoalRequest('base_link', (math.nan, 0.0, 0.0, 1.0), (0.0, 0.0, 0.0)),
                      3 * MS)
    assert not nan.accepted and 'non-finite' in texts(nan.logs, Severity.WARN)[0]
    unknown = ctl.on_goal(request(Goal(paper.Q_DESIRED), frame='/world'), 4 * MS)
    assert not unknown.accepted and "header.frame_id is '/world'" in unknown.logs[0].text
    assert ctl.counters.rejected_goals == 3 and ctl.goal is held
    # the same cause again within a second: held back, then counted in the next line
    again = ctl.on_goal(GoalRequest('base_link', (0.0, 0.0, 0.0, 3.0), (0.0, 0.0, 0.0)),
                        500 * MS)
    assert not again.accepted and not again.logs
    later = ctl.on_goal(GoalRequest('base_link', (0.0, 0.0, 0.0, 4.0), (0.0, 0.0, 0.0)),
                        1100 * MS)
    assert later.logs[0].text.endswith('(and 1 more like it)'), later.logs


def test_a_link_goal_is_placed_with_the_measured_joints():
    ctl = controller()
    before = ctl.on_goal(GoalRequest('tool0', (0.0, 0.0, 0.0, 1.0), (0.0, 0.0, 0.0)), MS)
    assert not before.accepted and 'no joint state has come yet' in before.logs[0].text
    q = (0.2, 0.6, -0.3)
    tick(ctl, q, 2 * MS)
    reply = ctl.on_goal(GoalRequest('tool0', (0.0, 0.0, 0.0, 1.0), (0.0, 0.0, 0.0)), 3 * MS)
    assert reply.accepted and 'placed in base_link at the measured joints' in reply.logs[0].text
    here = ctl.regulator.pose(q).q_desired_base
    assert abs(sum(a * b for a, b in zip(ctl.goal.q_desired_base, here))) == pytest.approx(1.0)


def test_a_refused_state_gives_no_torque_and_says_why():
    ctl = controller(max_state_age_s=0.5)
    now = 10_000 * MS
    stale = ctl.on_state(JOINTS, (0.0, 0.5, 0.0), REST, now - 900 * MS, now, MS)
    assert stale.tau_nm is None and stale.out is None
    assert texts(stale.logs, Severity.WARN)[0].startswith('joint_states rejected, stamped 0.900')
    missing = ctl.on_state(('joint1', 'joint2'), (0.0, 0.5), (0.0, 0.0), now, now, 2 * MS)
    assert missing.tau_nm is None and 'joint3' in missing.logs[0].text
    assert ctl.counters.rejected_states == 2 and ctl.counters.stale_states == 1
    assert not ctl.has_state and ctl.goal is None
    assert tick(ctl, (0.0, 0.5, 0.0), 3 * MS, stamp_ns=now).tau_nm is not None


def test_a_state_naming_none_of_the_joints_is_ignored_and_said_once():
    """Another publisher on joint_states (a gripper's driver): not a rejection, one INFO."""
    ctl = controller()
    first = ctl.on_state(('finger_left', 'finger_right'), (0.01, 0.01), (0.0, 0.0), 0, 0, MS)
    assert first.tau_nm is None
    [line] = texts(first.logs, Severity.INFO)
    assert line.startswith('joint_states from another publisher: it names none of the '
                           "controlled joints: ['finger_left', 'finger_right']; such states "
                           'are ignored')
    again = ctl.on_state(('finger_left', 'finger_right'), (0.01, 0.01), (0.0, 0.0), 0, 0,
                         2 * MS)
    assert again.tau_nm is None and again.logs == ()
    assert ctl.counters.foreign_states == 2 and ctl.counters.rejected_states == 0
    assert not ctl.has_state and tick(ctl, (0.0, 0.5, 0.0), 3 * MS).tau_nm is not None
    figures = {'control_rate_hz': 0.0, 'ticks_in_window': 0, 'saturated_ticks': 0}
    assert ('foreign_states_total', '2') in ctl.statuses(figures)[0][3]
    # no valid state at all: the start-up warning says what came instead
    warning = diagnostics.no_state_warning('/joint_states', 6.0, 1, 0, 2)
    assert '2 received naming none of the controlled joints' in warning


def test_states_without_velocities_are_estimated_and_said_once():
    ctl = controller(state_rate_hz=500.0)
    logs = []
    for k in range(10):
        logs += tick(ctl, (0.0, 0.5 + 0.001 * k, 0.0), (k + 1) * MS, qdot=(),
                     stamp_ns=1_000_000_000 + 2 * MS * k).logs
    [line] = texts(logs, Severity.WARN)
    assert 'carry no velocities: estimating them from the positions and their stamps' in line
    assert '2 ms = one period at state_rate 500 Hz' in line
    assert 0.0 < ctl.last_qdot[1] <= 0.5 and ctl.last_qdot[0] == 0.0


def test_nan_velocities_of_ros2_control_are_estimated_and_said_once_by_joint():
    """joint_state_broadcaster's NaN for a joint without a velocity interface: estimated."""
    ctl = controller(state_rate_hz=500.0)
    logs = []
    for k in range(10):
        logs += tick(ctl, (0.0, 0.5 + 0.001 * k, 0.0), (k + 1) * MS,
                     qdot=(0.0, math.nan, math.nan), stamp_ns=1_000_000_000 + 2 * MS * k).logs
    [line] = texts(logs, Severity.WARN)
    assert line.startswith("joint_states carry NaN velocities for ['joint2', 'joint3'] "
                           "(ros2_control's joint_state_broadcaster publishes NaN where the "
                           'hardware has no velocity state interface): estimating them from '
                           'the positions and their stamps')
    assert 0.0 < ctl.last_qdot[1] <= 0.5 and ctl.last_qdot[0] == 0.0
    assert ctl.counters.rejected_states == 0


def test_an_encoders_count_is_estimated_on_its_window_and_said_so():
    """With position_resolution a count from rest reads 0, two in 16 states count / (8 h)."""
    count = 1e-4
    ctl = controller(position_resolution=(count,) * 3)
    logs = []
    for k in range(21):
        steps = 0 if k < 12 else 1 if k < 20 else 2
        logs += tick(ctl, (0.0, 0.5 + steps * count, 0.0), (k + 1) * MS, qdot=(),
                     stamp_ns=1_000_000_000 + MS * k).logs
        if k == 12:
            assert ctl.last_qdot[1] == 0.0  # one count: at rest, as far as the count tells
    [line] = texts(logs, Severity.WARN)
    assert 'on the longest window of up to 16 states that position_resolution allows' in line
    assert ctl.last_qdot[1] == pytest.approx(count / 8e-3) and ctl.last_qdot[0] == 0.0


def test_the_watchdog_trips_once_and_states_coming_back_say_so():
    ctl = controller()
    assert ctl.on_watchdog(10_000 * MS) is None  # no state yet: nothing to stop
    tick(ctl, (0.0, 0.5, 0.0), 100 * MS)
    assert ctl.on_watchdog(500 * MS) is None  # 0.4 s: within state_timeout
    zero = ctl.on_watchdog(700 * MS)
    assert zero.tau_nm == [0.0, 0.0, 0.0] and ctl.stopped
    [line] = texts(zero.logs, Severity.ERROR)
    assert line.startswith('no valid joint_states for 0.600 s (> state_timeout 0.5 s)'), line
    assert ctl.on_watchdog(800 * MS) is None  # once
    back = tick(ctl, (0.0, 0.5, 0.0), 900 * MS)
    assert texts(back.logs, Severity.INFO) == ['joint_states are back: commanding torque again']
    assert not ctl.stopped and back.tau_nm is not None


def test_no_state_since_start_warns_soon_then_slowly_and_never_after_a_state():
    start = 5_000 * MS
    ctl = controller(started_ns=start)
    assert NO_STATE_WARN_NS < 2_000 * MS < NO_STATE_REPEAT_NS
    assert ctl.no_state_yet(start + NO_STATE_WARN_NS - MS) is None
    first = start + NO_STATE_WARN_NS
    assert ctl.no_state_yet(first) == pytest.approx(NO_STATE_WARN_NS * 1e-9)
    assert ctl.no_state_yet(first + 50 * MS) is None  # throttled
    again = first + NO_STATE_REPEAT_NS
    assert ctl.no_state_yet(again - MS) is None
    assert ctl.no_state_yet(again) == pytest.approx((again - start) * 1e-9)
    tick(ctl, (0.0, 0.5, 0.0), again + MS)
    assert ctl.has_state and ctl.no_state_yet(again + 3 * NO_STATE_REPEAT_NS) is None


def test_the_no_state_warning_says_what_is_known():
    none = diagnostics.no_state_warning('/arm/joint_states', 1.8, 0, 0)
    assert none.startswith('no valid joint state on /arm/joint_states 1.8 s after start, '
                           '0 publishers on it: is the robot driver or simulator running')
    assert 'remap with -r joint_states:=' in none
    connecting = diagnostics.no_state_warning('/joint_states', 1.8, 1, 0)
    assert '1 publisher on it: none received yet (still connecting?)' in connecting
    silent = diagnostics.no_state_warning('/joint_states', 11.8, 1, 0)
    assert '1 publisher on it: none received (a QoS mismatch' in silent
    refused = diagnostics.no_state_warning('/joint_states', 1.8, 2, 40)
    assert '2 publishers on it: 40 received and rejected' in refused


def test_feedback_every_nth_tick_and_diagnostics_after_the_next_command():
    ctl = controller(divider=3)
    cmds = [tick(ctl, (0.0, 0.5, 0.0), k * MS) for k in range(1, 7)]
    assert [c.feedback is not None for c in cmds] == [False, False, True, False, False, True]
    measured = quat.from_rotation_matrix(cmds[2].out.R_tip_base)
    assert abs(sum(a * b for a, b in zip(cmds[2].feedback, measured))) == pytest.approx(1.0)
    assert not ctl.on_diagnostics_timer(6 * MS + DIAGNOSTICS_WAIT_NS // 2)  # states flow
    assert tick(ctl, (0.0, 0.5, 0.0), 7 * MS).diagnostics  # owed: after this command
    assert not tick(ctl, (0.0, 0.5, 0.0), 8 * MS).diagnostics
    assert ctl.on_diagnostics_timer(8 * MS + 2 * DIAGNOSTICS_WAIT_NS)  # states stopped: now


def test_the_statuses_report_the_loop_the_goal_and_the_stall():
    ctl = controller()
    figures = {'control_rate_hz': 0.0, 'ticks_in_window': 0, 'saturated_ticks': 0}
    waiting = ctl.statuses(figures)
    assert [s[0] for s in waiting] == ['control loop', 'goal', 'stall']
    assert waiting[0][1] == diagnostics.WARN and 'waiting for joint_states' in waiting[0][2]
    tick(ctl, (0.0, 0.5, 0.0), MS)
    loop, goal, stall = ctl.statuses(figures, ['2 publishers on /cmd: another controller'])
    assert loop[1] == diagnostics.WARN and '2 publishers on /cmd' in loop[2]
    assert 'holding the initial pose' in goal[2]
    assert ('goal_configuration_rad', '[0.0, 0.5, 0.0]') in goal[3]
    assert stall[1] == diagnostics.OK


def test_a_receiver_with_other_joints_stops_the_commands_until_it_agrees():
    """
    A receiver that applies the torques to its joints in another order: zeros once, then none.

    The ticks go on (the watchdog, the feedback); /diagnostics says why, as an ERROR.
    """
    assert diagnostics.command_order_problem(JOINTS, '/effort_controller', JOINTS) == ''
    swapped = diagnostics.command_order_problem(JOINTS, '/effort_controller',
                                                ['joint2', 'joint1', 'joint3'])
    assert swapped.startswith("/effort_controller applies the commands to joints ['joint2', "
                              "'joint1', 'joint3'], this controller computes them for "
                              "['joint1', 'joint2', 'joint3']: the same joints in another order")
    other = diagnostics.command_order_problem(JOINTS, '/sim', ['joint1', 'joint2', 'finger'])
    assert "other joints (without ['joint3'], with ['finger'])" in other
    ctl = controller()
    assert tick(ctl, (0.0, 0.5, 0.0), MS).tau_nm is not None
    stop = ctl.refuse_commands(swapped)
    assert stop.tau_nm == [0.0, 0.0, 0.0] and texts(stop.logs, Severity.ERROR) == [swapped]
    assert ctl.refuse_commands(swapped) is None  # the same problem: nothing more
    refused = tick(ctl, (0.0, 0.5, 0.0), 2 * MS)
    assert refused.tau_nm is None and refused.out is not None and ctl.has_state
    figures = {'control_rate_hz': 0.0, 'ticks_in_window': 0, 'saturated_ticks': 0}
    loop = ctl.statuses(figures)[0]
    assert loop[1] == diagnostics.ERROR and swapped in loop[2]
    again = ctl.refuse_commands(other)  # another problem: said, no second zero
    assert again.tau_nm is None and texts(again.logs, Severity.ERROR) == [other]
    [back] = texts(ctl.allow_commands(), Severity.INFO)
    assert 'commanding torque again' in back and ctl.allow_commands() == ()
    assert tick(ctl, (0.0, 0.5, 0.0), 3 * MS).tau_nm is not None
    assert ctl.statuses(figures)[0][1] == diagnostics.OK


def test_the_published_quaternion_keeps_its_hemisphere():
    ctl = controller(divider=1)
    ctl.on_goal(request(Goal(paper.Q_DESIRED)), 0)
    signs = []
    for k, q in enumerate(((3.1, 0.5, 0.0), (-3.1, 0.5, 0.0), (3.13, 0.5, 0.0))):
        signs.append(tick(ctl, q, (k + 1) * MS).feedback)
    for a, b in zip(signs, signs[1:]):  # about the same rotation: never the other sign
        assert sum(x * y for x, y in zip(a, b)) > 0.0


class StepRecorder(Regulator):
    """The wrist's regulator, recording the time step each tick is given."""

    def __init__(self) -> None:
        super().__init__(wrist_model(), cl.Task.ORIENTATION, GAINS)
        self.steps = []

    def update(self, q, qdot, dt_s=0.0):
        self.steps.append(dt_s)
        return super().update(q, qdot, dt_s)


def test_the_tick_interval_comes_from_the_state_stamps_or_else_their_arrival():
    recorder = StepRecorder()
    ctl = Controller(recorder, 0.5, 3)
    for k, stamp in enumerate((0, 5_000_000_000, 5_001_000_000, 5_001_000_000, 5_000_500_000,
                               5_002_500_000, 0, 0)):
        tick(ctl, (0.0, 0.5, 0.0), (k + 1) * MS, stamp_ns=stamp)
    # unstamped (the first), the first stamped, 1 ms, a repeat, older, 2 ms after the last,
    # unstamped (another clock: no step), then 1 ms after it by arrival
    assert recorder.steps == pytest.approx([0.0, 0.0, 1e-3, 0.0, 0.0, 2e-3, 0.0, 1e-3])


def test_a_stamped_stream_has_a_velocity_until_it_stops():
    checker = FakeChecker()
    ctl = controller(checker=checker)
    tick(ctl, (0.0, 0.5, 0.0), 0)
    goals = [turned(0.01 * k) for k in range(5)]
    taken = [ctl.on_goal(request(g, 100.0 + 0.01 * k), k * 10 * MS)
             for k, g in enumerate(goals)]
    assert taken[0].nu_desired_base is None  # the first of a stream is a fixed goal
    omega = taken[-1].nu_desired_base
    assert omega[2] == pytest.approx(1.0) and ctl.streaming  # 0.01 rad per 10 ms about z
    checker.verdicts = [(ctl.goal, '')]
    checker.qdot_star = {id(ctl.goal): [0.0, 0.0, 1.0]}
    ctl.take_goal_checks()
    assert ctl.regulator.goal_joint_velocity == (0.0, 0.0, 1.0)
    tick(ctl, (0.0, 0.5, 0.0), 60 * MS)  # within the hold
    assert ctl.regulator.goal_joint_velocity is not None
    tick(ctl, (0.0, 0.5, 0.0), 200 * MS)  # no goal for longer than the hold
    assert ctl.regulator.goal_joint_velocity is None and not ctl.streaming
    checker.verdicts = [(ctl.goal, '')]  # a late answer is not taken
    checker.qdot_star = {id(ctl.goal): [0.0, 0.0, 1.0]}
    ctl.take_goal_checks()
    assert ctl.regulator.goal_joint_velocity is None
    ctl.on_goal(request(turned(1.0)), 300 * MS)  # not stamped: fixed
    assert not ctl.streaming


class FakeChecker:
    """The goal-check worker's interface, answering what the test tells it to."""

    unavailable_reason = ''
    ready = True

    def __init__(self) -> None:
        self.submitted = []
        self.verdicts = []
        self.failure = None
        self.q_star = {}
        self.qdot_star = {}

    def submit(self, goal, q_measured, *rest) -> None:
        self.submitted.append((goal, q_measured, rest))

    def poll(self):
        verdicts, self.verdicts = self.verdicts, []
        return verdicts

    def take_failure(self):
        failure, self.failure = self.failure, None
        return failure

    def take_configuration(self, goal):
        return self.q_star.pop(id(goal), None)

    def take_configuration_velocity(self, goal):
        return self.qdot_star.pop(id(goal), None)


def test_the_goal_check_answers_the_goal_in_force_and_warns_once():
    checker = FakeChecker()
    ctl = controller(checker=checker)
    # The worker died before any goal: the failure is said, the goal-less verdict skipped.
    checker.failure = 'the goal-check worker exited'
    checker.verdicts = [(None, 'the goal-check worker exited')]
    logs = ctl.take_goal_checks()
    assert texts(logs, Severity.ERROR) == ['the goal-check worker exited; regulation goes on']
    assert len(logs) == 1
    tick(ctl, (0.0, 0.5, 0.0), MS)
    old, new = turned(0.2), turned(0.4)
    for k, goal in enumerate((old, new)):
        ctl.on_goal(request(goal), (k + 2) * MS)
    old, new = (s[0] for s in checker.submitted)  # the goals as the controller holds them
    assert new is ctl.goal
    assert checker.submitted[-1][1] == [0.0, 0.5, 0.0]  # searched from the measured joints
    q_star = (0.1, 0.6, 0.2)
    checker.q_star = {id(new): q_star}
    checker.verdicts = [(old, 'near a singularity'), (new, 'near a singularity')]
    [warning] = ctl.take_goal_checks()
    assert warning.severity == Severity.WARN and 'near a singularity' in warning.text
    assert ctl.goal_warning == 'near a singularity'
    assert ctl.regulator.goal_configuration == pytest.approx(q_star)
    checker.verdicts = [(new, 'near a singularity')]
    assert ctl.take_goal_checks() == ()  # the same warning again: said once


def test_a_repeated_goal_keeps_its_goal_configuration_and_is_checked_once():
    checker = FakeChecker()
    ctl = controller(checker=checker)
    tick(ctl, (0.0, 0.5, 0.0), MS)
    reply = ctl.on_goal(request(turned(0.3)), 2 * MS)
    assert reply.accepted and reply.new
    [(goal, _, _)] = checker.submitted
    checker.q_star = {id(goal): (0.1, 0.6, 0.2)}
    checker.verdicts = [(goal, '')]  # the worker's answer: no warning, and q*
    ctl.take_goal_checks()
    assert ctl.regulator.goal_configuration == pytest.approx((0.1, 0.6, 0.2))
    again = ctl.on_goal(request(turned(0.3)), 3 * MS)  # e.g. ros2 topic pub at 1 Hz
    assert again.accepted and not again.new
    assert ctl.goal is goal and len(checker.submitted) == 1
    assert ctl.regulator.goal_configuration == pytest.approx((0.1, 0.6, 0.2))


def test_the_payload_held_at_rest_is_identified_on_an_arm_that_shows_it():
    """The torque held at rest beyond g(q), fitted by a payload: its mass and its g(q) here."""
    from quat_jt_runtime.payload import Payload
    from robots import panda_model, PANDA_JOINTS, random_q
    import numpy as np
    model = panda_model()
    gains = cl.Gains.create('tanh', (50.0,) * 3 + (5.0,) * 3, (5.0,) * 7, (40.0,) * 3
                            + (4.0,) * 3, cl.Task.POSE, 7)
    ctl = Controller(Regulator(model, cl.Task.POSE, gains), 0.5, 3, started_ns=0)
    payload, why = ctl.identify_payload()
    assert payload is None and 'no joint state yet' in why
    q = random_q(model, np.random.default_rng(2)).tolist()
    ctl.on_state(PANDA_JOINTS, q, [0.0] * 7, 0, 0, MS // 2)  # held as the model has it
    payload, why = ctl.identify_payload()
    assert payload == Payload() and "the model's g(q) holds the arm here" in why
    ctl.regulator.set_goal(ctl.regulator.pose([x + 0.1 for x in q]))  # pushed, not a weight
    ctl.on_state(PANDA_JOINTS, q, [0.0] * 7, 0, 0, MS // 2)
    payload, why = ctl.identify_payload()
    assert payload is None and 'is not a weight at the tip' in why
    ctl.regulator.hold(q)
    carried = Payload.create(1.3, (0.02, -0.01, 0.08))
    ctl.regulator.set_payload(carried)  # the arm holds its pose with 1.3 kg in g(q) ...
    ctl.on_state(PANDA_JOINTS, q, [0.0] * 7, 0, 0, MS)
    ctl.regulator.set_payload(Payload())  # ... which the model then has no more
    payload, why = ctl.identify_payload()
    assert payload is not None and payload.mass_kg == pytest.approx(1.3, rel=1e-6), why
    Y = model.payload_regressor(q)  # the weight it gives here is the one held
    np.testing.assert_allclose(Y @ [payload.mass_kg, *(payload.mass_kg * c
                                                       for c in payload.com_m)],
                               Y @ [1.3, 0.026, -0.013, 0.104], atol=1e-9)
    assert why.startswith('identified at rest: payload 1.3 kg at [') and 'across gravity' in why
    # with a payload in force, its lever along gravity (which this pose does not show) kept
    in_force = Payload.create(0.4, (0.0, 0.05, 0.02))
    ctl.regulator.set_payload(carried)
    ctl.on_state(PANDA_JOINTS, q, [0.0] * 7, 0, 0, MS)
    ctl.regulator.set_payload(in_force)
    again, why = ctl.identify_payload()
    assert again is not None and again.mass_kg == pytest.approx(1.3, rel=1e-6), why
    _, R, _ = model.kinematics(q)
    up = np.array(R).T @ model.gravity_base_m_s2
    up /= np.linalg.norm(up)
    assert up @ again.com_m == pytest.approx(up @ np.array(in_force.com_m), abs=1e-9)
    np.testing.assert_allclose(Y @ [again.mass_kg, *(again.mass_kg * c for c in again.com_m)],
                               Y @ [1.3, 0.026, -0.013, 0.104], atol=1e-9)
    ctl.refuse_commands('another receiver')  # our torque no longer holds the arm
    payload, why = ctl.identify_payload()
    assert payload is None and 'no torque of ours holds the arm' in why
    ctl.allow_commands()
    ctl.on_state(PANDA_JOINTS, q, [0.3] + [0.0] * 6, 0, 0, 2 * MS)
    payload, why = ctl.identify_payload()
    assert payload is None and 'the arm is moving (0.3 rad/s' in why
    wrist = controller()
    tick(wrist, (0.1, 0.2, 0.3), MS)
    payload, why = wrist.identify_payload()
    assert payload is None and 'an arm of 3 joints shows too little' in why


def test_a_pose_gravity_asks_more_than_the_effort_limits_of_is_a_warning_naming_the_joints():
    """Where the arm cannot hold itself, the control loop's status says which joint, and why."""
    from quat_jt_runtime.payload import Payload
    ctl = controller()
    figures = {'control_rate_hz': 1000.0, 'ticks_in_window': 1000, 'saturated_ticks': 0}
    tick(ctl, (0.0, 0.5, 0.0), MS)
    level, message, _ = ctl.statuses(figures)[0][1:]
    assert 'cannot hold itself' not in message and level == diagnostics.OK
    ctl.regulator.set_payload(Payload(200.0, (0.3, 0.0, 0.0)))  # far more than it carries
    tick(ctl, (0.0, 0.5, 0.0), 2 * MS)
    level, message, _ = ctl.statuses(figures)[0][1:]
    g = ctl.regulator.model.gravity([0.0, 0.5, 0.0])
    over = [j for j, (t, e) in enumerate(zip(g, ctl.regulator.model.effort_limits))
            if abs(t) > e]
    assert over and level == diagnostics.WARN, (g, message)
    assert message.startswith('the arm cannot hold itself here: joint'), message
    for j in over:
        assert (f'joint{j + 1} needs {abs(g[j]):.3g} N m against gravity here, above its '
                f'effort limit {ctl.regulator.model.effort_limits[j]:g} N m') in message
    assert 'its command is clamped and it sags' in message
    unclamped = Regulator(ctl.regulator.model, cl.Task.ORIENTATION, GAINS, [math.inf] * 3)
    assert diagnostics.gravity_beyond_effort(unclamped, [0.0, 0.5, 0.0]) == []  # no limit
    # the drives hold the weight themselves: none of ours
    ctl.regulator.set_gains(cl.Gains.create('tanh', paper.KP, paper.KV, paper.LAMBDA,
                                            cl.Task.ORIENTATION, 3, gravity_compensation=False))
    assert 'cannot hold itself' not in ctl.statuses(figures)[0][2]
