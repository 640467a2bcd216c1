"""A node of the tools' own on a private domain: its context, its EventsExecutor, teardown."""
from experiments.local_ros import keep_this_process_local
import rclpy
from rclpy.experimental import EventsExecutor


class ProbeNode:
    """
    An rclpy node with its own context on ``domain_id`` (recording, goals, diagnostics).

    Loopback-only, like the nodes it talks to (``local_ros.keep_this_process_local``).
    """

    def __init__(self, name: str, domain_id: int) -> None:
        keep_this_process_local()
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = EventsExecutor(context=self.context)
        self.executor.add_node(self.node)

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)
