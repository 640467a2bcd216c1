"""
The robot description passed the ROS ways: text, a file, robot_state_publisher's topic.

Unit: which source the parameters name (at most one; none is the bundled wrist) and the file's
errors. Over DDS, the commands the docs and the nodes' hints give: ``--ros-args -p
robot_description_file:=<path>`` for both nodes, and ``-p
robot_description_topic:=/robot_description`` with a transient-local publisher started before
the controller, or after it (it waits, and says so), or never (a clear error, exit status 1).
The simulator publishes the URDF it loaded on ``/robot_description`` for late subscribers.
"""
import os
from pathlib import Path
import time

from experiments import local_ros
from process_harness import ProcessHarnessMixin
import pytest
from quat_jt_runtime.resources import default_urdf_xml
from quat_jt_runtime.urdf_source import choose, DescriptionError, read_file
from quat_jt_runtime.urdf_source import resolve_offline, Source
from robots import XARM6_URDF

REPO = Path(__file__).resolve().parent.parent
XARM6_CONTROLLER = REPO / 'config' / 'xarm6_controller.yaml'
XARM6_SIM = REPO / 'config' / 'xarm6_sim.yaml'
XARM6_START = "pose task, joints ['joint1', 'joint2', 'joint3', 'joint4', 'joint5'"


# ------------------------------------------------------------------------------------ unit
@pytest.mark.unit
def test_no_source_is_the_bundled_wrist_and_one_source_is_taken_as_given(tmp_path):
    bundled = resolve_offline(choose('', '', ''))
    assert bundled.source is Source.BUNDLED and bundled.xml == default_urdf_xml()
    assert bundled.given == ''
    text = resolve_offline(choose('<robot name="r"/>', '', ''))
    assert (text.source, text.xml, text.given) == (Source.TEXT, '<robot name="r"/>',
                                                   '<robot name="r"/>')
    path = tmp_path / 'r.urdf'
    path.write_text('<robot name="f"/>')
    from_file = resolve_offline(choose('', str(path), ''))
    assert (from_file.source, from_file.xml, from_file.origin) == (
        Source.FILE, '<robot name="f"/>', str(path))
    assert str(path) in from_file.describe()
    assert choose('', '', 'robot_description').source is Source.TOPIC


@pytest.mark.unit
@pytest.mark.parametrize('given', [('<robot/>', 'a.urdf', ''), ('', 'a.urdf', 'topic'),
                                   ('<robot/>', '', 'topic')])
def test_two_sources_are_refused_naming_both(given):
    names = [n for n, v in zip(('robot_description', 'robot_description_file',
                                'robot_description_topic'), given) if v]
    with pytest.raises(DescriptionError, match=f'{names[0]} and {names[1]} are both set'):
        choose(*given)


@pytest.mark.unit
def test_a_file_that_cannot_be_read_says_why(tmp_path):
    with pytest.raises(DescriptionError, match="robot_description_file 'nowhere.urdf': no such "
                                               'file'):
        read_file('nowhere.urdf')
    with pytest.raises(DescriptionError, match='cannot be read'):
        read_file(str(tmp_path))  # a directory
    empty = tmp_path / 'empty.urdf'
    empty.write_text('\n')
    with pytest.raises(DescriptionError, match='is empty'):
        read_file(str(empty))


@pytest.mark.unit
def test_the_tools_build_a_config_with_a_urdf_file_as_the_node_does():
    from quat_jt_controller.controller_config import controller_from_config
    from quat_jt_runtime.resources import config_parameters
    params = {**config_parameters('xarm6_controller.yaml'),
              'robot_description_file': str(XARM6_URDF)}
    assert controller_from_config(params).model.joint_names == tuple(
        f'joint{i}' for i in range(1, 7))
    with pytest.raises(DescriptionError, match='needs a node'):
        controller_from_config({**params, 'robot_description_file': '',
                                'robot_description_topic': '/robot_description'})


# ------------------------------------------------------------------------------------- dds
class Rig(ProcessHarnessMixin):
    """This test's own node (publishes and listens) beside the spawned node processes."""

    def __init__(self, work_dir: Path) -> None:
        import rclpy
        from rclpy.experimental import EventsExecutor
        self.work_dir = work_dir
        self.env = local_ros.isolated_env(work_dir, domain_id=int(os.environ['ROS_DOMAIN_ID']))
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node('qjt_description_test', context=self.context)
        self.executor = EventsExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.procs = {}

    def spawn(self, name: str, executable: str, params_file: Path, ros_args: tuple) -> None:
        self.procs[name] = local_ros.spawn_node(executable, self.env, self.work_dir,
                                                params_files=(params_file,),
                                                ros_args=ros_args, name=name)

    def log(self, name: str) -> str:
        path = self.work_dir / f'{name}.log'
        return path.read_text(errors='replace') if path.exists() else ''

    def wait_log(self, name: str, fragment: str, timeout: float = 60.0) -> None:
        self.spin_until(lambda: fragment in self.log(name), timeout,
                        f'{fragment!r} in the log of {name}')

    def description_publisher(self):
        from quat_jt_runtime.description import LATCHED_QOS
        from std_msgs.msg import String
        return self.node.create_publisher(String, '/robot_description', LATCHED_QOS)


@pytest.fixture
def rig(tmp_path):
    r = Rig(tmp_path)
    yield r
    r.close()


@pytest.mark.dds
def test_both_nodes_take_a_urdf_file_from_the_command_line(rig):
    """The hint's command: -p robot_description_file:=<path>; the simulator republishes it."""
    from quat_jt_runtime.description import LATCHED_QOS
    from std_msgs.msg import String
    file_arg = ('-p', f'robot_description_file:={XARM6_URDF}')
    rig.spawn('xarm6_sim', 'wrist_sim_node', XARM6_SIM, file_arg)
    rig.spawn('controller', 'controller_node', XARM6_CONTROLLER, file_arg)
    rig.wait_log('controller', XARM6_START)
    rig.wait_log('xarm6_sim', f'URDF from file {XARM6_URDF} (robot_description_file), '
                              'published on /robot_description')
    received = []
    # subscribed after the simulator published: transient local, so it still arrives
    rig.node.create_subscription(String, '/robot_description',
                                 lambda msg: received.append(msg.data), LATCHED_QOS)
    rig.spin_until(lambda: received, 20.0, 'the URDF on /robot_description')
    assert received == [XARM6_URDF.read_text()]
    # the controller answers the simulator: both run the xArm6 from the file
    rig.spin_until(lambda: rig.node.count_publishers('/effort_controller/commands') == 1
                   and rig.node.count_subscribers('/joint_states') >= 1, 20.0,
                   "the controller on the simulator's topics")


@pytest.mark.dds
@pytest.mark.parametrize('publisher_first', [True, False],
                         ids=['publisher_before', 'publisher_after'])
def test_the_controller_takes_the_urdf_from_the_topic(rig, publisher_first):
    """robot_state_publisher's topic (transient local), published before or after the start."""
    from std_msgs.msg import String
    publisher = rig.description_publisher()
    if publisher_first:
        publisher.publish(String(data=XARM6_URDF.read_text()))
    rig.spawn('controller', 'controller_node', XARM6_CONTROLLER,
              ('-p', 'robot_description_topic:=/robot_description'))
    rig.wait_log('controller', 'waiting up to 30 s for the robot description on '
                               '/robot_description')
    if not publisher_first:
        assert XARM6_START not in rig.log('controller')  # it waits: no model yet
        publisher.publish(String(data=XARM6_URDF.read_text()))
    rig.wait_log('controller', 'robot description received on /robot_description')
    rig.wait_log('controller', XARM6_START)


@pytest.mark.dds
def test_no_description_on_the_topic_is_a_clear_error(rig):
    rig.spawn('controller', 'controller_node', XARM6_CONTROLLER,
              ('-p', 'robot_description_topic:=/robot_description', '-p',
               'robot_description_timeout:=0.5'))
    proc = rig.procs.pop('controller')  # its exit is the point here
    deadline = time.monotonic() + 60.0
    while proc.poll() is None and time.monotonic() < deadline:
        rig.executor.spin_once(timeout_sec=0.1)
    assert proc.returncode == 1, rig.log('controller')
    log = rig.log('controller')
    assert ('cannot start: no robot description on /robot_description within '
            'robot_description_timeout 0.5 s (no publisher)') in log
    assert 'robot_description_file:=/path/robot.urdf' in log
    assert 'Traceback' not in log


@pytest.mark.dds
def test_a_ctrl_c_while_waiting_for_the_topic_is_a_clean_stop(rig):
    rig.spawn('controller', 'controller_node', XARM6_CONTROLLER,
              ('-p', 'robot_description_topic:=/robot_description'))
    rig.wait_log('controller', 'waiting up to 30 s for the robot description')
    proc = rig.procs.pop('controller')
    assert local_ros.stop_node(proc) == 0, rig.log('controller')
    assert 'Traceback' not in rig.log('controller')


@pytest.mark.dds
def test_any_arm_runs_from_its_urdf_and_the_files_design_gains_writes(rig, tmp_path):
    """
    Run arm_demo.launch.py's two nodes as it starts them; a reachable goal is reached.

    Each node gets its file from design_gains (--out, --sim-out) and -p
    robot_description_file:=<the URDF>.
    """
    import math
    from geometry_msgs.msg import PoseStamped, Vector3Stamped
    from quat_jt_controller import gain_design
    from quat_jt_controller import quaternion as quat
    from quat_jt_controller.model import RobotModel
    from robots import small_arm_urdf
    urdf = tmp_path / 'arm.urdf'
    urdf.write_text(small_arm_urdf(('revolute',) * 4))
    controller_file, sim_file = tmp_path / 'arm_controller.yaml', tmp_path / 'arm_sim.yaml'
    assert gain_design.main(['--urdf', str(urdf), '--task', 'orientation', '--out',
                             str(controller_file), '--sim-out', str(sim_file)]) == 0
    file_arg = ('-p', f'robot_description_file:={urdf}')
    rig.spawn('arm_sim', 'wrist_sim_node', sim_file, file_arg)
    rig.spawn('controller', 'controller_node', controller_file, file_arg)
    rig.wait_log('controller', 'orientation task, joints')
    errors = []
    rig.node.create_subscription(Vector3Stamped, '/quat_jt_controller/orientation_error',
                                 lambda m: errors.append(math.hypot(m.vector.x, m.vector.y,
                                                                    m.vector.z)), 10)
    rig.spin_until(lambda: errors, 30.0, "the controller's orientation error")
    model = RobotModel(urdf.read_text(), 'base_link', 'tool')
    _, rotation = model.forward_kinematics([0.4, -0.5, 0.6, 0.3])
    goal = PoseStamped()
    goal.header.frame_id = 'base_link'
    q = quat.from_rotation_matrix(rotation)
    goal.pose.orientation.w, goal.pose.orientation.x = float(q[0]), float(q[1])
    goal.pose.orientation.y, goal.pose.orientation.z = float(q[2]), float(q[3])
    publisher = rig.node.create_publisher(PoseStamped, '/quat_jt_controller/target_pose', 10)
    rig.spin_until(lambda: publisher.get_subscription_count() >= 1, 20.0, 'the goal topic')
    publisher.publish(goal)
    rig.spin_until(lambda: errors and errors[-1] > 0.05, 20.0, 'the new goal taken')
    rig.spin_until(lambda: errors[-1] < 0.01, 60.0, 'the goal reached (||e|| < 0.01)')
