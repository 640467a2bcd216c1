"""
What the controller reports: the feedback topics and ``/diagnostics`` (ROS marshalling).

:class:`Feedback` publishes ``~/current_pose``, ``~/orientation_error`` and, for the pose and
position tasks, ``~/position_error``; :class:`GoalPose` the goal in force on ``~/goal_pose``;
:class:`Diagnostics` turns the figures of the ROS-free builders
(``controller.py``, ``diagnostics.py``) into ``/diagnostics`` and warns of a second commander on
the robot.
"""
import time
from typing import Callable, Optional, Sequence

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, Vector3Stamped
from quat_jt_controller import diagnostics
from quat_jt_controller import quaternion as quat
from quat_jt_controller.controller import Controller
from quat_jt_controller.regulator import Goal, TickOutput
from quat_jt_runtime.description import LATCHED_QOS
from quat_jt_runtime.loop_stats import TickStats
from quat_jt_runtime.messages import diagnostic_array
from quat_jt_runtime.throttle import cause, Throttle
from rcl_interfaces.msg import ParameterType
from rcl_interfaces.srv import GetParameters
from rclpy.exceptions import InvalidServiceNameException
from rclpy.node import Node


class Feedback:
    """
    Publishers of the measured pose and the errors, with their messages built once.

    ``~/current_pose`` (PoseStamped), ``~/orientation_error`` (e, the last three rows of
    y_tilde; zeros for the position task, which has no orientation error) and, for the pose and
    position tasks, ``~/position_error`` (p_d - p), all in ``base_link``.
    """

    def __init__(self, node: Node, base_link: str, with_position: bool) -> None:
        self._pose, self._e_o, self._e_p = PoseStamped(), Vector3Stamped(), Vector3Stamped()
        for msg in (self._pose, self._e_o, self._e_p):
            msg.header.frame_id = base_link
        self._pose_pub = node.create_publisher(PoseStamped, '~/current_pose', 10)
        self._e_o_pub = node.create_publisher(Vector3Stamped, '~/orientation_error', 10)
        self._e_p_pub = (node.create_publisher(Vector3Stamped, '~/position_error', 10)
                         if with_position else None)

    def publish(self, stamp, out: TickOutput, q_tip_base: Sequence[float]) -> None:
        """Publish one sample; ``q_tip_base``: the measured orientation, scalar first."""
        pose = self._pose
        pose.header.stamp = stamp
        pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = out.p_tip_base
        o = pose.pose.orientation
        o.x, o.y, o.z, o.w = quat.to_xyzw(q_tip_base)
        self._pose_pub.publish(pose)
        self._e_o.header.stamp = stamp
        self._e_o.vector.x, self._e_o.vector.y, self._e_o.vector.z = out.orientation_error
        self._e_o_pub.publish(self._e_o)
        if self._e_p_pub is not None:
            self._e_p.header.stamp = stamp
            v = self._e_p.vector
            v.x, v.y, v.z = out.y_tilde[0], out.y_tilde[1], out.y_tilde[2]
            self._e_p_pub.publish(self._e_p)


class GoalPose:
    """
    ``~/goal_pose`` (PoseStamped in ``base_link``, latched): the goal in force, for RViz.

    Published when the goal changes (the first measured pose held, a goal accepted, a link
    goal placed in the base), from a timer, never from the tick; a stream of goals is sampled
    at that timer's rate. Transient local, so a viewer started later gets the goal in force.
    The orientation task's goal has no position: it is drawn at ``anchor_m``, the tip's
    position measured when the goal took force.
    """

    def __init__(self, node: Node, base_link: str, with_position: bool) -> None:
        self._node = node
        self._with_position = with_position
        self._msg = PoseStamped()
        self._msg.header.frame_id = base_link
        self._pub = node.create_publisher(PoseStamped, '~/goal_pose', LATCHED_QOS)
        self._published: Optional[Goal] = None

    def update(self, goal: Optional[Goal], anchor_m: Optional[Sequence[float]]) -> None:
        """Publish ``goal`` if it is not the one published last."""
        if goal is None or goal == self._published:
            return
        msg = self._msg
        msg.header.stamp = self._node.get_clock().now().to_msg()
        position = (goal.p_desired_base if self._with_position or anchor_m is None
                    else anchor_m)
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = position
        o = msg.pose.orientation
        o.x, o.y, o.z, o.w = goal.xyzw()
        self._pub.publish(msg)
        self._published = goal


class Diagnostics:
    """
    ``/diagnostics`` of the controller: the loop, the goal and the stall, one array a second.

    The statuses are the :class:`~quat_jt_controller.controller.Controller`'s (built when
    published, never in the tick's computation); the loop's figures are ``stats``' window.
    The ROS graph is read only by :meth:`check_graph`, on a timer, never in the state
    callback (a graph query can block for milliseconds while DDS discovers a process): a
    second commander on the command topic, or a second node of the same name, is warned of
    every 10 s while it lasts and reported in the next arrays.
    """

    def __init__(self, node: Node, hardware_id: str, command_topic: str,
                 controller: Controller, stats: TickStats) -> None:
        self._node = node
        self._hardware_id = hardware_id
        self._command_topic = command_topic
        self._controller, self._stats = controller, stats
        self._pub = node.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self._name = node.get_fully_qualified_name().lstrip('/')  # one topic for the graph
        self._graph_log = Throttle(10.0)
        self._graph_warnings: list[str] = []
        self._window_start_ns = time.monotonic_ns()

    def publish(self) -> None:
        """Publish the loop's figures since the last call, the goal's state and the stall's."""
        now = time.monotonic_ns()
        figures = self._stats.window((now - self._window_start_ns) * 1e-9)
        self._window_start_ns = now
        statuses = self._controller.statuses(figures, self._graph_warnings)
        self._pub.publish(diagnostic_array(self._name, self._hardware_id, statuses,
                                           self._node.get_clock().now().to_msg()))

    def check_graph(self) -> None:
        """Read the graph: warn of a second commander or a second node of this name."""
        node = self._node
        me = (node.get_name(), node.get_namespace())
        warnings = diagnostics.graph_warnings(
            self._command_topic, node.count_publishers(self._command_topic),
            node.get_fully_qualified_name(),
            sum(1 for other in node.get_node_names_and_namespaces() if tuple(other) == me))
        for warning in warnings:
            if self._graph_log(cause(warning)) is not None:
                node.get_logger().warn(warning)
        self._graph_warnings = warnings


class CommandReceivers:
    """
    Ask each node that subscribes to the command topic which joints it applies them to.

    A command is one torque per joint in the controller's ``joints`` order; ros2_control's
    JointGroupEffortController (and the simulator) apply the i-th torque to the i-th of their
    own ``joints`` parameter. :meth:`check` runs on the graph timer, never in the state
    callback: it lists the topic's subscribers and asks each for its ``joints`` (one
    GetParameters client per node, its answer in a callback), again at every check: a
    controller reloaded under the same name between two checks may list other joints now. A
    node without that parameter, or without parameter services (a recorder,
    ``ros2 topic echo``), has nothing to check. ``on_change`` gets the problems
    (``diagnostics.command_order_problem``) whenever they change, and a receiver that agrees is
    logged when it first does.
    """

    def __init__(self, node: Node, command_topic: str, joints: Sequence[str],
                 on_change: Callable[[list[str]], None]) -> None:
        self._node, self._topic, self._joints = node, command_topic, tuple(joints)
        self._on_change = on_change
        self._clients: dict[str, object] = {}  # receiver -> its GetParameters client (or None)
        self._pending: set[str] = set()  # ... asked, its answer not in yet
        self._problems: dict[str, str] = {}  # ... its last answer: '' where its joints agree
        # or it has none

    def check(self) -> None:
        """Read the topic's subscribers; ask each whose last answer is in; forget the gone."""
        node = self._node
        here = {_full_name(info.node_namespace, info.node_name)
                for info in node.get_subscriptions_info_by_topic(self._topic)}
        for name in here - set(self._clients):
            try:
                self._clients[name] = node.create_client(GetParameters,
                                                         f'{name}/get_parameters')
            except InvalidServiceNameException:  # a reader the graph names oddly (not ROS)
                self._clients[name] = None
        for name, client in self._clients.items():
            if (name in here and name not in self._pending and client is not None
                    and client.service_is_ready()):
                self._pending.add(name)
                request = GetParameters.Request(names=['joints'])
                client.call_async(request).add_done_callback(
                    lambda future, name=name: self._answered(name, future))
        gone = set(self._clients) - here
        for name in gone:
            client = self._clients.pop(name)
            if client is not None:
                node.destroy_client(client)
            self._pending.discard(name)
        if gone & set(self._problems):
            for name in gone:
                self._problems.pop(name, None)
            self._report()

    def _answered(self, name: str, future) -> None:
        """Compare a receiver's ``joints`` with the controller's."""
        self._pending.discard(name)
        response = future.result() if future.done() and not future.cancelled() else None
        if response is None or name not in self._clients or len(response.values) != 1:
            return  # no answer: asked again at the next check
        value = response.values[0]
        if value.type != ParameterType.PARAMETER_STRING_ARRAY:
            problem = ''  # no joints parameter: not a receiver this check knows
        else:
            problem = diagnostics.command_order_problem(self._joints, name,
                                                        value.string_array_value)
            if not problem and self._problems.get(name) != '':
                self._node.get_logger().info(
                    f'{name} applies the commands to joints {list(value.string_array_value)}, '
                    "this controller's joints in its order")
        changed = self._problems.get(name) != problem
        self._problems[name] = problem
        if changed:
            self._report()

    def _report(self) -> None:
        self._on_change([p for p in self._problems.values() if p])


def _full_name(namespace: str, name: str) -> str:
    """Return a node's fully qualified name from its namespace and name."""
    return (namespace.rstrip('/') + '/' + name) if namespace else '/' + name
