"""
What the demo launch files (``launch/*.launch.py``) share: the exit rule and the live view.

- :func:`shutdown_when_exits`: ``on_exit`` of each node the demo cannot run without. If the
  node exits on its own (a simulator that cannot open its window, say), the whole launch shuts
  down, with the reason logged once. If it exits because the launch is already shutting down
  (Ctrl-C, or the other node's exit), nothing more: launch's ``Shutdown`` action would log
  "process[...] was required: shutting down launched system" again for every such node.
- :func:`gui_and_namespace_arguments`: the ``use_gui`` and ``namespace`` arguments.
- :func:`live_view`: with ``rviz:=true``, robot_state_publisher (the URDF as its parameter,
  ``/tf`` from the simulator's ``joint_states``) and RViz with the shipped
  ``rviz/quat_jt.rviz``: the robot, the controller's ``~/goal_pose`` and ``~/current_pose``.
  robot_state_publisher publishes ``robot_description`` then, so the launch files turn the
  simulator's own publication off (``publish_robot_description``).

launch and launch_ros are imported inside the functions: the module imports without them.
"""
import os
from typing import Any, Callable, Optional

# /clock is absolute (rclpy's time source subscribes to it): remapped to the relative 'clock',
# it becomes <namespace>/clock, so two robots in lockstep (publish_clock) keep their own time.
CLOCK_IN_NAMESPACE = [('/clock', 'clock')]
RVIZ_CONFIG = os.path.join('rviz', 'quat_jt.rviz')
# The RViz config names absolute topics; in a namespace, RViz reads the namespace's own.
RVIZ_TOPICS = ('/robot_description', '/quat_jt_controller/goal_pose',
               '/quat_jt_controller/current_pose')
RVIZ_IN_NAMESPACE = [(topic, topic.lstrip('/')) for topic in RVIZ_TOPICS]


def gui_and_namespace_arguments() -> list:
    """Return the launch arguments every demo takes: ``use_gui`` and ``namespace``."""
    from launch.actions import DeclareLaunchArgument
    return [
        DeclareLaunchArgument('use_gui', default_value='false', choices=['true', 'false'],
                              description='open the PyBullet window of the simulator'),
        DeclareLaunchArgument('namespace', default_value='',
                              description='namespace of both nodes, their topics and their '
                                          'simulated clock, e.g. left (one robot per '
                                          'namespace)'),
    ]


def shutdown_when_exits(reason: str) -> Callable[[Any, Any], Optional[list]]:
    """Return an ``on_exit`` that shuts the launch down unless it is shutting down already."""
    def on_exit(event: Any, context: Any) -> Optional[list]:
        if context.is_shutdown:  # set by Ctrl-C and by the first Shutdown alike
            return None
        from launch.actions import Shutdown
        return [Shutdown(reason=reason)]
    return on_exit


def live_view(share: str, urdf_xml: str, fixed_frame: str, namespace: Any,
              rviz: Any) -> list:
    """
    Return robot_state_publisher and RViz, started when ``rviz`` (a launch argument) is true.

    ``fixed_frame`` is the robot's base link (RViz's fixed frame, the frame of the goal and
    the measured pose).
    """
    from launch.conditions import IfCondition
    from launch_ros.actions import Node
    from launch_ros.parameter_descriptions import ParameterValue
    return [
        Node(package='robot_state_publisher', executable='robot_state_publisher',
             output='screen', namespace=namespace, condition=IfCondition(rviz),
             parameters=[{'robot_description': ParameterValue(urdf_xml, value_type=str)}]),
        Node(package='rviz2', executable='rviz2', output='screen', namespace=namespace,
             condition=IfCondition(rviz), remappings=RVIZ_IN_NAMESPACE,
             arguments=['-d', os.path.join(share, RVIZ_CONFIG), '-f', fixed_frame]),
    ]


def publish_robot_description(rviz: Any) -> Any:
    """Return the simulator's ``publish_robot_description``: off when RViz's view is on."""
    from launch.substitutions import NotSubstitution
    from launch_ros.parameter_descriptions import ParameterValue
    return ParameterValue(NotSubstitution(rviz), value_type=bool)
