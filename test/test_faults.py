"""
Faults, over real DDS: killed, stopped and interrupted processes, floods, resets, twins.

Each test runs ``wrist_sim_node`` and ``controller_node`` as processes (the package's config
files, no friction) on a private loopback graph of its own, and asserts the documented safe
behaviour. Every wait is a condition with a deadline; the whole module takes about a minute.
"""
import math
import os
from pathlib import Path
import random
import re
import signal
import subprocess
import time
from typing import Callable

from cpus import thread_policies
from experiments import local_ros
from geometry_msgs.msg import PoseStamped
from process_harness import alive, call_service, descendants_of, ProcessHarnessMixin
import pytest
from quat_jt_controller import paper
from quat_jt_controller import quaternion as quat
from quat_jt_runtime.resources import share_path
from rcl_interfaces.msg import Parameter as ParameterMsg, ParameterType
import rclpy
from rclpy.experimental import EventsExecutor
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import Trigger

pytestmark = pytest.mark.dds

SIM_PARAMS = {'coulomb_friction': [0.0] * 3}
CONFIGS = {'wrist_sim_node': ('config/wrist_sim.yaml',),
           'controller_node': ('config/wrist_controller.yaml',),
           'composed': ('config/wrist_sim.yaml', 'config/wrist_controller.yaml')}


class Pair(ProcessHarnessMixin):
    """The two nodes on their own domain, and a probe that watches states and commands."""

    def __init__(self, work_dir: Path) -> None:
        self.work_dir = work_dir
        self.env = local_ros.isolated_env(work_dir, random.randint(101, 200))
        self.procs: dict[str, subprocess.Popen] = {}
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=int(self.env['ROS_DOMAIN_ID']))
        self.node = rclpy.create_node('fault_probe', context=self.context)
        self.executor = EventsExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.states: list[JointState] = []
        self.commands: list[tuple[float, list[float]]] = []
        # Deep queues: on a loaded host this process may take its samples a second late, and
        # a sample dropped here (the one state at q(0) = 0 after a reset, say) is a false fail.
        self.node.create_subscription(JointState, 'joint_states', self._on_state, 1000)
        self.node.create_subscription(Float64MultiArray, 'effort_controller/commands',
                                      lambda m: self.commands.append(
                                          (time.monotonic(), list(m.data))), 1000)
        self.goal_pub = self.node.create_publisher(
            PoseStamped, 'quat_jt_controller/target_pose', 100)
        self.reset = self.node.create_client(Trigger, 'wrist_sim/reset')

    def _on_state(self, msg: JointState) -> None:
        self.states.append(msg)
        del self.states[:-5000]  # the last 5 s

    def start(self, executable: str, log_name: str = '', **params) -> subprocess.Popen:
        name = log_name or executable
        params = {**(SIM_PARAMS if executable != 'controller_node' else {}), **params}
        self.procs[name] = local_ros.spawn_node(
            executable, self.env, self.work_dir, params=params, name=name,
            params_files=tuple(share_path(f) for f in CONFIGS[executable]))
        return self.procs[name]

    def log(self, name: str) -> str:
        path = self.work_dir / f'{name}.log'
        return path.read_text(errors='replace') if path.exists() else ''

    def logs(self) -> str:
        return '\n'.join(f'--- {n}.log ---\n{self.log(n)[-4000:]}' for n in self.procs)

    def spin_until(self, condition: Callable[[], bool], timeout: float, what: str) -> None:
        """Wait for ``condition``; unlike the mixin's, a node that exits is no failure here."""
        deadline = time.monotonic() + timeout
        while not condition():
            if time.monotonic() > deadline:
                pytest.fail(f'timed out after {timeout} s waiting for {what}\n{self.logs()}')
            self.executor.spin_once(timeout_sec=0.02)

    def commands_flow(self, since: float, count: int = 50) -> Callable[[], bool]:
        return lambda: sum(1 for t, _ in self.commands if t > since) >= count

    def running(self, controller: str = '', timeout: float = 60.0) -> None:
        """
        Wait until states flow and the controller answers them.

        With ``controller`` (a log name), also until that process has taken its first state, so
        the commands counted are its own, however slowly it started.
        """
        if controller:
            wait_log(self, controller, 'first joint state', timeout)
        now = time.monotonic()
        self.spin_until(lambda: len(self.states) > 50 and self.commands_flow(now)(), timeout,
                        'states and commands')

    def q(self) -> list[float]:
        m = self.states[-1]
        return [m.position[list(m.name).index(j)] for j in ('joint1', 'joint2', 'joint3')]

    def error_norm(self) -> float:
        from quat_jt_controller.model import RobotModel
        from quat_jt_runtime.resources import default_urdf_xml
        if not hasattr(self, '_model'):
            self._model = RobotModel(default_urdf_xml(), 'base_link', 'tool0')
        _, R = self._model.forward_kinematics(self.q())
        _, e = quat.orientation_error(quat.from_rotation_matrix(R), paper.Q_DESIRED)
        return math.sqrt(sum(x * x for x in e))

    def send_paper_goal(self) -> None:
        goal = PoseStamped()
        goal.header.frame_id = 'base_link'
        o = goal.pose.orientation
        o.x, o.y, o.z, o.w = quat.to_xyzw(paper.Q_DESIRED)
        self.spin_until(lambda: self.goal_pub.get_subscription_count() > 0, 10.0, 'goal sub')
        self.goal_pub.publish(goal)


@pytest.fixture
def pair(tmp_path):
    p = Pair(tmp_path)
    yield p
    p.close()


def wait_log(pair: 'Pair', name: str, pattern: str, timeout: float = 10.0) -> None:
    pair.spin_until(lambda: re.search(pattern, pair.log(name)), timeout,
                    f'{pattern!r} in {name}.log')


def test_sigint_with_states_flowing_exits_cleanly_every_time(pair):
    """Ctrl-C mid-loop: exit code 0, no publish on a dead context, the sim's stats logged."""
    pair.start('wrist_sim_node')
    for k in range(3):
        ctrl = pair.start('controller_node', f'controller_{k}')
        pair.running(f'controller_{k}')
        assert local_ros.stop_node(ctrl, timeout=10.0) == 0, pair.logs()
        text = pair.log(f'controller_{k}')
        assert 'context is invalid' not in text and 'Traceback' not in text, text[-3000:]
    sim = pair.procs['wrist_sim_node']
    assert local_ros.stop_node(sim, timeout=10.0) == 0, pair.logs()
    text = pair.log('wrist_sim_node')
    assert ']: stats {' in text, text[-3000:]
    assert 'Failed to publish' not in text and 'Traceback' not in text, text[-3000:]


def test_kill9_of_the_controller_zeroes_the_torque_and_a_restart_recovers(pair):
    pair.start('wrist_sim_node')
    ctrl = pair.start('controller_node')
    pair.running()
    pair.spin_until(lambda: len(descendants_of(ctrl.pid)) == 3, 10.0,
                    'the worker launcher, the goal-check and design workers')
    workers = descendants_of(ctrl.pid)
    ctrl.kill()
    ctrl.wait()
    wait_log(pair, 'wrist_sim_node', r'no command for [0-9.]+ s .*torque set to zero')
    # The launcher, the goal-check and design workers do not outlive their controller.
    pair.spin_until(lambda: not any(alive(w) for w in workers), 10.0, 'the workers to exit')
    restarted = time.monotonic()
    pair.start('controller_node', 'controller_restarted')
    pair.spin_until(pair.commands_flow(restarted), 30.0, 'commands from the new controller')
    wait_log(pair, 'wrist_sim_node', 'commands are back')


def test_kill9_of_the_sim_stops_the_controller_and_a_restart_recovers(pair):
    sim = pair.start('wrist_sim_node')
    pair.start('controller_node')
    pair.running()
    sim.kill()
    sim.wait()
    wait_log(pair, 'controller_node', r'no valid joint_states for .*published zero torque')
    pair.spin_until(lambda: pair.commands and pair.commands[-1][1] == [0.0, 0.0, 0.0], 5.0,
                    'the zero command')
    pair.start('wrist_sim_node', 'wrist_sim_restarted')
    pair.running()
    wait_log(pair, 'controller_node', 'joint_states are back')


def test_sigstop_of_the_controller_trips_the_sim_watchdog_and_sigcont_resumes(pair):
    pair.start('wrist_sim_node')
    ctrl = pair.start('controller_node')
    pair.running()
    ctrl.send_signal(signal.SIGSTOP)
    try:
        wait_log(pair, 'wrist_sim_node', r'no command for .*torque set to zero')
    finally:
        ctrl.send_signal(signal.SIGCONT)
    resumed = time.monotonic()
    pair.spin_until(pair.commands_flow(resumed), 10.0, 'commands after SIGCONT')
    wait_log(pair, 'wrist_sim_node', 'commands are back')
    assert ctrl.poll() is None, pair.logs()


@pytest.mark.parametrize('kind', ['nan', 'valid'])
def test_goal_floods_keep_the_loop_running_with_few_log_lines(pair, kind):
    """
    A flood of goals (1000 as fast as this process publishes) leaves the loop running.

    The commands counted from the flood's start must reach half of what the loop gave before
    it, at the rate this process received them on this host, over the flood's length (500 a
    second of flood on a host that keeps the 1 kHz loop): a host several times slower, or
    one busy with other work, slows the loop and the flood alike.
    """
    pair.start('wrist_sim_node')
    pair.start('controller_node')
    pair.running()
    before = time.monotonic()
    pair.spin_until(pair.commands_flow(before, 200), 10.0, 'commands before the flood')
    rate_hz = 200 / (time.monotonic() - before)  # the loop's commands as received here
    goal = PoseStamped()
    goal.header.frame_id = 'base_link'
    start = time.monotonic()
    for k in range(1000):  # as fast as this process publishes: about 1000 goals in 1 s
        angle = 0.8 + 1e-3 * k
        o = goal.pose.orientation
        o.x, o.y, o.z, o.w = 0.0, 0.0, math.sin(angle / 2), math.cos(angle / 2)
        if kind == 'nan':
            o.w = math.nan
        pair.goal_pub.publish(goal)
        pair.executor.spin_once(timeout_sec=0.0)
    flood_s = time.monotonic() - start
    pair.spin_until(pair.commands_flow(start, int(0.5 * rate_hz * flood_s)), 10.0 + flood_s,
                    'commands during the flood')
    settled = time.monotonic()
    pair.spin_until(pair.commands_flow(settled, 200), 5.0, 'commands after the flood')
    text = pair.log('controller_node')
    if kind == 'nan':
        lines = text.count('target_pose rejected')
        assert 1 <= lines <= 3 + flood_s, text[-3000:]
        assert 'more like it' in text or lines == 1
    else:
        lines = text.count('new goal')
        assert 1 <= lines <= 6 * (1 + flood_s), text[-3000:]


def test_reset_during_motion_returns_to_the_start_and_regulation_resumes(pair):
    pair.start('wrist_sim_node')
    pair.start('controller_node')
    pair.running()
    pair.send_paper_goal()
    pair.spin_until(lambda: 0.2 < pair.error_norm() < 0.7, 10.0, 'the wrist on its way')
    pair.states.clear()
    assert call_service(pair.executor, pair.reset, Trigger.Request()).success
    # Back at q(0) = 0 at rest (the controller moves it on within milliseconds).
    pair.spin_until(lambda: any(max(map(abs, s.position)) < 1e-9 and max(map(abs, s.velocity))
                                < 1e-9 for s in pair.states), 5.0, 'the reset to q(0) = 0')
    pair.spin_until(lambda: pair.error_norm() < 1e-2, 20.0, 'the goal again after the reset')


def test_a_duplicate_controller_is_reported_by_both_nodes(pair):
    pair.start('wrist_sim_node')
    pair.start('controller_node')
    pair.running()
    pair.start('controller_node', 'controller_twin')
    wait_log(pair, 'wrist_sim_node', r'2 publishers on /effort_controller/commands', 15.0)
    for name in ('controller_node', 'controller_twin'):
        wait_log(pair, name, r'2 nodes are named /quat_jt_controller', 15.0)


def test_the_composed_process_regulates_and_exits_cleanly(pair):
    """Both nodes in one process: the same topics, the goal reached, Ctrl-C exits with 0."""
    both = pair.start('composed')
    pair.running()
    pair.send_paper_goal()
    pair.spin_until(lambda: pair.error_norm() < 1e-2, 20.0, 'the paper goal, composed')
    assert local_ros.stop_node(both, timeout=10.0) == 0, pair.logs()
    text = pair.log('composed')
    assert '[wrist_sim]: stats {' in text and '[quat_jt_controller]: new goal' in text, text
    assert 'prewarm: off (composed)' in text, text  # one process: its caches stay warm
    assert 'Traceback' not in text and 'context is invalid' not in text, text[-3000:]


def stop_flag_installed(pid: int) -> bool:
    """Tell whether the process catches SIGTERM: its stop flag is in (Python's is SIGINT's)."""
    try:
        status = Path(f'/proc/{pid}/status').read_text()
    except OSError:
        return False
    caught = int(re.search(r'SigCgt:\s*([0-9a-f]+)', status).group(1), 16)
    return bool(caught >> (signal.SIGTERM - 1) & 1)


@pytest.mark.parametrize('executable', ['controller_node', 'wrist_sim_node', 'composed'])
def test_ctrl_c_during_start_up_exits_0_without_a_traceback(pair, executable):
    """Ctrl-C to the group as soon as the process runs this package's code; at its first line."""
    for when in ('stop flag', 'first log line'):
        name = f'{executable}_{when.replace(" ", "_")}'
        proc = pair.start(executable, name)
        if when == 'stop flag':
            pair.spin_until(lambda: proc.poll() is not None or stop_flag_installed(proc.pid),
                            30.0, 'the stop flag')
        else:
            pair.spin_until(lambda: proc.poll() is not None or '[INFO]' in pair.log(name),
                            60.0, 'the first log line')
        local_ros.interrupt_group(proc)
        assert proc.wait(60.0) == 0, pair.logs()
        assert 'Traceback' not in pair.log(name), pair.log(name)


@pytest.mark.parametrize('executable', ['controller_node', 'composed'])
def test_ctrl_c_again_and_again_during_shutdown_still_exits_0(pair, executable):
    """A second Ctrl-C (ros2 launch sends one when another process exits) changes nothing."""
    if executable == 'controller_node':
        pair.start('wrist_sim_node')
    proc = pair.start(executable)
    pair.running(executable)
    deadline = time.monotonic() + 60.0
    while proc.poll() is None and time.monotonic() < deadline:  # every 10 ms until it exits
        local_ros.interrupt_group(proc)
        try:
            proc.wait(0.01)
        except subprocess.TimeoutExpired:
            pass
    assert proc.wait(10.0) == 0, pair.logs()
    assert 'Traceback' not in pair.log(executable), pair.log(executable)


def test_the_workers_ignore_ctrl_c_and_come_back_when_they_die(pair):
    """
    Both workers die before any goal: one ERROR each, regulation goes on, each starts again.

    Then the new workers get a SIGINT (as they would from a terminal, were they in the node's
    group): they ignore it, and are still there when the next goal has been reached.
    """
    pair.start('wrist_sim_node')
    ctrl = pair.start('controller_node')
    pair.running('controller_node')
    workers = {'quat_jt_controller.goal_check': 'goal-check worker exited',  # the launcher's
               'quat_jt_controller.redesign': 'design worker exited'}  # children, both
    pair.spin_until(lambda: all(descendants_of(ctrl.pid, m) for m in workers), 10.0,
                    'the goal-check and design workers')
    first = {m: descendants_of(ctrl.pid, m)[0] for m in workers}
    for module, said in workers.items():
        os.kill(first[module], signal.SIGKILL)
        wait_log(pair, 'controller_node', rf'\[ERROR\].*{said}')
    since = time.monotonic()
    pair.spin_until(pair.commands_flow(since, 200), 10.0, 'commands while the workers are down')

    def started_again(module: str) -> list:
        return [w for w in descendants_of(ctrl.pid, module) if w != first[module] and alive(w)]
    pair.spin_until(lambda: all(started_again(m) for m in workers), 30.0,
                    'the workers started again')
    second = [started_again(m)[0] for m in workers]
    for pid in second:
        # Started again by the launcher (the node starts no process while it runs), it runs
        # with normal scheduling.
        assert set(thread_policies(pid).values()) == {('other', 0)}, pid
        os.kill(pid, signal.SIGINT)
    pair.send_paper_goal()
    pair.spin_until(lambda: pair.error_norm() < 1e-2, 30.0, 'the paper goal')
    assert all(alive(pid) for pid in second) and ctrl.poll() is None, pair.logs()
    assert local_ros.stop_node(ctrl) == 0, pair.logs()
    text = pair.log('controller_node')
    for said in workers.values():
        assert text.count(said) == 1, text[-3000:]
    assert 'Traceback' not in text and 'accepted with a warning' not in text, text[-3000:]


def test_every_parameter_has_a_value_and_a_whole_file_is_one_logged_change(pair):
    """``ros2 param dump`` gets every value back; ``ros2 param load`` of it logs one line."""
    pair.start('wrist_sim_node')
    pair.start('controller_node')
    pair.running('controller_node')
    for node_name, log_name in (('quat_jt_controller', 'controller_node'),
                                ('wrist_sim', 'wrist_sim_node')):
        client = AsyncParameterClient(pair.node, node_name)
        pair.spin_until(client.services_are_ready, 30.0, f'{node_name} parameter services')
        listed = client.list_parameters()
        pair.spin_until(listed.done, 10.0, 'list_parameters')
        names = list(listed.result().result.names)
        got = client.get_parameters(names)  # what ros2 param dump asks for
        pair.spin_until(got.done, 10.0, 'get_parameters')
        values = got.result().values
        assert len(values) == len(names) > 10, (names, values)
        unset = [n for n, v in zip(names, values) if v.type == ParameterType.PARAMETER_NOT_SET]
        assert not unset, unset
        # What ros2 param load sends for the dumped file: every parameter in one request.
        before = pair.log(log_name).count('parameters updated')
        loaded = client.set_parameters(
            [ParameterMsg(name=n, value=v) for n, v in zip(names, values)])
        pair.spin_until(loaded.done, 10.0, 'set_parameters')
        refused = [n for n, r in zip(names, loaded.result().results) if not r.successful]
        assert 'cpu_affinity' in refused and 'joints' in refused, refused  # read-only
        assert 'kv' in names and 'kv' not in refused or node_name == 'wrist_sim', refused
        wait_log(pair, log_name, 'parameters updated')
        # One more request, of one parameter: its line is the next one, so the file made one.
        single = client.set_parameters([Parameter('use_sim_time', value=False)])
        pair.spin_until(single.done, 10.0, 'set use_sim_time')
        pair.spin_until(lambda: pair.log(log_name).count('parameters updated') >= before + 2,
                        10.0, 'the line of the second request')
        assert pair.log(log_name).count('parameters updated') == before + 2, pair.log(log_name)


def test_a_namespaced_lockstep_pair_keeps_its_clock_in_its_namespace(pair):
    """As the launch files run them: ``__ns:=/left`` and ``/clock:=clock``; nothing on /clock."""
    remaps = ('-r', '__ns:=/left', '-r', '/clock:=clock')
    for executable, params, config in (
            ('wrist_sim_node', {'publish_clock': True}, 'config/wrist_sim.yaml'),
            ('controller_node', {'use_sim_time': True}, 'config/wrist_controller.yaml')):
        pair.procs[executable] = local_ros.spawn_node(
            executable, pair.env, pair.work_dir, params=params, ros_args=remaps,
            params_files=(share_path(config),))
    clocks = {'/left/clock': 0, '/clock': 0}
    commands = []
    for topic in clocks:
        pair.node.create_subscription(Clock, topic, lambda m, t=topic: clocks.__setitem__(
            t, clocks[t] + 1), 10)
    pair.node.create_subscription(Float64MultiArray, '/left/effort_controller/commands',
                                  commands.append, 10)
    pair.spin_until(lambda: clocks['/left/clock'] > 100 and len(commands) > 1000, 60.0,
                    'lockstep in /left')
    assert clocks['/clock'] == 0, clocks
    # No deadlines in lockstep: thread_priority (50 by default) is not applied there.
    for executable, proc in pair.procs.items():
        assert set(thread_policies(proc.pid).values()) == {('other', 0)}, executable
