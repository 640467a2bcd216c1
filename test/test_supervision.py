"""The controller's decisions around the law (quat_jt_controller.supervision), ROS-free."""
import math

import pytest
from quat_jt_controller import control_law as cl
from quat_jt_controller import diagnostics
from quat_jt_controller import paper
from quat_jt_controller import quaternion as quat
from quat_jt_controller.regulator import Goal, Regulator
from quat_jt_controller.supervision import (
    DIAGNOSTICS_WAIT_NS, NO_STATE_REPEAT_NS, NO_STATE_WARN_NS, Supervisor)
from robots import wrist_model

pytestmark = pytest.mark.unit

MS = 1_000_000  # ns


def supervisor(divider: int = 3) -> Supervisor:
    gains = cl.Gains.create('tanh', paper.KP, paper.KV, paper.LAMBDA, cl.Task.ORIENTATION, 3)
    return Supervisor(Regulator(wrist_model(), cl.Task.ORIENTATION, gains), 0.5, divider)


def turned(angle: float) -> Goal:
    s = math.sin(0.5 * angle)
    return Goal(quat.multiply((math.cos(0.5 * angle), 0.0, 0.0, s), paper.Q_DESIRED))


def test_the_first_state_holds_its_pose_until_a_goal():
    sup = supervisor()
    held = sup.before_tick([0.1, 0.5, 0.2], 1 * MS)
    assert held is not None and sup.goal_source == 'hold'
    assert sup.regulator.goal_configuration == (0.1, 0.5, 0.2)
    assert sup.before_tick([0.3, 0.5, 0.2], 2 * MS) is None  # held once
    assert sup.on_goal(Goal(paper.Q_DESIRED), 0.0, 3 * MS).new
    assert sup.goal_source == 'target_pose'
    assert not sup.on_goal(Goal(paper.Q_DESIRED), 0.0, 4 * MS).new  # the same goal again


def test_the_watchdog_trips_once_and_states_coming_back_say_so():
    sup = supervisor()
    assert sup.on_silence(10_000 * MS) is None  # no state yet: nothing to stop
    sup.before_tick([0.0, 0.5, 0.0], 0)
    sup.after_tick(100 * MS)
    assert sup.on_silence(500 * MS) is None  # 0.4 s: within state_timeout
    assert sup.on_silence(700 * MS) == pytest.approx(0.6)
    assert sup.stopped and sup.on_silence(800 * MS) is None  # once
    resumed, _, _ = sup.after_tick(900 * MS)
    assert resumed and not sup.stopped


def test_no_state_since_start_warns_soon_then_slowly_and_never_after_a_state():
    gains = cl.Gains.create('tanh', paper.KP, paper.KV, paper.LAMBDA, cl.Task.ORIENTATION, 3)
    start = 5_000 * MS
    sup = Supervisor(Regulator(wrist_model(), cl.Task.ORIENTATION, gains), 0.5, 3,
                     started_ns=start)
    assert NO_STATE_WARN_NS < 2_000 * MS < NO_STATE_REPEAT_NS
    assert sup.no_state_yet(start + NO_STATE_WARN_NS - MS) is None
    first = start + NO_STATE_WARN_NS
    assert sup.no_state_yet(first) == pytest.approx(NO_STATE_WARN_NS * 1e-9)
    assert sup.no_state_yet(first + 50 * MS) is None  # throttled
    again = first + NO_STATE_REPEAT_NS
    assert sup.no_state_yet(again - MS) is None
    assert sup.no_state_yet(again) == pytest.approx((again - start) * 1e-9)
    sup.before_tick([0.0, 0.5, 0.0], again + MS)
    sup.after_tick(again + MS)
    assert sup.no_state_yet(again + 3 * NO_STATE_REPEAT_NS) is None  # states have come


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
    sup = supervisor(divider=3)
    sup.before_tick([0.0, 0.5, 0.0], 0)
    feedback = [sup.after_tick(k * MS)[1] for k in range(1, 7)]
    assert feedback == [False, False, True, False, False, True]
    assert not sup.on_diagnostics_timer(6 * MS + DIAGNOSTICS_WAIT_NS // 2)  # states flow
    assert sup.after_tick(7 * MS)[2]  # owed: published after this command
    assert not sup.after_tick(8 * MS)[2]
    assert sup.on_diagnostics_timer(8 * MS + 2 * DIAGNOSTICS_WAIT_NS)  # states stopped: now


def test_a_stamped_stream_has_a_velocity_until_it_stops():
    sup = supervisor()
    sup.before_tick([0.0, 0.5, 0.0], 0)
    taken = [sup.on_goal(turned(0.01 * k), 100.0 + 0.01 * k, k * 10 * MS) for k in range(5)]
    assert taken[0].nu_desired_base is None  # the first of a stream is a fixed goal
    omega = taken[-1].nu_desired_base
    assert omega[2] == pytest.approx(1.0) and sup.streaming  # 0.01 rad per 10 ms about z
    assert sup.on_goal_velocity([0.0, 0.0, 1.0])
    assert sup.regulator.goal_joint_velocity == (0.0, 0.0, 1.0)
    assert sup.before_tick([0.0, 0.5, 0.0], 60 * MS) is None  # within the hold
    assert sup.regulator.goal_joint_velocity is not None
    sup.before_tick([0.0, 0.5, 0.0], 200 * MS)  # no goal for longer than the hold
    assert sup.regulator.goal_joint_velocity is None and not sup.streaming
    assert not sup.on_goal_velocity([0.0, 0.0, 1.0])  # a late answer is not taken
    sup.on_goal(turned(1.0), 0.0, 300 * MS)  # not stamped: fixed
    assert not sup.streaming


def test_the_published_quaternion_keeps_its_hemisphere():
    sup = supervisor()
    first = sup.published_quaternion(quat.to_rotation_matrix(paper.Q_DESIRED))
    flipped = tuple(-c for c in paper.Q_DESIRED)  # the same rotation, the other sign
    again = sup.published_quaternion(quat.to_rotation_matrix(flipped))
    assert sum(a * b for a, b in zip(first, again)) > 0.0


def test_the_tick_interval_comes_from_the_state_stamps():
    sup = supervisor()
    assert sup.tick_interval_s(0) == 0.0  # unstamped
    assert sup.tick_interval_s(5_000_000_000) == 0.0  # the first stamped state
    assert sup.tick_interval_s(5_001_000_000) == pytest.approx(1e-3)
    assert sup.tick_interval_s(5_001_000_000) == 0.0  # a repeat: no time passed
    assert sup.tick_interval_s(5_000_500_000) == 0.0  # older: no time passes backwards
    assert sup.tick_interval_s(5_002_500_000) == pytest.approx(2e-3)


class FakeChecker:
    """The goal-check worker's interface, answering what the test tells it to."""

    def __init__(self) -> None:
        self.submitted = []
        self.verdicts = []
        self.failure = None
        self.q_star = {}

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
        return None


def test_the_goal_check_answers_the_goal_in_force_and_warns_once():
    gains = cl.Gains.create('tanh', paper.KP, paper.KV, paper.LAMBDA, cl.Task.ORIENTATION, 3)
    checker = FakeChecker()
    sup = Supervisor(Regulator(wrist_model(), cl.Task.ORIENTATION, gains), 0.5, 3, checker)
    # The worker died before any goal: the failure is given, the goal-less verdict skipped.
    checker.failure = 'the goal-check worker exited'
    checker.verdicts = [(None, 'the goal-check worker exited')]
    assert sup.take_checks() == ('the goal-check worker exited', [])
    old, new = turned(0.2), turned(0.4)
    for goal in (old, new):
        sup.check_goal(goal, None, [0.0, 0.5, 0.0])
        sup.on_goal(goal, 0.0, 0)
    assert [s[0] for s in checker.submitted] == [old, new]
    assert checker.submitted[-1][1] == [0.0, 0.5, 0.0]  # searched from the measured joints
    q_star = (0.1, 0.6, 0.2)
    checker.q_star = {id(new): q_star}
    checker.verdicts = [(old, 'near a singularity'), (new, 'near a singularity')]
    failure, warnings = sup.take_checks()
    assert failure is None and len(warnings) == 1 and 'near a singularity' in warnings[0]
    assert sup.goal_warning == 'near a singularity'
    assert sup.regulator.goal_configuration == pytest.approx(q_star)
    checker.verdicts = [(new, 'near a singularity')]
    assert sup.take_checks() == (None, [])  # the same warning again: said once
