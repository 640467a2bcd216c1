"""
The robot description of both nodes, the ROS way: the wait for the topic, and its QoS.

``robot_description_file`` and ``robot_description_topic`` (with its
``robot_description_timeout``) are rows of both nodes' tables (``urdf_source.SOURCES``), beside
``robot_description``; ``urdf_source`` decides which source is meant (at most one; none: the
bundled wrist). The topic is read as ros2_control reads robot_state_publisher's:
``std_msgs/String``, reliable, transient local, depth 1, so a description published before the
node subscribed still arrives. The node waits for it in its constructor, before it builds its
model, on an executor of its own (no other callback exists yet), with a log line saying what it
waits for, and a Ctrl-C or the timeout ends the wait.
"""
import time

from quat_jt_runtime import shutdown_signals
from quat_jt_runtime import urdf_source
from quat_jt_runtime.urdf_source import Description, DescriptionError, Source
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

# Latched, as robot_state_publisher's /robot_description: the last message kept for late
# subscribers (the robot description, the controller's goal).
LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
WAIT_LOG_PERIOD_S = 5.0  # while waiting: a line this often, with the publishers seen


def robot_description(node: Node, values: dict) -> Description:
    """
    Return the URDF the declared ``values`` name (``robot_description``, ``SOURCES``' rows).

    A topic is waited for here (:func:`wait_for_description`). Raises DescriptionError saying
    what is wrong (two sources, an unreadable file, nothing on the topic in time).
    """
    choice = urdf_source.choose(values['robot_description'], values['robot_description_file'],
                                values['robot_description_topic'])
    if choice.source is not Source.TOPIC:
        return urdf_source.resolve_offline(choice)
    return wait_for_description(node, choice.value, float(values['robot_description_timeout']))


def wait_for_description(node: Node, topic: str, timeout_s: float) -> Description:
    """
    Wait for the URDF on ``topic`` (transient local); raise DescriptionError after timeout_s.

    Spins ``node`` on an executor of its own until the first non-empty message; a Ctrl-C
    (the process's stop flag) raises KeyboardInterrupt, a clean stop for ``run_node``.
    """
    received: list[str] = []
    sub = node.create_subscription(String, topic, lambda msg: received.append(msg.data)
                                   if msg.data.strip() else None, LATCHED_QOS)
    name = sub.topic_name
    log = node.get_logger()
    log.info(f'waiting up to {timeout_s:g} s for the robot description on {name} '
             '(std_msgs/String, transient local, as robot_state_publisher publishes it; '
             'robot_description_topic)')
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    start = time.monotonic()
    next_log = start + WAIT_LOG_PERIOD_S
    try:
        while not received and node.context.ok():
            now = time.monotonic()
            if shutdown_signals.requested():
                raise KeyboardInterrupt
            if now >= start + timeout_s:
                break
            if now >= next_log:
                next_log += WAIT_LOG_PERIOD_S
                log.info(f'still waiting for the robot description on {name} '
                         f'({node.count_publishers(name)} publishers)')
            executor.spin_once(timeout_sec=min(0.1, start + timeout_s - now))
    finally:
        executor.remove_node(node)
        executor.shutdown(timeout_sec=0.0)
        node.destroy_subscription(sub)
    if not received:
        publishers = node.count_publishers(name) if node.context.ok() else 0
        why = (f'{publishers} publisher(s), none of which sent it (a publisher that is not '
               'transient local only reaches the subscribers present when it publishes)'
               if publishers else 'no publisher')
        raise DescriptionError(
            f'no robot description on {name} within robot_description_timeout '
            f'{timeout_s:g} s ({why}): start robot_state_publisher (or wrist_sim_node) with '
            'the URDF, remap the topic, or pass the file instead: -p '
            'robot_description_file:=/path/robot.urdf')
    log.info(f'robot description received on {name} ({len(received[-1])} characters)')
    return Description(received[-1], Source.TOPIC, name)


def publish_description(node: Node, xml: str, topic: str = 'robot_description'):
    """Publish ``xml`` once on ``topic``, transient local (kept for late subscribers)."""
    publisher = node.create_publisher(String, topic, LATCHED_QOS)
    publisher.publish(String(data=xml))
    return publisher
