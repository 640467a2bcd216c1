"""
How this package's nodes start and stop: one idiom for ``main()``.

rclpy's default SIGINT handler shuts the context down at once, even while a callback is running,
so a callback that was about to publish fails with "publisher's context is invalid" and the
process exits with an error. Here SIGINT and SIGTERM only set a flag; the node's loop checks it
between callbacks, then the node is destroyed and the context shut down, in that order.
"""
import gc
import signal
from typing import Callable, Optional

from quat_jt_controller import realtime
import rclpy
from rclpy.signals import SignalHandlerOptions


class StopFlag:
    """Set by SIGINT / SIGTERM; the spin loop ends then."""

    def __init__(self) -> None:
        self.is_set = False
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, self._on_signal)

    def _on_signal(self, signum: int, frame: object) -> None:
        self.is_set = True

    def __call__(self) -> bool:
        """Return True while the node should keep running."""
        return not self.is_set


def init(args: Optional[list[str]] = None) -> StopFlag:
    """``rclpy.init`` without rclpy's signal handlers, and a StopFlag in their place."""
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    return StopFlag()


def spin(executor, context: rclpy.Context, keep_running: Callable[[], bool],
         period_s: float = 0.1) -> None:
    """Spin ``executor`` until ``keep_running()`` is false or ``context`` is shut down."""
    ok = realtime.RunCheck(keep_running, context.ok)
    while ok():
        executor.spin_once(timeout_sec=period_s)


def pin(nodes: list) -> None:
    """
    Pin the process to the CPUs its nodes ask for (``cpu_affinity``), once all are built.

    Composed nodes share the process: it is pinned to the union of their CPUs.
    """
    cpus = sorted({c for node in nodes for c in getattr(node, 'cpu_affinity', ())})
    if cpus:
        pinned = realtime.pin_process(cpus)
        nodes[0].get_logger().info(f'process pinned to CPUs {list(pinned)} (cpu_affinity)')


def run_node(make_node: Callable[[], object], name: str, startup_errors: tuple,
             run: Callable[[object, object, Callable[[], bool]], None],
             args: Optional[list[str]] = None) -> None:
    """
    Run a node of this package: its ``main()``, the Jazzy way.

    Build the node, or a tuple of nodes sharing the process (``startup_errors`` exit with
    status 1 and a FATAL line saying why), add it to one EventsExecutor, pin the process to the
    nodes' ``cpu_affinity`` (if set), freeze what is built so far from the garbage collector,
    then ``run(node, executor, keep_running)``. On the way
    out (Ctrl-C, SIGTERM, an external shutdown) the nodes are destroyed, last built first,
    before the context is shut down.
    """
    from rclpy.exceptions import ParameterException
    from rclpy.executors import ExternalShutdownException
    from rclpy.experimental import EventsExecutor

    keep_running = init(args)
    nodes: list = []
    try:
        try:
            node = make_node()
        except (*startup_errors, ParameterException) as exc:  # e.g. a parameter's wrong type
            rclpy.logging.get_logger(name).fatal(f'cannot start: {exc}')
            raise SystemExit(1) from None
        nodes = list(node) if isinstance(node, tuple) else [node]
        executor = EventsExecutor(context=nodes[0].context)
        for each in nodes:
            executor.add_node(each)
        pin(nodes)
        # What is built so far lives as long as the node: keep the cyclic garbage collector
        # from rescanning it during the 1 kHz loop.
        gc.collect()
        gc.freeze()
        run(node, executor, keep_running)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        for each in reversed(nodes):
            each.destroy_node()
        rclpy.try_shutdown()
