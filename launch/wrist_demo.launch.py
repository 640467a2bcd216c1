"""
The wrist demo: the simulated spherical wrist and the transpose-Jacobian regulator.

    ros2 launch quat_jt_controller wrist_demo.launch.py [potential:=tanh|quadratic]
                                                      [use_gui:=true|false]

The nodes read their parameters from this package's ``config/wrist_sim.yaml`` and
``config/wrist_controller.yaml`` (gains from the robot with the issue-10 extensions;
``config/paper_wrist_controller.yaml`` is the paper's experiment; the xarm6_*.yaml files in the
same folder are for another robot, so they are not loaded here);
``potential`` overrides the controller's, ``use_gui`` opens the PyBullet window. Then send a
goal, e.g. the paper's corrected one (docs/errata.md, note 2):

    ros2 topic pub --once /quat_jt_controller/target_pose geometry_msgs/msg/PoseStamped \
      "{header: {frame_id: base_link},
        pose: {orientation: {x: 0.0, y: 0.4226, z: 0.7152, w: 0.5566}}}"
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue


def generate_launch_description() -> LaunchDescription:
    share = get_package_share_directory('quat_jt_controller')
    sim_config = os.path.join(share, 'config', 'wrist_sim.yaml')
    controller_config = os.path.join(share, 'config', 'wrist_controller.yaml')
    potential = LaunchConfiguration('potential')
    use_gui = LaunchConfiguration('use_gui')
    return LaunchDescription([
        DeclareLaunchArgument('potential', default_value='tanh',
                              choices=['tanh', 'quadratic'],
                              description="controller potential: 'tanh' (Eq. 38) or "
                                          "'quadratic' (Eq. 37)"),
        DeclareLaunchArgument('use_gui', default_value='false', choices=['true', 'false'],
                              description='open the PyBullet window of the simulator'),
        Node(package='quat_jt_controller', executable='wrist_sim_node', name='wrist_sim',
             output='screen', emulate_tty=True,
             parameters=[sim_config, {'use_gui': ParameterValue(use_gui, value_type=bool)}]),
        Node(package='quat_jt_controller', executable='controller_node',
             name='quat_jt_controller', output='screen', emulate_tty=True,
             parameters=[controller_config,
                         {'potential': ParameterValue(potential, value_type=str)}]),
    ])
