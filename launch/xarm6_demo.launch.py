"""
The 6-DOF demo: the xArm6 of pybullet_data in the simulator, regulated in full pose.

    ros2 launch quat_jt_controller xarm6_demo.launch.py [potential:=tanh|quadratic]
                                                       [use_gui:=true|false]
                                                       [namespace:=left]
                                                       [rviz:=true|false]

The general case of Campa and Kelly (Section 4): y_tilde = [p_d - p; e], law (24) or (32). The
URDF ships inside the ``pybullet_data`` Python package (no download): it is read here into
``robot_description`` of both nodes (its ``package://xarm_description`` meshes are resolved by
the simulator inside pybullet_data). Parameters come from this package's
``config/xarm6_sim.yaml`` and ``config/xarm6_controller.yaml`` (task: pose, link_base ->
link6, the gains and how they were chosen). ``potential`` overrides the controller's,
``use_gui`` opens the PyBullet window (it needs a display), ``rviz`` starts
robot_state_publisher and RViz with ``rviz/quat_jt.rviz`` (the arm, the goal and the measured
pose). If either node exits on its own, the whole launch shuts down. The simulator node is
named ``xarm6_sim``. The arm starts at rest at a non-singular configuration (tool pointing
down at (0.334, 0, 0.498) m) and holds that pose; then send a reachable goal, e.g. this one,
0.10 m and 0.25 rad away (the arm's pose at q = [0.2, -0.4, -1.1, 0.2, 1.4, 0.3]):

    ros2 topic pub --once /quat_jt_controller/target_pose geometry_msgs/msg/PoseStamped \
      "{header: {frame_id: link_base},
        pose: {position: {x: 0.3604, y: 0.0898, z: 0.5157},
               orientation: {x: -0.9919, y: 0.0617, z: -0.0237, w: 0.1083}}}"

and watch ``/quat_jt_controller/position_error`` and ``/quat_jt_controller/orientation_error``.
The simulator holds the arm at its start until the controller's first command arrives
(``hold_until_first_command``), so it does not sag while the nodes discover each other;
``ros2 service call /xarm6_sim/reset std_srvs/srv/Trigger`` puts it back there, at rest.
"""
import os
from pathlib import Path

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
import pybullet_data
from quat_jt_bringup.launch_parts import CLOCK_IN_NAMESPACE, gui_and_namespace_arguments
from quat_jt_bringup.launch_parts import live_view, publish_robot_description
from quat_jt_bringup.launch_parts import shutdown_when_exits

XARM6_URDF = Path(pybullet_data.getDataPath()) / 'xarm' / 'xarm6_robot.urdf'


def generate_launch_description() -> LaunchDescription:
    share = get_package_share_directory('quat_jt_controller')
    sim_config = os.path.join(share, 'config', 'xarm6_sim.yaml')
    controller_config = os.path.join(share, 'config', 'xarm6_controller.yaml')
    robot_description = XARM6_URDF.read_text()
    potential = LaunchConfiguration('potential')
    use_gui = LaunchConfiguration('use_gui')
    namespace = LaunchConfiguration('namespace')
    rviz = LaunchConfiguration('rviz')
    return LaunchDescription([
        DeclareLaunchArgument('potential', default_value='tanh',
                              choices=['tanh', 'quadratic'],
                              description="controller potential: 'tanh' (Eq. 32) or "
                                          "'quadratic' (Eq. 24)"),
        *gui_and_namespace_arguments(),
        DeclareLaunchArgument('rviz', default_value='false', choices=['true', 'false'],
                              description='start robot_state_publisher and RViz (the robot, '
                                          'the goal and the measured pose)'),
        Node(package='quat_jt_controller', executable='wrist_sim_node', name='xarm6_sim',
             output='screen', emulate_tty=True, namespace=namespace,
             remappings=CLOCK_IN_NAMESPACE,
             on_exit=shutdown_when_exits('the simulator exited'),
             parameters=[sim_config,
                         {'robot_description': robot_description,
                          'use_gui': ParameterValue(use_gui, value_type=bool),
                          'publish_robot_description': publish_robot_description(rviz)}]),
        Node(package='quat_jt_controller', executable='controller_node',
             name='quat_jt_controller', output='screen', emulate_tty=True, namespace=namespace,
             remappings=CLOCK_IN_NAMESPACE,
             on_exit=shutdown_when_exits('the controller exited'),
             parameters=[controller_config,
                         {'robot_description': robot_description,
                          'potential': ParameterValue(potential, value_type=str)}]),
        *live_view(share, robot_description, 'link_base', namespace, rviz),
    ])
