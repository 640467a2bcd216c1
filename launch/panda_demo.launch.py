"""
The 7-DOF demo: the Franka Panda of pybullet_data in the simulator, regulated in full pose.

    ros2 launch quat_jt_controller panda_demo.launch.py [potential:=tanh|quadratic]
                                                       [use_gui:=true|false]
                                                       [namespace:=left]
                                                       [rviz:=true|false]

A redundant arm: the transpose-Jacobian law needs no inverse, so it runs unchanged on
seven joints; the self-motion is held by the goal-configuration term, whose q* the goal check
slides along the self-motion to the posture nearest the arm's (then ``preferred_configuration``,
``posture_weight``; docs/lyapunov.md, section 9). The URDF ships inside the ``pybullet_data``
Python package: it is read here into ``robot_description`` of both nodes (its
``package://meshes/...`` files are found inside pybullet_data). The seven arm joints are
regulated, ``panda_link0`` -> ``panda_link8`` (the flange); the two finger joints are held
closed by the simulator and are not in ``/joint_states``. Parameters come from this package's
``config/panda_sim.yaml`` and ``config/panda_controller.yaml`` (both written by
``design_gains``). The simulator node is named ``panda_sim``. ``use_gui:=true`` opens the
PyBullet window, ``rviz:=true`` starts robot_state_publisher and RViz with
``rviz/quat_jt.rviz`` (the arm, the goal and the measured pose; the fingers, not in
``/joint_states``, have no transform and are not drawn). If either node exits on its own, the
whole launch shuts down. The arm starts at rest in the
Panda's usual ready pose (flange at (0.307, 0, 0.590) m, pointing down) and holds it; then send
a reachable goal, e.g. this one, 0.25 m away (the flange's pose at q = [0.3, -0.5, 0.2, -2.0,
0.1, 1.8, 0.9]):

    ros2 topic pub --once /quat_jt_controller/target_pose geometry_msgs/msg/PoseStamped \
      "{header: {frame_id: panda_link0},
        pose: {position: {x: 0.3514, y: 0.2278, z: 0.6777},
               orientation: {x: -0.9678, y: 0.2055, z: -0.1104, w: 0.0942}}}"

and watch ``/quat_jt_controller/position_error`` and ``/quat_jt_controller/orientation_error``;
``/diagnostics`` gives the goal configuration q* the elbow settles at.
``ros2 service call /panda_sim/reset std_srvs/srv/Trigger`` puts the arm back at its start.
Self-collision is not simulated (docs/panda.md).
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

PANDA_URDF = Path(pybullet_data.getDataPath()) / 'franka_panda' / 'panda.urdf'


def generate_launch_description() -> LaunchDescription:
    share = get_package_share_directory('quat_jt_controller')
    sim_config = os.path.join(share, 'config', 'panda_sim.yaml')
    controller_config = os.path.join(share, 'config', 'panda_controller.yaml')
    robot_description = PANDA_URDF.read_text()
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
        Node(package='quat_jt_controller', executable='wrist_sim_node', name='panda_sim',
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
        *live_view(share, robot_description, 'panda_link0', namespace, rviz),
    ])
