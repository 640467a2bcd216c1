"""
The console scripts (``ros2 run quat_jt_controller <name>``): the stop flag first, then the node.

Each entry point installs :func:`shutdown_signals.install` before it imports its node module,
so a Ctrl-C during the seconds of start-up (rclpy, Pinocchio, PyBullet, the URDF) is a clean
stop, not a KeyboardInterrupt traceback from inside an import. ``python -m
quat_jt_bringup.entry_points <name> [args]`` runs the same thing (the tests' way).

``-h`` or ``--help`` before any ``--ros-args`` prints what the executable is and how to give it
parameters, then exits with status 0: no node, no rclpy.
"""
import sys
from typing import Optional

from quat_jt_runtime import shutdown_signals

_ROS_ARGS = """\
Parameters, remappings and the rest come after --ros-args, the ROS 2 way:
  --params-file FILE     a parameter file (the package's are in {share}/config)
  -p NAME:=VALUE         one parameter, e.g. -p "cpu_affinity:=[1]"
  -r FROM:=TO            a remapping, e.g. -r __ns:=/arm or -r joint_states:=/arm/joint_states
Every parameter, its type, range and meaning: {share}/docs/parameters.md, or
`ros2 param describe <node> <name>` on the running node. How to run, command and tune the
nodes, and what they do when something goes wrong: {share}/docs/ros.md.
"""

USAGE = {
    'controller_node': """\
usage: ros2 run quat_jt_controller controller_node [-h] [--ros-args ...]

The transpose-Jacobian regulator with unit-quaternion orientation error (Campa and Kelly,
Eq. 22) as the ROS 2 node quat_jt_controller. Each joint state on joint_states is one tick: it
publishes the joint torques on effort_controller/commands (std_msgs/Float64MultiArray, in
`joints` order) at once. Until a goal arrives on ~/target_pose (geometry_msgs/PoseStamped in
`base_link`) it holds the first pose measured. Feedback: ~/current_pose, ~/orientation_error
(and ~/position_error), /diagnostics.

Main parameters: the robot (robot_description: its URDF, empty = the bundled wrist; joints,
base_link, tip_link; task: orientation or pose), read at start; the gains (potential, kp, kv,
lambda, gravity_compensation) and the extensions, live with `ros2 param set`.

Example: ros2 run quat_jt_controller controller_node --ros-args
           --params-file {share}/config/wrist_controller.yaml
""",
    'wrist_sim_node': """\
usage: ros2 run quat_jt_controller wrist_sim_node [-h] [--ros-args ...]

A fixed-base serial robot (by default the paper's spherical wrist) simulated in PyBullet as
the ROS 2 node wrist_sim, torque driven like a ros2_control robot with a
JointGroupEffortController: it publishes joint_states at rate_hz and applies the torques it
receives on effort_controller/commands (one per joint, N m), holding the joints at rest until
the first one; ~/reset (std_srvs/Trigger) puts it back at initial_positions.

Main parameters: robot_description (its URDF, empty = the bundled wrist), joints,
initial_positions, rate_hz, use_gui (the PyBullet window), publish_clock (lockstep with
/clock), viscous_friction and coulomb_friction (live), command_timeout.

Example: ros2 run quat_jt_controller wrist_sim_node --ros-args
           --params-file {share}/config/wrist_sim.yaml
""",
    'composed': """\
usage: ros2 run quat_jt_controller composed [-h] [--ros-args ...]

The simulator (wrist_sim) and the controller (quat_jt_controller) as two nodes in one process
on one executor, the rclpy counterpart of a component container: the same names, topics,
parameters and services as wrist_sim_node and controller_node (see their --help), with no
process switch between a state and its command. Give both nodes' parameter files; each node
takes the parameters it declares.

Example: ros2 run quat_jt_controller composed --ros-args
           --params-file {share}/config/wrist_sim.yaml
           --params-file {share}/config/wrist_controller.yaml
""",
}


def _share() -> str:
    """Return the package's share folder (its config/ and docs/), or where it would be."""
    from quat_jt_runtime.resources import share_path
    try:
        return str(share_path('package.xml').parent)
    except FileNotFoundError:
        return '<prefix>/share/quat_jt_controller'


def help_asked(argv: list[str]) -> bool:
    """Tell whether ``-h`` or ``--help`` comes before any ``--ros-args`` (ROS's own)."""
    own = argv[:argv.index('--ros-args')] if '--ros-args' in argv else argv
    return '-h' in own or '--help' in own


def print_help(name: str, argv: Optional[list[str]] = None) -> bool:
    """Print ``name``'s usage if it was asked for (``argv``: sys.argv[1:]); tell whether."""
    if not help_asked(sys.argv[1:] if argv is None else argv):
        return False
    share = _share()
    sys.stdout.write(USAGE[name].format(share=share) + '\n' + _ROS_ARGS.format(share=share))
    return True


def controller_node() -> None:
    """``ros2 run quat_jt_controller controller_node``."""
    shutdown_signals.install()
    if print_help('controller_node'):
        return
    from quat_jt_controller.controller_node import main
    main()


def wrist_sim_node() -> None:
    """``ros2 run quat_jt_controller wrist_sim_node``."""
    shutdown_signals.install()
    if print_help('wrist_sim_node'):
        return
    from wrist_sim.sim_node import main
    main()


def composed() -> None:
    """``ros2 run quat_jt_controller composed``."""
    shutdown_signals.install()
    if print_help('composed'):
        return
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
