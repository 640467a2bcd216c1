"""
Any arm from its URDF: the simulator and the controller, with the two files design_gains writes.

    ros2 run quat_jt_controller design_gains --urdf arm.urdf --task pose \
        --out arm_controller.yaml --sim-out arm_sim.yaml [--sim-engine mujoco] [--armature 0.1]
    ros2 launch quat_jt_controller arm_demo.launch.py urdf:=arm.urdf \
        controller_params:=arm_controller.yaml sim_params:=arm_sim.yaml
                                                       [use_gui:=true|false]
                                                       [namespace:=left]

``design_gains`` picks the chain (the URDF's root link to the end of its longest chain of revolute
or continuous joints, or ``--base-link`` / ``--tip-link``), the gains and the simulator's start
(docs/gain_design.md). Both nodes read the URDF from ``urdf`` (their ``robot_description_file``;
meshes are looked for as docs/ros.md says, and the dynamics need none). The simulator node is named
``arm_sim``, the controller ``quat_jt_controller``; if either exits on its own, the whole launch
shuts down. The arm starts at rest where ``--initial-positions`` put it (the middle of its ranges
by default) and holds there until a goal arrives on ``/quat_jt_controller/target_pose`` (under
``namespace``, if given), in the base link of the design; ``/diagnostics`` says whether the goal is
reachable. ``use_gui:=true`` opens the PyBullet window (``engine: pybullet`` only). On a real arm
driven by ros2_control, run ``controller_node`` alone with the controller file (docs/ros.md, "On a
real robot").
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from quat_jt_bringup.launch_parts import CLOCK_IN_NAMESPACE, gui_and_namespace_arguments
from quat_jt_bringup.launch_parts import shutdown_when_exits


def generate_launch_description() -> LaunchDescription:
    urdf = LaunchConfiguration('urdf')
    namespace = LaunchConfiguration('namespace')
    return LaunchDescription([
        DeclareLaunchArgument('urdf', description="the arm's URDF file (required)"),
        DeclareLaunchArgument('controller_params',
                              description="the controller's parameter file: design_gains "
                                          '--out (required)'),
        DeclareLaunchArgument('sim_params',
                              description="the simulator's parameter file: design_gains "
                                          '--sim-out (required)'),
        *gui_and_namespace_arguments(),
        Node(package='quat_jt_controller', executable='wrist_sim_node', name='arm_sim',
             output='screen', emulate_tty=True, namespace=namespace,
             remappings=CLOCK_IN_NAMESPACE,
             on_exit=shutdown_when_exits('the simulator exited'),
             parameters=[LaunchConfiguration('sim_params'),
                         {'robot_description_file': urdf,
                          'use_gui': ParameterValue(LaunchConfiguration('use_gui'),
                                                    value_type=bool)}]),
        Node(package='quat_jt_controller', executable='controller_node',
             name='quat_jt_controller', output='screen', emulate_tty=True, namespace=namespace,
             remappings=CLOCK_IN_NAMESPACE,
             on_exit=shutdown_when_exits('the controller exited'),
             parameters=[LaunchConfiguration('controller_params'),
                         {'robot_description_file': urdf}]),
    ])
