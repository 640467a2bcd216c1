"""
Small ROS-free pieces the nodes are made of.

Loop statistics, log throttling, joint layout, the simulator's live config, the goal-check
worker and the workers' input.
"""
import math
import os
import time

import pytest
from quat_jt_controller import paper
from quat_jt_controller.control_law import Task
from quat_jt_controller.goal_check import check_goal, GoalCheckWorker, ModelSpec
from quat_jt_runtime.joints import ForeignState, movable_joints, StateLayout
from quat_jt_runtime.loop_stats import LoopStats, Ring, TickStats
from quat_jt_runtime.resources import default_urdf_xml
from quat_jt_runtime.throttle import cause, Throttle
from quat_jt_runtime.worker import LineWriter
from robots import wrist_model
from wrist_sim.config import SimConfig
from wrist_sim.simulator import SimulatorError

pytestmark = pytest.mark.unit


def test_loop_stats_summary():
    stats = LoopStats(capacity=100)
    for k in range(250):
        stats.record_step(k * 1e-3, 50e-6, 1e-6, fresh=k % 2 == 0)
        stats.record_latency(300e-6)
    stats.missed_deadlines = 2
    out = stats.summary()
    assert out['steps'] == 250 and out['fresh_steps'] == 125
    assert out['window_rate_hz'] == pytest.approx(1000.0)
    assert out['step_compute_us_p50'] == pytest.approx(50.0)
    assert out['cmd_latency_us_p99'] == pytest.approx(300.0)
    assert out['window_fresh_fraction'] == pytest.approx(0.5)
    assert out['missed_deadlines'] == 2


def test_tick_stats_window_then_reset():
    stats = TickStats(capacity=16)
    for k in range(40):  # wraps the ring; the window keeps the last 16
        t0 = 1_000_000 * k
        stats.record(t0, t0 + 20_000, t0 + 100_000, 250.0, saturated=k < 4)
    w = stats.window(0.04)
    assert w['ticks_in_window'] == 40 and w['control_rate_hz'] == pytest.approx(1000.0)
    assert w['compute_us_p50'] == pytest.approx(20.0)
    assert w['publish_us_p99'] == pytest.approx(80.0)
    assert w['period_mean_us'] == pytest.approx(1000.0)
    assert w['state_age_us_p50'] == 250.0 and w['saturated_ticks'] == 4
    after = stats.window(1.0)
    assert after['ticks_in_window'] == 0 and math.isnan(after['compute_us_p50'])
    assert after['total_ticks'] == 40


def test_ring_keeps_the_last_samples_and_returns_the_finite_ones_sorted():
    ring = Ring(4)
    for x in (5.0, math.nan, 1.0, math.inf, 3.0, 2.0):  # the first two fall out of the ring
        ring.push(x)
    assert ring.values().tolist() == [1.0, 2.0, 3.0] and ring.count == 6
    ring.clear()
    assert ring.values().tolist() == []


def test_loop_stats_count_late_publications_in_the_window():
    stats = LoopStats(capacity=100)
    for k in range(50):
        stats.record_step(k * 1e-3, 50e-6, 0.7e-3 if k in (10, 20) else 1e-6, fresh=True)
    out = stats.summary()
    assert out['window_late_steps'] == 2 and out['lateness_us_max'] == pytest.approx(700.0)


def test_throttle_passes_once_per_period_and_cause_and_counts_the_rest():
    now = [0.0]
    throttle = Throttle(1.0, clock=lambda: now[0])
    key = cause('quaternion (x, y, z, w) = (nan, 0.0, 0.0, 1.0) has a non-finite component')
    assert key == cause('quaternion (x, y, z, w) = (0.5, inf, -2e-3, 1.0) has a non-finite '
                        'component')
    assert throttle(key) == 0
    assert [throttle(key) for _ in range(9)] == [None] * 9
    assert throttle('another cause') == 0
    now[0] = 1.5
    assert throttle(key) == 9


def test_state_layout_maps_names_and_rejects_bad_states():
    layout = StateLayout(('joint1', 'joint2', 'joint3'))
    q, v = layout.extract(['joint3', 'gripper', 'joint1', 'joint2'], [3.0, 9.0, 1.0, 2.0],
                          [0.3, 9.0, 0.1, 0.2])
    assert (q, v) == ([1.0, 2.0, 3.0], [0.1, 0.2, 0.3])
    for names, pos, vel, words in (
            (['joint1', 'joint1', 'joint2', 'joint3'], [0.0] * 4, [0.0] * 4, 'repeat'),
            (['joint1', 'joint3'], [0.0] * 2, [0.0] * 2, "missing controlled joint(s) ['joint2']"),
            (['joint1', 'joint2', 'joint3'], [0.0] * 3, [], '3 names but 3 positions and 0'),
            (['joint1', 'joint2', 'joint3'], [0.0, math.nan, 0.0], [0.0] * 3,
             'non-finite position'),
            (['joint1', 'joint2', 'joint3'], [0.0] * 3, [0.0, math.nan, 0.0],
             'non-finite velocity')):
        with pytest.raises(ValueError) as exc:
            layout.extract(names, pos, vel)
        assert words in str(exc.value)
    # a state naming none of the controlled joints is another publisher's (a gripper's)
    with pytest.raises(ForeignState, match=r"names none of the controlled joints: \['finger'\]"):
        layout.extract(['finger'], [0.0], [0.0])
    # velocities not required: NaN (not measured) passes for the caller to estimate, Inf not
    q, v = layout.extract(['joint1', 'joint2', 'joint3'], [0.0] * 3, [0.1, math.nan, 0.3],
                          velocity_required=False)
    assert v[0] == 0.1 and math.isnan(v[1]) and v[2] == 0.3
    with pytest.raises(ValueError, match='Inf is refused'):
        layout.extract(['joint1', 'joint2', 'joint3'], [0.0] * 3, [0.1, -math.inf, 0.3],
                       velocity_required=False)


def test_movable_joints_one_definition():
    assert movable_joints(default_urdf_xml()) == ['joint1', 'joint2', 'joint3']
    assert list(wrist_model().joint_names) == movable_joints(default_urdf_xml())
    with pytest.raises(ValueError, match='not valid XML'):
        movable_joints('<robot')


def test_sim_config_validates_and_is_immutable():
    values = {'initial_positions': [0.0, 0.3, 0.0], 'viscous_friction': [0.0] * 3,
              'coulomb_friction': [2.0, 0.8, 0.5], 'command_timeout': 0.1,
              'lockstep_timeout': 0.05, 'max_real_time_factor': 0.0}
    config = SimConfig.create(values, 3)
    assert config.command_timeout_ns == 100_000_000 and config.coulomb_nm == (2.0, 0.8, 0.5)
    with pytest.raises(AttributeError):
        config.coulomb_nm = (0.0, 0.0, 0.0)
    for name, bad, words in (('coulomb_friction', [1.0, -1.0, 0.0], 'must be >= 0'),
                             ('initial_positions', [0.0, 0.0], 'expected 3 values'),
                             ('viscous_friction', [0.0, math.inf, 0.0], 'finite'),
                             ('command_timeout', math.nan, 'command_timeout_s')):
        with pytest.raises(SimulatorError, match=words):
            SimConfig.create({**values, name: bad}, 3)


def test_goal_check_is_deterministic_and_bounded_by_starts():
    """The paper's goal from a far start: the same verdict every time (no wall-time budget)."""
    model = wrist_model()
    far = [3.1252, -0.4917, -1.1201]
    verdicts = {check_goal(model, far, paper.Q_DESIRED, (0, 0, 0), Task.ORIENTATION)
                for _ in range(3)}
    assert verdicts == {''}


def test_lines_longer_than_a_pipe_holds_are_queued_without_waiting_for_the_reader():
    """A whole robot's URDF to a worker that has not read yet: put returns, the lines follow."""
    read_fd, write_fd = os.pipe()
    writer = LineWriter(os.fdopen(write_fd, 'w'), 'test_writer')
    long_line = 'u' * (1 << 20)  # 1 MiB: 16 times a pipe's buffer
    writer.put(long_line)  # nobody reads yet: returns at once all the same
    writer.put('{"id": 1}')
    writer.close()
    with os.fdopen(read_fd) as reader:
        assert reader.read() == long_line + '\n{"id": 1}\n'  # in order, then closed
    assert writer.join(timeout_s=60.0)


def test_a_launcher_starts_workers_hands_their_pipes_over_and_reports_their_exits():
    """What a node's Launcher process starts: pipes as a Popen's, exits as its returncode."""
    import json
    import os
    import queue
    import signal
    import subprocess
    from quat_jt_runtime.worker import Launcher
    started: queue.SimpleQueue = queue.SimpleQueue()
    launcher = Launcher()
    try:
        for _ in range(2):
            launcher.start('quat_jt_controller.redesign', lambda *got: started.put(got))
        first, error = started.get(timeout=30.0)
        second, _ = started.get(timeout=30.0)
        assert error == '' and first.pid != second.pid and os.getpid() not in (first.pid,
                                                                               second.pid)
        first.stdin.write(json.dumps({'urdf_xml': '<robot name="x"/>'}) + '\n')
        first.stdin.write(json.dumps({'armature': [0.1], 'values': {}}) + '\n')
        assert json.loads(first.stdout.readline()) == {'ready': True}
        assert 'error' in json.loads(first.stdout.readline())  # the worker answered
        first.kill()
        assert first.wait(timeout=30.0) == -9 and first.poll() == -9
        second.stdin.close()  # a worker ends when its input closes
        assert second.wait(timeout=30.0) == 0
        launcher.start('quat_jt_controller.redesign', lambda *got: started.put(got))
        third, _ = started.get(timeout=30.0)
        with pytest.raises(subprocess.TimeoutExpired):
            third.wait(timeout=0.05)  # running: its exit not told
        os.kill(launcher.pid, signal.SIGKILL)  # the launcher gone: a start says so
        launcher.start('quat_jt_controller.redesign', lambda *got: started.put(got))
        none, reason = started.get(timeout=30.0)
        assert none is None and 'worker launcher' in reason, reason
        assert third.wait(timeout=30.0) is None  # its exit can no longer be told
        third.stdin.close()
    finally:
        launcher.close()


@pytest.mark.parametrize('nice', [0, 7])
def test_a_launcher_starts_its_workers_niced_as_told(nice):
    """Each worker runs ``worker_nice`` more niced than the node (0 on simulated time)."""
    import os
    import queue
    from quat_jt_runtime.worker import Launcher
    started: queue.SimpleQueue = queue.SimpleQueue()
    launcher = Launcher(nice)
    try:
        launcher.start('quat_jt_controller.redesign', lambda *got: started.put(got))
        worker, error = started.get(timeout=30.0)
        assert error == ''
        assert (os.getpriority(os.PRIO_PROCESS, worker.pid)
                == min(19, os.getpriority(os.PRIO_PROCESS, 0) + nice))
        worker.stdin.close()
        assert worker.wait(timeout=30.0) == 0
    finally:
        launcher.close()
    with pytest.raises(ValueError, match='worker_nice must be 0 to 19, got 20'):
        Launcher(20)


def test_goal_check_worker_checks_the_newest_goal_of_a_flood():
    model = wrist_model()
    worker = GoalCheckWorker(ModelSpec(default_urdf_xml(), 'base_link', 'tool0',
                                       model.joint_names, Task.ORIENTATION))
    try:
        singular = (math.cos(0.4), 0.0, 0.0, math.sin(0.4))  # Rz(0.8): only q2 = 0 reaches it
        worker.submit('paper', [0.0, 0.0, 0.0], paper.Q_DESIRED, (0, 0, 0))
        for k in range(200):
            worker.submit(k, [0.5, 0.5, 0.5], singular, (0, 0, 0))
        verdicts = []
        deadline = time.monotonic() + 30.0
        while worker.busy and time.monotonic() < deadline:
            verdicts += worker.poll()
            time.sleep(0.01)
        assert not worker.busy
        keys = [k for k, _ in verdicts]
        assert keys[0] == 'paper' and keys[-1] == 199 and len(keys) <= 3, keys
        assert verdicts[0][1] == '' and 'singular' in verdicts[-1][1]
    finally:
        worker.close()


def test_goal_check_worker_that_dies_says_so_once_and_restarts_after_its_back_off(monkeypatch):
    """
    Killed mid-check: one failure, unavailable until the back-off ends, then the check again.

    The new worker is the launcher's: the node's process starts none (a ``Popen`` there would
    hold its loop up).
    """
    import os
    import signal
    import subprocess
    from quat_jt_runtime.worker import RESTART_BACKOFF_S
    now = [0.0]
    model = wrist_model()
    worker = GoalCheckWorker(ModelSpec(default_urdf_xml(), 'base_link', 'tool0',
                                       model.joint_names, Task.ORIENTATION),
                             clock=lambda: now[0])
    try:
        assert worker.available and worker.unavailable_reason == ''
        deadline = time.monotonic() + 30.0
        while worker.pid is None and time.monotonic() < deadline:  # the launcher starts it
            assert worker.poll() == []
            time.sleep(0.01)
        first_pid = worker.pid
        os.kill(first_pid, signal.SIGKILL)
        worker.submit('paper', [0.0, 0.0, 0.0], paper.Q_DESIRED, (0, 0, 0))
        while worker.available and time.monotonic() < deadline:
            assert worker.poll() == []
            time.sleep(0.01)
        failure = worker.take_failure()
        assert 'exited (exit code -9)' in failure and f'{RESTART_BACKOFF_S[0]:g} s' in failure
        assert worker.take_failure() is None  # said once
        assert 'restarting in 1.0 s' in worker.unavailable_reason
        assert worker.poll() == [] and not worker.available and worker.restarts == 0
        now[0] += RESTART_BACKOFF_S[0]
        verdicts = []
        with monkeypatch.context() as patched:  # the node itself starts no process to restart
            patched.setattr(subprocess, 'Popen', forbidden_popen)
            while not verdicts and time.monotonic() < deadline:
                verdicts += worker.poll()
                time.sleep(0.01)
        assert worker.restarts == 1 and worker.available
        assert verdicts == [('paper', '')]  # the goal that waited is checked by the new one
        assert worker.pid not in (None, first_pid)
        with pytest.raises(ChildProcessError):  # the launcher's child, not this process's
            os.waitpid(worker.pid, os.WNOHANG)
    finally:
        worker.close()


def forbidden_popen(*args, **kwargs):
    raise AssertionError('a process started from the node while its loop runs')


def test_goal_check_unavailability_is_a_diagnostics_warning():
    from quat_jt_controller import diagnostics
    level, message, values = diagnostics.goal_status(
        'hold', None, '', None, None, False, diagnostics.Counters(),
        'the goal-check worker exited (exit code -9); restarting in 0.6 s')
    assert level == diagnostics.WARN and 'goal checks unavailable' in message
    assert ('goal_check', 'unavailable') in values
    level, _, values = diagnostics.goal_status('hold', None, '', None, None, False,
                                               diagnostics.Counters())
    assert level == diagnostics.OK and ('goal_check', 'available') in values


def test_fresh_command_figures_find_the_lowest_window_and_the_largest_gap():
    import numpy as np
    from quat_jt_runtime.loop_stats import fresh_command_figures
    t = np.arange(2000) * 1e-3  # 2 s at 1 kHz
    fresh = np.ones(2000, dtype=bool)
    fresh[600:640] = False  # 40 stale steps in the third window
    figures = fresh_command_figures(t[::-1].copy(), fresh[::-1].copy())  # any order
    assert figures['fresh_rate_hz_min'] == pytest.approx((250 - 40) / 0.25)
    assert figures['fresh_gap_ms_max'] == pytest.approx(41.0)


def test_goal_check_worker_says_when_it_is_ready():
    """The worker answers checks once it has built its model: 'starting' until then."""
    from quat_jt_controller import diagnostics
    model = wrist_model()
    worker = GoalCheckWorker(ModelSpec(default_urdf_xml(), 'base_link', 'tool0',
                                       model.joint_names, Task.ORIENTATION))
    try:
        assert not worker.ready
        _, _, values = diagnostics.goal_status('hold', None, '', None, None, False,
                                               diagnostics.Counters(), '', worker.ready)
        assert ('goal_check', 'starting') in values
        deadline = time.monotonic() + 30.0
        while not worker.ready and time.monotonic() < deadline:
            assert worker.poll() == []
            time.sleep(0.01)
        assert worker.ready
    finally:
        worker.close()


def test_every_unusable_value_error_has_one_base_class():
    """A caller can catch them all at once (QuatJtError, a ValueError) or each by its kind."""
    from quat_jt_controller.control_law import GainsError
    from quat_jt_runtime.errors import QuatJtError
    from quat_jt_controller.model import ModelError
    from quat_jt_controller.shaping import ShapingError
    for kind in (GainsError, ModelError, ShapingError, SimulatorError):
        assert issubclass(kind, QuatJtError) and issubclass(kind, ValueError), kind
    with pytest.raises(QuatJtError, match='goal_velocity_gain'):
        from quat_jt_controller.shaping import Shaping
        Shaping.create(3, goal_velocity_gain=2.0)


def test_the_goal_status_says_when_the_goal_configuration_term_is_off_or_in_a_band():
    from quat_jt_controller import diagnostics
    Counters = diagnostics.Counters
    none = diagnostics.ConfigurationState(True, None, ())
    _, message, values = diagnostics.goal_status('target_pose', None, '', None, None, False,
                                                 Counters(), configuration=none)
    assert 'goal-configuration term is off for this goal' in message
    assert ('goal_configuration_rad', '') in values
    banded = diagnostics.ConfigurationState(True, (0.1, 2.5, 0.0), ('joint2',), (0.5, 0.0, 0.1))
    _, message, values = diagnostics.goal_status('target_pose', None, '', None, None, False,
                                                 Counters(), configuration=banded)
    assert 'joint-limit band of joint2: the band ends there' in message
    assert ('goal_configuration_in_band', 'joint2') in values
    assert ('learned_friction_nm', '[0.5, 0.0, 0.1]') in values
    _, message, _ = diagnostics.goal_status('hold', None, '', None, None, False, Counters(),
                                            configuration=none)
    assert 'goal-configuration' not in message  # holding: q* is the held pose


def test_the_state_check_names_the_problem_and_tells_a_stale_stamp():
    from quat_jt_runtime.joints import StaleState, StateCheck
    check = StateCheck(('joint1', 'joint2'), max_age_s=0.5)
    now_ns = 10_000_000_000
    q, qdot = check(['joint2', 'joint1'], [2.0, 1.0], [0.2, 0.1], now_ns - 1_000_000, now_ns)
    assert (q, qdot) == ([1.0, 2.0], [0.1, 0.2])  # in the controlled joints' order
    with pytest.raises(StaleState, match='ago'):
        check(['joint1', 'joint2'], [1.0, 2.0], [0.0, 0.0], now_ns - 2_000_000_000, now_ns)
    with pytest.raises(ValueError, match='missing') as caught:
        check(['joint1'], [1.0], [0.0], now_ns, now_ns)
    assert not isinstance(caught.value, StaleState)


def test_a_throttled_line_says_how_many_it_stands_for():
    now = [0.0]
    throttle = Throttle(1.0, clock=lambda: now[0])
    assert throttle.line('k', 'bad') == 'bad'
    assert throttle.line('k', 'bad') is None
    assert throttle.line('k', 'bad') is None
    now[0] = 1.5
    assert throttle.line('k', 'bad', ' ({} more)') == 'bad (2 more)'
