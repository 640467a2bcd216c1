"""
The wrist demo: the simulated spherical wrist and the transpose-Jacobian regulator.

    ros2 launch quat_jt_controller wrist_demo.launch.py [potential:=tanh|quadratic]
                                                      [use_gui:=true|false]
                                                      [composed:=true|false]
                                                      [namespace:=left]
                                                      [rviz:=true|false]

The nodes read their parameters from this package's ``config/wrist_sim.yaml`` and
``config/wrist_controller.yaml`` (gains from the robot with the extensions;
``config/paper_wrist_controller.yaml`` is the paper's experiment). The files are keyed ``/**``,
so a namespace (``namespace:=left``, or ``-r __ns:=/left`` with ``ros2 run``) keeps them; the
launch remaps ``/clock`` into the namespace too. ``potential`` overrides the controller's,
``use_gui`` opens the PyBullet window (it needs a display), ``rviz`` starts
robot_state_publisher and RViz with ``rviz/quat_jt.rviz`` (the wrist, the goal and the measured
tool pose; ``quat_jt_bringup.launch_parts``). If either node exits on its own, the whole launch
shuts down (Ctrl-C ends it once, without "was required" lines). Then send a goal, e.g. the
paper's corrected one (docs/errata.md, note 2):

    ros2 topic pub --once /quat_jt_controller/target_pose geometry_msgs/msg/PoseStamped \
      "{header: {frame_id: base_link},
        pose: {orientation: {x: 0.0, y: 0.4226, z: 0.7152, w: 0.5566}}}"
"""
import os
from pathlib import Path

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition, UnlessCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from quat_jt_bringup.launch_parts import CLOCK_IN_NAMESPACE, gui_and_namespace_arguments
from quat_jt_bringup.launch_parts import live_view, publish_robot_description
from quat_jt_bringup.launch_parts import shutdown_when_exits


def generate_launch_description() -> LaunchDescription:
    share = get_package_share_directory('quat_jt_controller')
    sim_config = os.path.join(share, 'config', 'wrist_sim.yaml')
    controller_config = os.path.join(share, 'config', 'wrist_controller.yaml')
    potential = LaunchConfiguration('potential')
    use_gui = LaunchConfiguration('use_gui')
    namespace = LaunchConfiguration('namespace')
    composed = LaunchConfiguration('composed')
    rviz = LaunchConfiguration('rviz')
    overrides = {'use_gui': ParameterValue(use_gui, value_type=bool),
                 'potential': ParameterValue(potential, value_type=str),
                 'publish_robot_description': publish_robot_description(rviz)}
    wrist_urdf = Path(share, 'urdf', 'spherical_wrist.urdf').read_text()  # for RViz
    return LaunchDescription([
        DeclareLaunchArgument('potential', default_value='tanh',
                              choices=['tanh', 'quadratic'],
                              description="controller potential: 'tanh' (Eq. 38) or "
                                          "'quadratic' (Eq. 37)"),
        *gui_and_namespace_arguments(),
        DeclareLaunchArgument('composed', default_value='false', choices=['true', 'false'],
                              description='both nodes in one process on one executor '
                                          '(the composed mode)'),
        DeclareLaunchArgument('rviz', default_value='false', choices=['true', 'false'],
                              description='start robot_state_publisher and RViz (the robot, '
                                          'the goal and the measured pose)'),
        Node(package='quat_jt_controller', executable='wrist_sim_node', name='wrist_sim',
             output='screen', emulate_tty=True, namespace=namespace,
             remappings=CLOCK_IN_NAMESPACE, condition=UnlessCondition(composed),
             on_exit=shutdown_when_exits('the simulator exited'),
             parameters=[sim_config, {'use_gui': overrides['use_gui'],
                                      'publish_robot_description':
                                      overrides['publish_robot_description']}]),
        Node(package='quat_jt_controller', executable='controller_node',
             name='quat_jt_controller', output='screen', emulate_tty=True, namespace=namespace,
             remappings=CLOCK_IN_NAMESPACE,
             condition=UnlessCondition(composed),
             on_exit=shutdown_when_exits('the controller exited'),
             parameters=[controller_config, {'potential': overrides['potential']}]),
        # Composed: one process holds both nodes (their own names: no name= here, which would
        # rename both); each takes the parameters it declares from both files.
        Node(package='quat_jt_controller', executable='composed', output='screen',
             emulate_tty=True, namespace=namespace, remappings=CLOCK_IN_NAMESPACE,
             condition=IfCondition(composed),
             on_exit=shutdown_when_exits('the composed process exited'),
             parameters=[sim_config, controller_config, overrides]),
        *live_view(share, wrist_urdf, 'base_link', namespace, rviz),
    ])
