"""
The controller node in-process.

Parameter declarations, validation, atomic gain swaps, goal checks, the hold-pose start and the
diagnostics (issue 4).

The node is constructed in this process and its callbacks are driven directly or through an
executor; the multi-process behaviour over DDS is in test_controller_node.py.
"""
import math
from pathlib import Path
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
import pytest
from quat_jt_controller import quaternion as quat
from quat_jt_controller.control_law import GainsError, Potential, Task
from quat_jt_controller.controller_node import QuatJtController
from quat_jt_controller.model import ModelError
from quat_jt_controller.parameters import GAIN_PARAMETERS
from rcl_interfaces.msg import ParameterType
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState

CONFIG = Path(__file__).resolve().parent.parent / 'config' / 'wrist_controller.yaml'
PAPER_KP = [4.5, 20.5, 17.5]
GOAL_XYZW = (0.0, 0.4226, 0.7152, 0.5566)
STRUCTURAL = ('task', 'joints', 'base_link', 'tip_link', 'robot_description',
              'state_timeout', 'publish_rate_divider')


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


def state(q, v=(0.0, 0.0, 0.0), names=('joint1', 'joint2', 'joint3')) -> JointState:
    msg = JointState()
    msg.name = list(names)
    msg.position = [float(x) for x in q]
    msg.velocity = [float(x) for x in v]
    return msg


def goal(xyzw, frame='base_link', position=(0.0, 0.0, 0.0)) -> PoseStamped:
    msg = PoseStamped()
    msg.header.frame_id = frame
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = position
    o = msg.pose.orientation
    o.x, o.y, o.z, o.w = xyzw
    return msg


def test_parameters_are_declared_with_descriptors(make_node):
    node = make_node()
    for name in STRUCTURAL + GAIN_PARAMETERS:
        d = node.describe_parameter(name)
        assert d.description, name
        assert not d.dynamic_typing, name
        assert d.read_only == (name in STRUCTURAL), name
    assert node.describe_parameter('kp').type == ParameterType.PARAMETER_DOUBLE_ARRAY
    assert node.describe_parameter('state_timeout').floating_point_range
    assert node.describe_parameter('publish_rate_divider').integer_range


def test_defaults_and_config_file_are_the_paper_experiment(make_node):
    for node in (make_node(), make_node(cli_args=['--ros-args', '--params-file', str(CONFIG)])):
        g = node._gains
        assert node.get_parameter('task').value == 'orientation'
        assert g.kp == tuple(PAPER_KP) and g.kv == (1.0, 1.0, 1.0)
        assert g.lam == (30.0, 30.0, 30.0) and g.gravity_compensation
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
    before = node._gains
    values_before = {k: node.get_parameter(k).value for k in GAIN_PARAMETERS}
    result = node.set_parameters_atomically(
        [Parameter(k, value=v) for k, v in changes.items()])
    assert not result.successful
    assert words in result.reason, result.reason
    assert node._gains is before
    for k in GAIN_PARAMETERS:
        assert node.get_parameter(k).value == values_before[k]


def test_read_only_parameters_cannot_be_set(make_node):
    node = make_node()
    for name, value in (('task', 'pose'), ('joints', ['a']), ('state_timeout', 1.0),
                        ('base_link', 'world')):
        result = node.set_parameters([Parameter(name, value=value)])[0]
        assert not result.successful and 'read-only' in result.reason


def test_valid_set_swaps_one_new_gains_object(make_node):
    node = make_node()
    before = node._gains
    result = node.set_parameters_atomically([
        Parameter('kp', value=[1.0, 2.0, 3.0]), Parameter('potential', value='quadratic'),
        Parameter('gravity_compensation', value=False)])
    assert result.successful, result.reason
    g = node._gains
    assert g is not before
    assert (g.kp, g.potential, g.gravity_compensation) == ((1.0, 2.0, 3.0),
                                                           Potential.QUADRATIC, False)
    assert g.kv == before.kv and g.lam == before.lam
    # A later single change builds on the stored values.
    assert node.set_parameters([Parameter('kv', value=[2.0, 2.0, 2.0])])[0].successful
    assert node._gains.kp == (1.0, 2.0, 3.0) and node._gains.kv == (2.0, 2.0, 2.0)


def test_pose_task_has_six_gains_and_a_position_error_topic(make_node):
    node = make_node({'task': 'pose'})
    assert len(node._gains.kp) == 6 and len(node._gains.lam) == 6
    assert len(node.get_publishers_info_by_topic('/quat_jt_controller/position_error')) == 1
    assert not node.set_parameters([Parameter('kp', value=PAPER_KP)])[0].successful
    ok = node.set_parameters([Parameter('kp', value=[100.0] * 3 + PAPER_KP)])[0]
    assert ok.successful, ok.reason


@pytest.mark.parametrize('overrides, error, words', [
    ({'kp': [1.0, 2.0]}, GainsError, 'kp must have 3 values'),
    ({'task': 'position'}, ValueError, 'task must be'),
    ({'joints': ['joint1', 'jointX', 'joint3']}, ModelError, 'jointX'),
    ({'tip_link': 'nowhere'}, ModelError, 'nowhere'),
])
def test_bad_start_up_configuration_raises_a_clear_error(make_node, overrides, error, words):
    with pytest.raises(error, match=words):
        make_node(overrides)


def test_tick_reads_no_parameters_and_holds_the_first_pose(make_node, monkeypatch):
    node = make_node()

    def forbidden(*args, **kwargs):
        raise AssertionError('parameter read in the tick')
    monkeypatch.setattr(node, 'get_parameter', forbidden)
    monkeypatch.setattr(node, 'get_parameters', forbidden)
    sent = []
    monkeypatch.setattr(node._cmd_pub, 'publish', lambda m: sent.append(list(m.data)))
    q = (0.3, 0.7, -0.2)
    node._on_joint_state(state(q))
    assert node._goal_source == 'hold'
    # Holding the measured pose at rest: e = 0, so the command is g(q) alone.
    g = node._model.gravity(list(q))
    assert all(abs(a - b) < 1e-12 for a, b in zip(sent[-1], g)), (sent[-1], g)
    node._on_joint_state(state((0.5, 0.2, 0.1)))  # pulled back towards the held pose
    assert len(sent) == 2 and sent[-1] != sent[0]


def test_shuffled_and_extra_names_give_the_same_command(make_node, monkeypatch):
    node = make_node()
    sent = []
    monkeypatch.setattr(node._cmd_pub, 'publish', lambda m: sent.append(list(m.data)))
    node._on_target_pose(goal(GOAL_XYZW))
    q, v = (0.1, 0.2, 0.3), (0.3, -0.1, 0.2)
    node._on_joint_state(state(q, v))
    msg = state((0.3, 9.0, 0.1, 0.2), (0.2, 9.0, 0.3, -0.1),
                names=('joint3', 'gripper', 'joint1', 'joint2'))
    node._on_joint_state(msg)
    node._on_joint_state(state(q, v))  # back to the first layout (cached)
    assert sent[0] == sent[1] == sent[2]


def test_goals_breaking_a1_or_a2_are_accepted_with_a_warning(make_node):
    node = make_node()
    node._on_target_pose(goal(GOAL_XYZW))
    assert node._goal_source == 'target_pose' and node._goal_warning == ''
    singular_xyzw = (0.0, 0.0, math.sin(0.4), math.cos(0.4))  # only reached with q2 = 0
    node._on_target_pose(goal(singular_xyzw))
    assert node._goal[0] == pytest.approx(quat.from_xyzw(*singular_xyzw))  # accepted
    assert 'singular' in node._goal_warning
    pose = make_node({'task': 'pose'})
    far = goal(GOAL_XYZW)
    far.pose.position.x = 1.0  # the wrist centre cannot move
    pose._on_target_pose(far)
    assert pose._goal[1] == (1.0, 0.0, 0.0) and 'A1' in pose._goal_warning


def test_rejected_goal_keeps_the_previous_one(make_node):
    node = make_node()
    node._on_target_pose(goal(GOAL_XYZW))
    kept = node._goal
    for bad in (goal((0.0, 0.4226, 0.7848, 0.5566)), goal((math.nan, 0.0, 0.0, 1.0)),
                goal((0.0, 0.0, 0.0, 1.0), frame='tool0')):
        node._on_target_pose(bad)
        assert node._goal is kept
    assert node._n_rejected_goals == 3
    node._on_target_pose(goal(tuple(-c for c in GOAL_XYZW), frame='/base_link'))
    assert node._goal is not kept


def test_diagnostics_warn_near_180_degrees(make_node, context):
    node = make_node()
    listener = rclpy.create_node('diag_listener', context=context)
    got = []
    listener.create_subscription(DiagnosticArray, '/diagnostics', got.append, 10)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    executor.add_node(listener)
    node._on_joint_state(state((0.0, 0.0, 0.0)))
    node._on_target_pose(goal((1.0, 0.0, 0.0, 0.0)))  # 180 degrees about x from q = 0
    node._on_joint_state(state((0.0, 0.0, 0.0)))
    deadline = time.monotonic() + 10.0
    while not got and time.monotonic() < deadline:
        node._on_diagnostics()
        executor.spin_once(timeout_sec=0.1)
    executor.remove_node(listener)
    listener.destroy_node()
    assert got, 'no /diagnostics received'
    status = {s.name.split(': ')[-1]: s for s in got[-1].status}
    assert status['goal'].level == bytes([1])
    assert '180 degrees' in status['goal'].message
    values = {kv.key: kv.value for kv in status['control loop'].values}
    for key in ('control_rate_hz', 'period_jitter_std_us', 'compute_us_p50', 'compute_us_p99',
                'state_age_us_p50', 'saturated_ticks'):
        assert key in values
    assert node._task is Task.ORIENTATION


def test_current_pose_quaternion_keeps_its_hemisphere(make_node, monkeypatch):
    """Through eta = 0 the canonical (eta >= 0) quaternion flips; ~/current_pose must not."""
    node = make_node({'publish_rate_divider': 1})
    published = []
    monkeypatch.setattr(node._pose_pub, 'publish', lambda m: published.append(
        (m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z,
         m.pose.orientation.w)))
    for q1 in (3.0, 3.1, 3.2, 3.3):  # joint 1 through 180 degrees about z: eta crosses 0
        node._on_joint_state(state((q1, 0.0, 0.0)))
    assert len(published) == 4
    for a, b in zip(published, published[1:]):
        assert sum(x * y for x, y in zip(a, b)) > 0.9, published
    assert published[0][3] > 0.0 > published[-1][3]  # it did go past eta = 0
