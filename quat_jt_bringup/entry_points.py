"""
The console scripts (``ros2 run quat_jt_controller <name>``): the stop flag first, then the node.

Each entry point installs :func:`shutdown_signals.install` before it imports its node module,
so a Ctrl-C during the seconds of start-up (rclpy, Pinocchio, PyBullet, the URDF) is a clean
stop, not a KeyboardInterrupt traceback from inside an import. ``python -m
quat_jt_bringup.entry_points <name> [args]`` runs the same thing (the tests' way).
"""
import sys

from quat_jt_runtime import shutdown_signals


def controller_node() -> None:
    """``ros2 run quat_jt_controller controller_node``."""
    shutdown_signals.install()
    from quat_jt_controller.controller_node import main
    main()


def wrist_sim_node() -> None:
    """``ros2 run quat_jt_controller wrist_sim_node``."""
    shutdown_signals.install()
    from wrist_sim.sim_node import main
    main()


def composed() -> None:
    """``ros2 run quat_jt_controller composed``."""
    shutdown_signals.install()
    from quat_jt_bringup.composed import main
    main()


ENTRY_POINTS = {'controller_node': controller_node, 'wrist_sim_node': wrist_sim_node,
                'composed': composed}

if __name__ == '__main__':
    shutdown_signals.install()
    if len(sys.argv) < 2 or sys.argv[1] not in ENTRY_POINTS:
        sys.exit(f'usage: python -m quat_jt_bringup.entry_points '
                 f'{{{",".join(ENTRY_POINTS)}}} [--ros-args ...]')
    name = sys.argv.pop(1)
    ENTRY_POINTS[name]()
