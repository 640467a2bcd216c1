"""
The controller node in-process, through its public interfaces.

Parameter declarations, validation, atomic gain swaps, goal checks, the hold-pose start and the
diagnostics. The node and a probe node share one context and one executor; the probe publishes
joint states and goals on the node's topics and listens to its commands, poses, /rosout and
/diagnostics. The multi-process behaviour over DDS is in test_controller_node.py.
"""
import math
import os
from pathlib import Path
import sys
import time
from typing import Callable

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
import numpy as np
import pytest
from quat_jt_controller import paper
from quat_jt_controller import quaternion as quat
from quat_jt_controller.control_law import GainsError, Potential, Task
from quat_jt_controller.controller import NO_STATE_WARN_NS
from quat_jt_controller.controller_node import NODE_NAME, QuatJtController
from quat_jt_controller.goal_motion import MAX_GAP_S
from quat_jt_controller.model import ModelError
from quat_jt_controller.parameter_table import GAINS, SHAPING
from quat_jt_controller.shaping import Shaping, ShapingError
from quat_jt_runtime.param_table import names
from quat_jt_runtime.worker import WORKER_NICE
from rcl_interfaces.msg import Log, ParameterType
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

pytestmark = pytest.mark.node

CONFIG = Path(__file__).resolve().parent.parent / 'config' / 'paper_wrist_controller.yaml'
PRODUCT = Path(__file__).resolve().parent.parent / 'config' / 'wrist_controller.yaml'
PAPER_KP = list(paper.KP)
GOAL_XYZW = quat.to_xyzw(paper.Q_DESIRED)
STRUCTURAL = ('task', 'joints', 'base_link', 'tip_link', 'robot_description',
              'state_timeout', 'publish_rate_divider')


def state(q, v=(0.0, 0.0, 0.0), names=('joint1', 'joint2', 'joint3'),
          age_s: float = 0.0) -> JointState:
    """Return a joint state stamped ``age_s`` ago by the system clock (the node's)."""
    msg = JointState()
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(
        time.time_ns() - int(age_s * 1e9), 1_000_000_000)
    msg.name = list(names)
    msg.position = [float(x) for x in q]
    msg.velocity = [float(x) for x in v]
    return msg


def goal(xyzw, frame='base_link', position=(0.0, 0.0, 0.0)) -> PoseStamped:
    msg = PoseStamped()
    msg.header.frame_id = frame
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = position
    o = msg.pose.orientation
    o.x, o.y, o.z, o.w = (float(c) for c in xyzw)
    return msg


class Probe:
    """Talks to one controller node through its topics, in the same process and executor."""

    def __init__(self, context, node: QuatJtController) -> None:
        self.node = node
        self.probe = rclpy.create_node('controller_probe', context=context)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(node)
        self.executor.add_node(self.probe)
        self.commands: list[list[float]] = []
        self.poses: list[tuple[float, ...]] = []
        self.logs: list[str] = []
        self.diagnostics: list[DiagnosticArray] = []
        p = self.probe
        p.create_subscription(Float64MultiArray, 'effort_controller/commands',
                              lambda m: self.commands.append(list(m.data)), 100)
        p.create_subscription(
            PoseStamped, f'{NODE_NAME}/current_pose', lambda m: self.poses.append(
                (m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z,
                 m.pose.orientation.w)), 100)
        p.create_subscription(Log, '/rosout', lambda m: self.logs.append(m.msg)
                              if m.name == NODE_NAME else None, 100)
        p.create_subscription(DiagnosticArray, '/diagnostics', self.diagnostics.append, 10)
        self.state_pub = p.create_publisher(JointState, 'joint_states', 100)
        self.goal_pub = p.create_publisher(PoseStamped, f'{NODE_NAME}/target_pose', 10)
        self.spin_until(lambda: self.state_pub.get_subscription_count() > 0
                        and self.goal_pub.get_subscription_count() > 0
                        and p.count_publishers('effort_controller/commands') > 0, 'discovery')

    def spin_until(self, condition: Callable[[], bool], what: str, timeout: float = 10.0):
        deadline = time.monotonic() + timeout
        while not condition():
            assert time.monotonic() < deadline, f'timed out waiting for {what}'
            self.executor.spin_once(timeout_sec=0.02)

    def command_for(self, msg: JointState) -> list[float]:
        """Publish one state and return the command computed from it."""
        n = len(self.commands)
        self.state_pub.publish(msg)
        self.spin_until(lambda: len(self.commands) > n, 'a command')
        assert len(self.commands) == n + 1
        return self.commands[-1]

    def send_goal(self, msg: PoseStamped) -> None:
        """Publish a goal and wait until the node has taken it (or counted its rejection)."""
        c = self.node.counters
        seen = c.accepted_goals + c.rejected_goals
        self.goal_pub.publish(msg)
        self.spin_until(lambda: c.accepted_goals + c.rejected_goals > seen, 'the goal')

    def wait_log(self, fragment: str) -> str:
        self.spin_until(lambda: any(fragment in m for m in self.logs), f'log {fragment!r}')
        return next(m for m in self.logs if fragment in m)

    def close(self) -> None:
        self.executor.remove_node(self.probe)
        self.executor.remove_node(self.node)
        self.probe.destroy_node()


@pytest.fixture
def context():
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    yield ctx
    rclpy.try_shutdown(context=ctx)


@pytest.fixture
def make_node(context):
    nodes = []

    def make(overrides=None, cli_args=None) -> QuatJtController:
        node = QuatJtController(
            context=context, cli_args=cli_args,
            parameter_overrides=[Parameter(k, value=v) for k, v in (overrides or {}).items()])
        nodes.append(node)
        return node
    yield make
    for node in nodes:
        node.destroy_node()


@pytest.fixture
def make_probe(context, make_node):
    probes = []

    def make(overrides=None) -> Probe:
        probes.append(Probe(context, make_node(overrides)))
        return probes[-1]
    yield make
    for probe in probes:
        probe.close()


def test_parameters_are_declared_with_descriptors(make_node):
    node = make_node()
    for name in STRUCTURAL + names(GAINS):
        d = node.describe_parameter(name)
        assert d.description, name
        assert not d.dynamic_typing, name
        assert d.read_only == (name in STRUCTURAL), name
    assert node.describe_parameter('kp').type == ParameterType.PARAMETER_DOUBLE_ARRAY
    assert node.describe_parameter('state_timeout').floating_point_range
    assert node.describe_parameter('publish_rate_divider').integer_range


def test_the_node_declares_exactly_its_table(make_node):
    """Every parameter the node has is a row of its table, with the row's type and range."""
    from quat_jt_controller import parameter_table as table
    from quat_jt_runtime.params import rclpy_type, REALTIME
    node = make_node()
    rows = {spec.name: spec for spec in table.STRUCTURE + table.GAINS + table.SHAPING
            + table.PAYLOAD + REALTIME}
    declared = set(node._parameters) - {'use_sim_time', 'start_type_description_service'}
    assert declared == set(rows)
    for name, spec in rows.items():
        d = node.describe_parameter(name)
        assert d.type == spec.kind.descriptor_type, name
        assert d.read_only == spec.read_only, name
        assert node.get_parameter(name).type_ is rclpy_type(spec.kind), name
        if spec.bounds is not None and not spec.kind.is_array:  # an array's: its entries'
            limits = d.floating_point_range or d.integer_range
            assert (limits[0].from_value, limits[0].to_value) == spec.bounds, name
    assert 'values in (0, ' in node.describe_parameter('kv').additional_constraints
    assert '3 finite values' in node.describe_parameter('kv').additional_constraints  # n filled


@pytest.mark.parametrize('name, urdf', [('paper_wrist_controller.yaml', None),
                                        ('wrist_controller.yaml', None),
                                        ('xarm6_controller.yaml', 'xarm6'),
                                        ('panda_controller.yaml', 'panda')])
def test_the_tools_build_the_controller_the_node_runs_from_a_config(make_node, name, urdf):
    """controller_from_config gives the node's gains, extensions, model and ceilings."""
    from quat_jt_controller.controller_config import controller_from_package_config
    from robots import PANDA_URDF, XARM6_URDF
    xml = {'xarm6': XARM6_URDF, 'panda': PANDA_URDF}[urdf].read_text() if urdf else ''
    node = make_node({'robot_description': xml} if xml else None,
                     cli_args=['--ros-args', '--params-file',
                               str(CONFIG.parent / name)])
    tools = controller_from_package_config(name, xml)
    assert tools.gains == node.regulator.gains
    assert tools.shaping == node.regulator.shaping
    assert tools.model.joint_names == node.regulator.model.joint_names
    assert tools.model.armature == node.regulator.model.armature
    with pytest.raises(GainsError, match='kv'):  # the node's ceilings, here too
        controller_from_package_config(name, xml, overrides={
            'kv': [1e6] * tools.n})
    with pytest.raises(ShapingError, match='posture_weight'):  # and the node's ranges
        controller_from_package_config(name, xml, overrides={'posture_weight': 101.0})


def test_the_armature_is_in_the_inertia_the_controller_uses(make_node):
    """The read-only armature goes on the diagonal of the node's M(q) (the Lyapunov V)."""
    plain = make_node().regulator.model
    model = make_node({'armature': [0.1, 0.2, 0.3]}).regulator.model
    q = [0.2, -0.4, 0.9]
    assert model.armature == (0.1, 0.2, 0.3)
    np.testing.assert_allclose(model.mass_matrix(q) - plain.mass_matrix(q),
                               np.diag([0.1, 0.2, 0.3]), atol=1e-12)


def test_the_payload_is_in_the_gravity_the_controller_compensates_and_set_live(make_probe):
    """
    payload_mass at payload_com in tip_link: in g(q); set live, whole, or refused by name.

    Refused too: a payload the arm cannot hold up where it was last measured.
    """
    from quat_jt_controller.model import RobotModel
    from quat_jt_runtime.resources import default_urdf_xml

    def with_payload(mass, com):
        return RobotModel(default_urdf_xml(), 'base_link', 'tool0', payload_kg=mass,
                          payload_com_tip_m=com)

    probe = make_probe({'payload_mass': 0.5, 'payload_com': [0.0, 0.0, 0.05]})
    node = probe.node
    model = node.regulator.model
    q = [0.2, -0.4, 0.9]
    np.testing.assert_allclose(model.gravity(q), with_payload(0.5, (0.0, 0.0, 0.05)).gravity(q),
                               atol=1e-12)
    results = node.set_parameters_atomically([Parameter('payload_mass', value=1.5),
                                              Parameter('payload_com', value=[0.0, 0.1, 0.0])])
    assert results.successful, results.reason
    np.testing.assert_allclose(model.gravity(q), with_payload(1.5, (0.0, 0.1, 0.0)).gravity(q),
                               atol=1e-12)
    refused = node.set_parameters([Parameter('payload_com', value=[0.0, 0.1])])[0]
    assert not refused.successful and 'payload_com must be 3 finite numbers' in refused.reason
    refused = node.set_parameters([Parameter('payload_mass', value=-1.0)])[0]
    assert not refused.successful  # below the declared range
    heavy = [Parameter('payload_mass', value=500.0),  # a typo, 10 cm off joint 2's axis
             Parameter('payload_com', value=[0.1, 0.0, 0.0])]
    probe.command_for(state((0.0, 0.0, 0.0)))  # the arm measured there
    refused = node.set_parameters_atomically(heavy)
    assert not refused.successful
    assert ('payload_mass 500 kg at payload_com [0.1, 0.0, 0.0] cannot be held up where the arm '
            'is: joint2 would need 491 N m of its 30 N m effort limit') in refused.reason
    assert (model.payload_kg, model.payload_com_tip_m) == (1.5, (0.0, 0.1, 0.0))


def test_the_position_resolution_reaches_the_state_check(make_node):
    """A read-only count per joint; the node's controller estimates velocities with it."""
    assert make_node().controller.position_resolution == (0.0, 0.0, 0.0)
    node = make_node({'position_resolution': [1e-4, 2e-4, 0.0]})
    assert node.controller.position_resolution == (1e-4, 2e-4, 0.0)
    assert not node.set_parameters([Parameter('position_resolution',
                                              value=[0.0] * 3)])[0].successful


def test_a_config_without_gains_is_refused_by_name():
    from quat_jt_controller.controller_config import ConfigError, controller_from_config
    from quat_jt_runtime.resources import config_parameters
    params = dict(config_parameters('wrist_controller.yaml'))
    del params['kv']
    with pytest.raises(ConfigError, match="lack \\['kv'\\]"):
        controller_from_config(params)


def test_defaults_and_paper_config_file_are_the_paper_experiment(make_node):
    for node in (make_node(), make_node(cli_args=['--ros-args', '--params-file', str(CONFIG)])):
        assert node.regulator.shaping == Shaping.create(  # no extension on
            3, preferred_configuration=node.regulator.model.middle_of_ranges())
        g = node.gains
        assert node.get_parameter('task').value == 'orientation'
        assert g.kp == paper.KP and g.kv == paper.KV
        assert g.lam == paper.LAMBDA and g.gravity_compensation
        assert g.potential is Potential.TANH
        assert list(node.get_parameter('joints').value) == ['joint1', 'joint2', 'joint3']
        assert node.get_parameter('tip_link').value == 'tool0'


@pytest.mark.parametrize('changes, words', [
    ({'kp': [1.0, 2.0]}, 'kp must have 3 values'),
    ({'kp': [1.0, 0.0, 2.0]}, 'kp[1] must be finite and > 0'),
    ({'kp': [1.0, math.inf, 2.0]}, 'kp[1] must be finite'),
    ({'kv': [1.0, 1.0, math.nan]}, 'kv[2] must be finite'),
    ({'lambda': [-30.0, 30.0, 30.0]}, 'lambda[0] must be finite and > 0'),
    ({'potential': 'exp'}, 'potential must be one of'),
    ({'kp': [1.0, 2.0, 3.0], 'kv': [1.0]}, 'kv must have 3 values'),  # atomic: none applied
])
def test_invalid_sets_are_rejected_and_nothing_changes(make_node, changes, words):
    node = make_node()
    before = node.gains
    values_before = {k: node.get_parameter(k).value for k in names(GAINS)}
    result = node.set_parameters_atomically(
        [Parameter(k, value=v) for k, v in changes.items()])
    assert not result.successful
    assert words in result.reason, result.reason
    assert node.gains is before
    for k in names(GAINS):
        assert node.get_parameter(k).value == values_before[k]


def test_read_only_parameters_cannot_be_set(make_node):
    node = make_node()
    for name, value in (('task', 'pose'), ('joints', ['a']), ('state_timeout', 1.0),
                        ('base_link', 'world')):
        result = node.set_parameters([Parameter(name, value=value)])[0]
        assert not result.successful and 'read-only' in result.reason


def test_valid_set_swaps_one_new_gains_object(make_node):
    node = make_node()
    before = node.gains
    result = node.set_parameters_atomically([
        Parameter('kp', value=[1.0, 2.0, 3.0]), Parameter('potential', value='quadratic'),
        Parameter('gravity_compensation', value=False)])
    assert result.successful, result.reason
    g = node.gains
    assert g is not before
    assert (g.kp, g.potential, g.gravity_compensation) == ((1.0, 2.0, 3.0),
                                                           Potential.QUADRATIC, False)
    assert g.kv == before.kv and g.lam == before.lam
    # A later single change builds on the stored values.
    assert node.set_parameters([Parameter('kv', value=[2.0, 2.0, 2.0])])[0].successful
    assert node.gains.kp == (1.0, 2.0, 3.0) and node.gains.kv == (2.0, 2.0, 2.0)


def test_pose_task_has_six_gains_and_a_position_error_topic(make_node):
    node = make_node({'task': 'pose'})
    assert len(node.gains.kp) == 6 and len(node.gains.lam) == 6
    assert len(node.get_publishers_info_by_topic('/quat_jt_controller/position_error')) == 1
    assert not node.set_parameters([Parameter('kp', value=PAPER_KP)])[0].successful
    ok = node.set_parameters([Parameter('kp', value=[100.0] * 3 + PAPER_KP)])[0]
    assert ok.successful, ok.reason


def test_position_task_has_three_gains_and_a_position_error_topic(make_node):
    node = make_node({'task': 'position'})
    assert len(node.gains.kp) == 3 and len(node.gains.lam) == 3
    assert len(node.get_publishers_info_by_topic('/quat_jt_controller/position_error')) == 1
    assert not node.set_parameters([Parameter('kp', value=[100.0] * 6)])[0].successful
    ok = node.set_parameters([Parameter('kp', value=[100.0] * 3)])[0]
    assert ok.successful, ok.reason


@pytest.mark.parametrize('overrides, error, words', [
    ({'kp': [1.0, 2.0]}, GainsError, 'kp must have 3 values'),
    ({'task': 'velocity'}, ValueError, 'task must be'),
    ({'joints': ['joint1', 'jointX', 'joint3']}, ModelError, 'jointX'),
    ({'tip_link': 'nowhere'}, ModelError, 'nowhere'),
    ({'state_rate': 50.0}, Exception, 'state_rate out of range'),
    ({'state_rate': 2000.0}, Exception, 'state_rate out of range'),
    ({'armature': [0.1, -1.0, 0.0]}, ValueError, r'armature\[1\] must be finite and >= 0, got -1'),
    ({'armature': [0.1, 0.1]}, ValueError, r'armature must have 3 values \(one per joint\)'),
    ({'armature': [0.1, float('inf'), 0.0]}, ValueError, r'armature\[1\] must be finite'),
    ({'position_resolution': [1e-4, -1e-4, 0.0]}, ValueError,
     r'position_resolution\[1\] must be finite and >= 0, got -0.0001'),
    ({'position_resolution': [1e-4]}, ValueError,
     r'position_resolution must have 3 values \(one per joint\)'),
    ({'payload_mass': -0.5}, Exception, 'payload_mass'),
    ({'payload_com': [0.0, 0.1]}, ValueError, 'payload_com must be 3 finite numbers'),
])
def test_bad_start_up_configuration_raises_a_clear_error(make_node, overrides, error, words):
    with pytest.raises(error, match=words):
        make_node(overrides)


def test_tick_reads_no_parameters_and_holds_the_first_pose(make_probe, monkeypatch):
    probe = make_probe()
    node = probe.node

    def forbidden(*args, **kwargs):
        raise AssertionError('parameter read in the tick')
    monkeypatch.setattr(node, 'get_parameter', forbidden)
    monkeypatch.setattr(node, 'get_parameters', forbidden)
    q = (0.3, 0.7, -0.2)
    first = probe.command_for(state(q))
    assert node.regulator.goal is not None
    probe.wait_log('holding the measured pose')
    # Holding the measured pose at rest: e = 0, so the command is g(q) alone.
    g = node.regulator.model.gravity(list(q))
    assert all(abs(a - b) < 1e-12 for a, b in zip(first, g)), (first, g)
    second = probe.command_for(state((0.5, 0.2, 0.1)))  # pulled back towards the held pose
    assert second != first


@pytest.mark.parametrize('sim_time', [False, True])
def test_no_joint_states_after_start_is_a_warning_naming_the_topic(context, sim_time):
    """
    Remapped to a topic nobody publishes: a WARN with its resolved name and 0 publishers.

    On simulated time too, with no /clock (no simulator) to run it.
    """
    listener = rclpy.create_node('rosout_listener', context=context)
    logs: list[tuple[int, str]] = []
    listener.create_subscription(Log, '/rosout', lambda m: logs.append((m.level, m.msg)) if (
        m.name == NODE_NAME) else None, 100)
    cli = ['--ros-args', '-r', 'joint_states:=/nowhere/joint_states']
    node = QuatJtController(context=context, cli_args=cli, parameter_overrides=[
        Parameter('use_sim_time', value=sim_time)])
    executor = SingleThreadedExecutor(context=context)
    try:
        executor.add_node(node)
        executor.add_node(listener)
        deadline = time.monotonic() + 10.0
        while not any(level == Log.WARN for level, _ in logs):
            assert time.monotonic() < deadline, 'no warning without joint states'
            executor.spin_once(timeout_sec=0.05)
        start = next(text for _, text in logs if 'task, joints' in text)
        assert 'waiting for joint states on /nowhere/joint_states, then holding' in start, start
        line = next(text for level, text in logs if level == Log.WARN)
        assert 'no valid joint state on /nowhere/joint_states' in line, line
        assert ', 0 publishers on it:' in line and 'remap with -r joint_states:=' in line, line
        waited_s = float(line.split(' s after start')[0].rsplit(' ', 1)[1])
        assert waited_s >= NO_STATE_WARN_NS * 1e-9, line  # due 1.8 s after start, not before
        assert node.controller.goal is None  # nothing held, nothing commanded
        # its goal-check worker niced, but not on simulated time (no deadlines to keep)
        while node.controller.checker.pid is None:
            assert time.monotonic() < deadline + 20.0, 'no goal-check worker'
            executor.spin_once(timeout_sec=0.05)
        ours = os.getpriority(os.PRIO_PROCESS, 0)
        assert os.getpriority(os.PRIO_PROCESS, node.controller.checker.pid) == (
            ours if sim_time else min(19, ours + WORKER_NICE))
    finally:
        executor.remove_node(listener)
        executor.remove_node(node)
        listener.destroy_node()
        node.destroy_node()


def test_a_silent_publisher_is_counted_until_the_first_state(make_probe):
    """The probe publishes nothing on joint_states yet: 1 publisher, none received."""
    probe = make_probe()
    line = probe.wait_log('no valid joint state on /joint_states')
    assert ', 1 publisher on it: none received' in line, line
    probe.command_for(state((0.1, 0.2, 0.3)))
    assert 's after start: holding the measured pose' in probe.wait_log('first joint state')


def test_shuffled_and_extra_names_give_the_same_command(make_probe):
    probe = make_probe()
    probe.send_goal(goal(GOAL_XYZW))
    q, v = (0.1, 0.2, 0.3), (0.3, -0.1, 0.2)
    first = probe.command_for(state(q, v))
    shuffled = probe.command_for(state((0.3, 9.0, 0.1, 0.2), (0.2, 9.0, 0.3, -0.1),
                                       names=('joint3', 'gripper', 'joint1', 'joint2')))
    again = probe.command_for(state(q, v))  # back to the first layout (cached)
    assert first == shuffled == again


def test_states_without_velocities_get_them_estimated_and_say_so_once(make_probe):
    # the stamps are the test's, 2 ms apart however slow the host: a round trip that stalls
    # on a busy host neither ages them past max_state_age nor trips the state timeout
    probe = make_probe({'state_rate': 500.0, 'max_state_age': 60.0, 'state_timeout': 10.0})
    probe.send_goal(goal(GOAL_XYZW))
    t0 = time.time_ns() - 10_000_000
    commands = []
    for k in range(20):  # joint 2 at 0.5 rad/s, every 2 ms, stamped; no velocities
        msg = state((0.3, 0.1, 0.04, 0.2 + 0.001 * k), v=(),
                    names=('joint3', 'joint1', 'gripper', 'joint2'))
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(t0 + 2_000_000 * k,
                                                                1_000_000_000)
        commands.append(probe.command_for(msg))
    probe.wait_log('joint_states carry no velocities: estimating them')
    assert sum('carry no velocities' in m for m in probe.logs) == 1
    assert probe.node.counters.rejected_states == 0
    qdot = probe.node.controller.last_qdot
    assert qdot[0] == 0.0 and qdot[2] == 0.0
    assert 0.49 < qdot[1] < 0.5  # the estimate has settled on 0.5 rad/s
    # the damping acts on it: the same state at rest asks for a different torque
    at_rest = probe.command_for(state((0.1, 0.2 + 0.001 * 19, 0.3), v=(0.0, 0.0, 0.0)))
    assert at_rest[1] != commands[-1][1]


def test_goals_breaking_a1_or_a2_are_accepted_with_a_warning(make_probe):
    probe = make_probe()
    probe.send_goal(goal(GOAL_XYZW))
    assert probe.node.regulator.goal.xyzw() == pytest.approx(GOAL_XYZW, abs=1e-4)
    singular_xyzw = (0.0, 0.0, math.sin(0.4), math.cos(0.4))  # only reached with q2 = 0
    probe.send_goal(goal(singular_xyzw))
    assert probe.node.regulator.goal.xyzw() == pytest.approx(singular_xyzw)  # in force
    assert 'singular' in probe.wait_log('accepted with a warning')
    pose = make_probe({'task': 'pose'})
    pose.send_goal(goal(GOAL_XYZW, position=(1.0, 0.0, 0.0)))  # the wrist centre cannot move
    assert pose.node.regulator.goal.p_desired_base == (1.0, 0.0, 0.0)
    pose.spin_until(lambda: any('accepted with a warning' in m and 'A1' in m for m in pose.logs),
                    'the A1 warning')


def test_rejected_goal_keeps_the_previous_one(make_probe):
    probe = make_probe()
    probe.send_goal(goal(GOAL_XYZW))
    kept = probe.node.regulator.goal
    for bad in (goal(quat.to_xyzw(paper.Q_DESIRED_AS_PRINTED)), goal((math.nan, 0.0, 0.0, 1.0)),
                goal((0.0, 0.0, 0.0, 1.0), frame='world'),
                goal((0.0, 0.0, 0.0, 1.0), frame='/base_link')):  # tf2: no leading slash
        probe.send_goal(bad)
        assert probe.node.regulator.goal is kept
    assert probe.node.counters.rejected_goals == 4
    probe.wait_log("header.frame_id is '/base_link', expected 'base_link' (tf2 frame ids have")
    probe.send_goal(goal(tuple(-c for c in GOAL_XYZW), frame=''))
    assert probe.node.regulator.goal is not kept


def test_goals_in_a_link_of_the_robot_are_placed_with_the_measured_joints(make_probe):
    """A goal in tool0 is placed in base_link at the last measured q, then held there."""
    from quat_jt_runtime.description import LATCHED_QOS
    probe = make_probe()
    node = probe.node
    probe.send_goal(goal((0.0, 0.0, 0.0, 1.0), frame='tool0'))  # no joint state yet
    probe.wait_log("'tool0' is a link of the robot, placed with the measured joints, and no "
                   'joint state has come yet')
    q = (0.3, -0.4, 0.5)
    probe.command_for(state(q))
    p_tip, R_tip = node.regulator.model.forward_kinematics(list(q))
    half = 0.1  # 0.2 rad about tool0's own x axis
    probe.send_goal(goal((math.sin(half), 0.0, 0.0, math.cos(half)), frame='tool0'))
    placed = node.regulator.goal
    c, s = math.cos(2 * half), math.sin(2 * half)
    want = [[sum(R_tip[i][k] * ((1.0, 0.0, 0.0), (0.0, c, -s), (0.0, s, c))[k][j]
                 for k in range(3)) for j in range(3)] for i in range(3)]
    got = quat.to_rotation_matrix(placed.q_desired_base)
    assert all(abs(got[i][j] - want[i][j]) < 1e-9 for i in range(3) for j in range(3))
    probe.wait_log('(given in tool0, placed in base_link at the measured joints)')
    probe.command_for(state((0.0, 0.0, 0.0)))  # the robot moves on: the goal stays
    assert node.regulator.goal == placed
    # ~/goal_pose: latched, so a viewer that joins now still gets the goal in force. It is
    # published on a timer: a first viewer waits for it (it may first get the one before) ...

    def placed_pose(pose: PoseStamped) -> bool:
        o = pose.pose.orientation
        return (o.x, o.y, o.z, o.w) == pytest.approx(placed.xyzw(), abs=1e-12)
    first: list[PoseStamped] = []
    probe.probe.create_subscription(PoseStamped, f'{NODE_NAME}/goal_pose', first.append,
                                    LATCHED_QOS)
    probe.spin_until(lambda: any(placed_pose(p) for p in first), 'the goal on ~/goal_pose')
    # ... and a viewer that joins after it gets that goal at once, the one message it gets
    poses: list[PoseStamped] = []
    probe.probe.create_subscription(PoseStamped, f'{NODE_NAME}/goal_pose', poses.append,
                                    LATCHED_QOS)
    probe.spin_until(lambda: poses, 'the latched goal on ~/goal_pose')
    o = poses[-1].pose.orientation
    assert poses[-1].header.frame_id == 'base_link'
    assert (o.x, o.y, o.z, o.w) == pytest.approx(placed.xyzw(), abs=1e-12)
    assert [poses[-1].pose.position.x, poses[-1].pose.position.y,
            poses[-1].pose.position.z] == pytest.approx(p_tip, abs=1e-9)  # at the tip then
    probe.send_goal(goal((0.0, 0.0, 0.0, 1.0), frame='world'))
    probe.wait_log("header.frame_id is 'world', expected 'base_link' (or empty) or a link of "
                   "the robot: ['link1', 'link2', 'link3', 'tool0']")
    assert node.regulator.goal == placed


def test_diagnostics_warn_near_180_degrees(make_probe):
    probe = make_probe()
    probe.command_for(state((0.0, 0.0, 0.0)))
    probe.send_goal(goal((1.0, 0.0, 0.0, 0.0)))  # 180 degrees about x from q = 0
    probe.command_for(state((0.0, 0.0, 0.0)))

    def statuses() -> dict:
        return {s.name.split(': ')[-1]: s for s in probe.diagnostics[-1].status}
    probe.spin_until(lambda: probe.diagnostics and statuses()['goal'].level == bytes([1]),
                     'a goal warning on /diagnostics')
    status = statuses()
    assert '180 degrees' in status['goal'].message
    values = {kv.key: kv.value for kv in status['control loop'].values}
    for key in ('control_rate_hz', 'period_jitter_std_us', 'compute_us_p50', 'compute_us_p99',
                'state_age_us_p50', 'saturated_ticks'):
        assert key in values
    assert probe.node.config.task is Task.ORIENTATION


def test_current_pose_quaternion_keeps_its_hemisphere(make_probe):
    """Through eta = 0 the canonical (eta >= 0) quaternion flips; ~/current_pose must not."""
    probe = make_probe({'publish_rate_divider': 1})
    for q1 in (3.0, 3.1, 3.2, 3.3):  # joint 1 through 180 degrees about z: eta crosses 0
        probe.command_for(state((q1, 0.0, 0.0)))
    probe.spin_until(lambda: len(probe.poses) == 4, 'four poses')
    published = probe.poses
    for a, b in zip(published, published[1:]):
        assert sum(x * y for x, y in zip(a, b)) > 0.9, published
    assert published[0][3] > 0.0 > published[-1][3]  # it did go past eta = 0


def status_values(probe: Probe, which: str) -> dict:
    """Return the key-values of the newest /diagnostics status named '<node>: <which>'."""
    for arr in reversed(probe.diagnostics):
        for s in arr.status:
            if s.name.endswith(f': {which}'):
                return {kv.key: kv.value for kv in s.values} | {'_message': s.message,
                                                                '_level': s.level}
    return {}


@pytest.mark.parametrize('age_s, words', [
    (10.0, 'stamped 10.0'),  # 10 s in the past
    (-10.0, 'in the future'),
    (None, 'header.stamp is zero'),
])
def test_stale_unstamped_and_future_states_are_not_used(make_probe, age_s, words):
    """No command from them; counted and flagged on /diagnostics; the state timeout follows."""
    probe = make_probe()
    probe.command_for(state((0.1, 0.2, 0.3)))
    n = len(probe.commands)
    bad = state((0.1, 0.2, 0.3), age_s=age_s or 0.0)
    if age_s is None:
        bad.header.stamp.sec = bad.header.stamp.nanosec = 0
    for _ in range(5):
        probe.state_pub.publish(bad)
    probe.spin_until(lambda: probe.node.counters.stale_states == 5, 'five stale states')
    assert any(words in m for m in probe.logs) or probe.wait_log(words)
    # Only the state timeout's single zero command may come; never a command from them.
    assert all(c == [0.0] * 3 for c in probe.commands[n:])
    probe.spin_until(lambda: 'stale_states_total' in status_values(probe, 'control loop')
                     and status_values(probe, 'control loop')['stale_states_total'] == '5',
                     'the stale count on /diagnostics')
    loop = status_values(probe, 'control loop')
    assert loop['_level'][0] >= 1 and 'rejected for their stamps' in loop['_message']


def test_repeated_joint_names_are_rejected_with_the_reason(make_probe):
    probe = make_probe()
    probe.command_for(state((0.1, 0.2, 0.3)))
    n = len(probe.commands)
    probe.state_pub.publish(state((0.1, 0.9, 0.2, 0.3),
                                  names=('joint1', 'joint1', 'joint2', 'joint3')))
    assert 'joint names repeat' in probe.wait_log("joint names repeat ['joint1']")
    assert probe.node.counters.rejected_states == 1 and len(probe.commands) == n


@pytest.mark.parametrize('name, value, words', [
    ('kp', [1.7e308] * 3, 'kp[0] = 1.7e+308 is above 50000'),
    ('kv', [1.0, 1e6, 1.0], 'kv[1] = 1e+06 is above 50000'),
    ('lambda', [30.0, 30.0, 1e5], 'lambda[2] = 100000 is above 10000'),
])
def test_absurd_gains_are_refused_with_a_reason(make_node, name, value, words):
    """Upper bounds from the effort limits (50 N m / 1e-3); the old node accepted 1.7e308."""
    node = make_node()
    result = node.set_parameters([Parameter(name, value=value)])[0]
    assert not result.successful and words in result.reason, result.reason
    assert node.gains.kp == paper.KP
    assert '50000' in node.describe_parameter('kp').additional_constraints


def test_pose_task_diagnostics_report_the_position_error_and_goal(make_probe):
    probe = make_probe({'task': 'pose'})
    probe.send_goal(goal(GOAL_XYZW, position=(0.0, 0.0, 0.05)))
    probe.command_for(state((0.1, 0.2, 0.3)))
    probe.spin_until(lambda: 'position_error_m' in status_values(probe, 'goal'),
                     'the goal status')
    values = status_values(probe, 'goal')
    p_tip, _ = probe.node.regulator.model.forward_kinematics([0.1, 0.2, 0.3])
    assert float(values['position_error_m']) == pytest.approx(
        math.dist(p_tip, (0.0, 0.0, 0.05)), rel=1e-5)
    assert values['goal_position_m'] == '[0.0, 0.0, 0.05]'


def test_namespaced_node_keeps_its_config_file(context):
    """The config files are keyed /**, so a namespace (or a rename) keeps their values."""
    cli = ['--ros-args', '-r', '__ns:=/arm', '-r', '__node:=renamed', '--params-file',
           str(CONFIG)]
    node = QuatJtController(context=context, cli_args=cli, parameter_overrides=[])
    try:
        assert node.get_fully_qualified_name() == '/arm/renamed'
        assert node.gains.kp == paper.KP and node.get_parameter('tip_link').value == 'tool0'
    finally:
        node.destroy_node()


def test_xarm6_joints_without_its_urdf_say_what_to_pass(make_node):
    with pytest.raises(ModelError, match='No robot description was given, so the bundled '
                                         'spherical wrist'):
        make_node({'joints': [f'joint{i}' for i in range(1, 7)], 'base_link': 'link_base',
                   'tip_link': 'link6', 'task': 'pose'})


def test_a_second_commander_and_a_name_twin_are_warned_about(make_probe, context):
    probe = make_probe()
    twin = QuatJtController(context=context)  # same name, same namespace
    try:
        probe.executor.add_node(twin)

        def warned() -> bool:
            message = status_values(probe, 'control loop').get('_message', '')
            return 'publishers on /effort_controller/commands' in message and (
                'nodes are named /quat_jt_controller' in message)
        probe.spin_until(warned, 'both warnings on /diagnostics', timeout=15.0)
        probe.wait_log('another controller commands this robot too')
        probe.wait_log('give each its own name')
    finally:
        probe.executor.remove_node(twin)
        twin.destroy_node()


def test_the_state_callback_never_reads_the_graph(make_probe):
    """While states flow, /diagnostics go out after a command; the graph is read on a timer."""
    probe = make_probe()
    node = probe.node
    callers: list[list[str]] = []  # the functions up the stack of each graph query

    def recorded(query):
        def call(*args, **kwargs):
            frame, names = sys._getframe(1), []
            while frame is not None:
                names.append(frame.f_code.co_name)
                frame = frame.f_back
            callers.append(names)
            return query(*args, **kwargs)
        return call
    node.count_publishers = recorded(node.count_publishers)
    node.get_node_names_and_namespaces = recorded(node.get_node_names_and_namespaces)
    in_tick = []  # each /diagnostics array: published from the state callback?
    publish_diagnostics = node._diagnostics.publish

    def publish() -> None:
        in_tick.append(sys._getframe(1).f_code.co_name == '_on_joint_state')
        publish_diagnostics()
    node._diagnostics.publish = publish
    probe.command_for(state((0.1, 0.2, 0.3)))
    deadline = time.monotonic() + 15.0
    while sum(in_tick) < 2:  # states every ~2 ms: the diagnostics wait for the next command
        assert time.monotonic() < deadline, 'no /diagnostics after a command'
        probe.state_pub.publish(state((0.1, 0.2, 0.3)))
        probe.executor.spin_once(timeout_sec=0.002)
    assert len(callers) >= 2 * 2, callers  # both queries, at each diagnostics timer
    assert not any('_on_joint_state' in names for names in callers), callers
    assert probe.diagnostics and status_values(probe, 'control loop')


# --------------------------------------------------------------------------- the extensions
def test_product_config_turns_the_extensions_on(make_node):
    node = make_node(cli_args=['--ros-args', '--params-file', str(PRODUCT)])
    s = node.regulator.shaping
    assert s.limits_on and s.friction_on and s.configuration_on and s.speed_damping_on
    assert node.regulator.limit_band is not None
    assert node.gains.kp != paper.KP  # designed, not the paper's
    for name in names(SHAPING):
        d = node.describe_parameter(name)
        assert d.description and not d.read_only and not d.dynamic_typing, name


@pytest.mark.parametrize('changes, words', [
    ({'joint_limit_margin': 2.0, 'joint_limit_gain': [1.0, 1.0, 1.0]}, 'out of range'),
    ({'friction_compensation': [1.0, -1.0, 0.0]}, 'friction_compensation[1] must be finite'),
    ({'configuration_gain': [1.0, 1.0]}, 'configuration_gain must have 3 values'),
])
def test_invalid_extension_sets_are_rejected_and_nothing_changes(make_node, changes, words):
    node = make_node()
    before = node.regulator.shaping
    result = node.set_parameters_atomically(
        [Parameter(k, value=v) for k, v in changes.items()])
    assert not result.successful and words in result.reason, result.reason
    assert node.regulator.shaping is before


def test_a_valid_extension_set_swaps_one_shaping(make_node):
    node = make_node()
    result = node.set_parameters_atomically([
        Parameter('joint_limit_margin', value=0.2),
        Parameter('joint_limit_gain', value=[30.0, 30.0, 30.0]),
        Parameter('friction_compensation', value=[1.8, 0.72, 0.45])])
    assert result.successful, result.reason
    s = node.regulator.shaping
    assert s.joint_limit_margin_rad == 0.2 and s.friction_compensation_nm == (1.8, 0.72, 0.45)
    assert node.regulator.limit_band is not None


def test_the_goal_configuration_arrives_from_the_worker(make_probe):
    probe = make_probe({'configuration_gain': [5.0, 5.0, 5.0]})
    node = probe.node
    probe.command_for(state((0.1, 0.5, 0.2)))
    probe.send_goal(goal(GOAL_XYZW))
    probe.spin_until(lambda: node.regulator.goal_configuration is not None,
                     'q* from the goal-check worker', timeout=20.0)
    _, R = node.regulator.model.forward_kinematics(list(node.regulator.goal_configuration))
    eta_e, _ = quat.orientation_error(quat.from_rotation_matrix(R), paper.Q_DESIRED)
    assert abs(eta_e) > 1.0 - 1e-8  # q* reaches the goal


def test_diagnostics_report_a_stall_with_its_cause(make_probe):
    """At rest against joint 1's stop, off the goal, for more than 0.5 s: a WARN naming it."""
    probe = make_probe()
    probe.command_for(state((0.0, 0.0, 0.0)))
    probe.send_goal(goal(GOAL_XYZW))
    stuck = (math.pi - 0.01, 0.8, 0.3)

    def stall_status():
        for arr in reversed(probe.diagnostics):
            for s in arr.status:
                if s.name.endswith(': stall'):
                    return s
        return None

    def warned() -> bool:
        probe.command_for(state(stuck))  # one tick at rest, freshly stamped
        s = stall_status()
        return s is not None and s.level == bytes([1])
    probe.spin_until(warned, 'a stall warning on /diagnostics', timeout=15.0)
    s = stall_status()
    assert 'joint1' in s.message and 'upper limit' in s.message
    assert {kv.key: kv.value for kv in s.values}['stalled'] == 'True'


def test_a_stamped_stream_gets_its_joint_velocity_and_a_pause_makes_the_goal_fixed(make_probe):
    """docs/lyapunov.md, section 7: nu_d from the stamps, qdot*_d from the worker, then 0."""
    probe = make_probe({'goal_velocity_gain': 1.0})
    node = probe.node
    q_now = (0.1, 0.5, 0.2)
    probe.command_for(state(q_now))
    axis, omega = (0.48, 0.36, 0.8), 0.5  # rad/s about axis, base frame
    t0 = time.time()
    for k in range(40):  # 100 Hz of stamps (sent faster: the stamps are what count)
        angle = omega * 0.01 * k
        s = math.sin(0.5 * angle)
        msg = goal(quat.to_xyzw(quat.multiply((math.cos(0.5 * angle), *(a * s for a in axis)),
                                              paper.Q_DESIRED)))
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int((t0 + 0.01 * k) * 1e9),
                                                                1_000_000_000)
        probe.send_goal(msg)
    probe.spin_until(lambda: node.regulator.goal_joint_velocity is not None,
                     'qdot*_d from the goal-check worker', timeout=20.0)
    qdot_star = node.regulator.goal_joint_velocity
    assert len(qdot_star) == 3 and all(math.isfinite(v) for v in qdot_star)
    assert max(abs(v) for v in qdot_star) > 0.1  # it moves (the mapping: test_goal_motion.py)
    # No goal for longer than any hold: the next tick makes the goal fixed again. (Not
    # command_for: after half a second without states the watchdog's zero command may come
    # first.)
    paused = time.monotonic()
    probe.spin_until(lambda: time.monotonic() > paused + MAX_GAP_S, 'the longest hold')
    probe.state_pub.publish(state(q_now))
    probe.spin_until(lambda: node.regulator.goal_joint_velocity is None,
                     'the next tick to make the goal fixed again')


def test_friction_is_learned_at_rest_off_the_goal_and_reported(make_probe):
    """Stuck away from the goal, the node learns friction from its states' stamps (section 4)."""
    probe = make_probe({'friction_compensation': [0.5, 0.5, 0.5],
                        'friction_learning_limit': [1.0, 1.0, 1.0]})
    node = probe.node
    stuck = (0.1, 0.5, 0.2)
    probe.command_for(state(stuck))
    probe.send_goal(goal(GOAL_XYZW))

    def learned() -> bool:
        probe.command_for(state(stuck))  # at rest, freshly stamped: time passes between ticks
        return all(a > 0.0 for a in node.regulator.learned_friction_nm)
    probe.spin_until(learned, 'friction learned at rest', timeout=15.0)

    def reported():
        probe.command_for(state(stuck))
        for arr in reversed(probe.diagnostics):
            for s in arr.status:
                if s.name.endswith(': goal'):
                    return {kv.key: kv.value for kv in s.values}
        return None

    def learned_reported() -> bool:
        text = (reported() or {}).get('learned_friction_nm', '')
        return bool(text) and all(float(x) > 0.0 for x in text.strip('[]').split(','))
    probe.spin_until(learned_reported, 'learned friction on /diagnostics', timeout=15.0)
    assert 'goal_configuration_rad' in reported()


def test_the_parameter_page_is_generated_from_the_tables():
    """docs/parameters.md is what ``make docs`` writes from both nodes' tables."""
    from quat_jt_bringup.parameter_docs import page
    written = (Path(__file__).resolve().parent.parent / 'docs' / 'parameters.md').read_text()
    assert written == page(), 'docs/parameters.md is stale: run make docs'
    for name in ('kp', 'goal_velocity_gain', 'coulomb_friction', 'cpu_affinity'):
        assert f'| `{name}` |' in written, name


def test_the_node_refuses_a_value_just_outside_a_row_and_takes_one_inside(make_node):
    """The node's path of test_parameter_table's cases: the same rows, the same verdicts."""
    from parameter_cases import inside, live_rows, outside, wrist_context
    node = make_node()
    context = wrist_context(node.regulator.effort_limits_nm)
    for spec in live_rows():
        for name, value, words in outside(spec, context):
            before = node.get_parameter(name).value
            result = node.set_parameters([Parameter(name, value=value)])[0]
            assert not result.successful, (name, value)
            for word in words:
                assert word in result.reason, (word, result.reason)
            assert node.get_parameter(name).value == before
        value = inside(spec, context)
        result = node.set_parameters([Parameter(spec.name, value=value)])[0]
        assert result.successful, (spec.name, value, result.reason)


def test_a_row_added_to_the_table_is_declared_described_and_checked(make_node, monkeypatch):
    from quat_jt_controller import parameter_table as table
    from quat_jt_runtime.param_table import Kind, Spec
    spec = Spec('test_added_gain', Kind.DOUBLE, 0.25, 'A row a test adds (N m). Live.',
                bounds=(0.0, 2.0))
    monkeypatch.setattr(table, 'SHAPING', (*table.SHAPING, spec))
    node = make_node()
    d = node.describe_parameter('test_added_gain')
    assert d.description == spec.description and not d.read_only
    assert (d.floating_point_range[0].from_value, d.floating_point_range[0].to_value) == (0.0,
                                                                                          2.0)
    assert node.get_parameter('test_added_gain').value == 0.25
    refused = node.set_parameters([Parameter('test_added_gain', value=2.5)])[0]
    assert not refused.successful and 'test_added_gain' in refused.reason
    assert '2.5' in refused.reason
    shaping = node.regulator.shaping
    assert node.set_parameters([Parameter('test_added_gain', value=1.5)])[0].successful
    assert node.regulator.shaping is not shaping  # a new snapshot, applied whole
    from quat_jt_bringup.parameter_docs import page
    assert ('| `test_added_gain` | double | `0.25` | [0, 2] | yes | A row a test adds (N m). '
            'Live. |') in page()


def test_the_readme_table_names_every_controller_parameter_and_no_other():
    import fnmatch
    import re
    from quat_jt_controller import parameter_table as table
    from quat_jt_runtime.params import REALTIME
    readme = (Path(__file__).resolve().parent.parent / 'README.md').read_text()
    rows = readme.split('## The parameters\n\n')[1].split('\n\n')[0].splitlines()[2:]
    patterns = re.findall(r'`([a-z_*]+)`', ' '.join(line.split('|')[1] for line in rows))
    parameters = names(table.STRUCTURE + table.GAINS + table.SHAPING + table.PAYLOAD + REALTIME)
    assert len(patterns) > 20, patterns  # the table was found
    assert [p for p in patterns if not fnmatch.filter(parameters, p)] == []
    assert [p for p in parameters if not any(fnmatch.fnmatch(p, pattern)
                                             for pattern in patterns)] == []
