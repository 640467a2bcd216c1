"""
How this package's nodes start and stop: one idiom for ``main()``.

rclpy's default SIGINT handler shuts the context down at once, even while a callback is running,
so a callback that was about to publish fails with "publisher's context is invalid" and the
process exits with an error. Here SIGINT and SIGTERM only set a flag (``shutdown_signals``,
installed by the entry points before any slow import, and kept to the end, so a second signal
during shutdown changes nothing); the node's loop checks it between callbacks, then the node is
destroyed and the context shut down, in that order, and the process exits with status 0.
"""
import gc
import os
from typing import Callable, Optional

from quat_jt_runtime import dds_transport
from quat_jt_runtime import realtime
from quat_jt_runtime import shutdown_signals
from quat_jt_runtime.resources import share_path
import rclpy
from rclpy.signals import SignalHandlerOptions


def init(args: Optional[list[str]] = None) -> tuple[shutdown_signals.StopFlag, str]:
    """
    ``rclpy.init`` without rclpy's signal handlers; the process's StopFlag in their place.

    The DDS transport is chosen first (:func:`dds_transport.choose`: UDP, not shared memory);
    returns the StopFlag and the line that says which transport.
    """
    keep_running = shutdown_signals.install()  # already there if started by an entry point
    transport = dds_transport.choose(os.environ, share_path)
    os.environ.update(transport.changes)  # read by rmw_fastrtps when rclpy.init creates it
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    return keep_running, transport.note


def spin(executor, context: rclpy.Context, keep_running: Callable[[], bool],
         period_s: float = 0.1) -> None:
    """Spin ``executor`` until ``keep_running()`` is false or ``context`` is shut down."""
    ok = realtime.RunCheck(keep_running, context.ok)
    while ok():
        executor.spin_once(timeout_sec=period_s)


def apply_realtime(nodes: list) -> None:
    """
    Apply the nodes' real-time settings (``realtime``: ``params.Realtime``), once all are built.

    The process is pinned to the CPUs they ask for (``cpu_affinity``) and its threads run at
    the highest of their ``thread_priority``, unless a node's mode needs normal scheduling
    (its ``off_reason``: then no thread is raised, composed nodes included). A priority that is
    refused is a warning, not an error: the node runs with normal scheduling.
    """
    settings = [node.realtime for node in nodes if getattr(node, 'realtime', None) is not None]
    logger = nodes[0].get_logger()
    cpus = sorted({c for s in settings for c in s.cpus})
    if cpus:
        pinned = realtime.pin_process(cpus)
        logger.info(f'process pinned to CPUs {list(pinned)} (cpu_affinity)')
    priority = max((s.thread_priority for s in settings), default=0)
    off = sorted({s.off_reason for s in settings if s.off_reason})
    if priority and off:
        logger.info(f'thread_priority {priority}: off ({", ".join(off)}): normal scheduling')
    elif priority:
        refused = realtime.set_thread_priority(priority)
        if refused:
            logger.warning(f'thread_priority {priority}: {refused}; running with normal '
                           'scheduling (thread_priority: 0 says so without this warning)')
        else:
            logger.info(f'every thread at SCHED_FIFO priority {priority} (thread_priority)')


def run_node(make_node: Callable[[], object], name: str, startup_errors: tuple,
             run: Callable[[object, object, Callable[[], bool]], None],
             args: Optional[list[str]] = None) -> None:
    """
    Run a node of this package: its ``main()``, the Jazzy way.

    Build the node, or a tuple of nodes sharing the process (``startup_errors`` exit with
    status 1 and a FATAL line saying why), add it to one EventsExecutor, apply the nodes'
    real-time settings (:func:`apply_realtime`), freeze what is built so far from the garbage
    collector, then ``run(node, executor, keep_running)``. On the way
    out (Ctrl-C, SIGTERM, an external shutdown) the nodes are destroyed, last built first,
    before the context is shut down.
    """
    from rclpy.exceptions import ParameterException
    from rclpy.executors import ExternalShutdownException
    from rclpy.experimental import EventsExecutor

    keep_running, transport_note = init(args)
    nodes: list = []
    try:
        try:
            node = make_node()
        except (*startup_errors, ParameterException) as exc:  # e.g. a parameter's wrong type
            rclpy.logging.get_logger(name).fatal(f'cannot start: {exc}')
            raise SystemExit(1) from None
        nodes = list(node) if isinstance(node, tuple) else [node]
        nodes[0].get_logger().info(transport_note)
        executor = EventsExecutor(context=nodes[0].context)
        for each in nodes:
            executor.add_node(each)
        apply_realtime(nodes)
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
        shutdown_signals.ignore_from_now_on()  # a late Ctrl-C: the exit status stays 0
