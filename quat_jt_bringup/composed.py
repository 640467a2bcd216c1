"""
The simulator and the controller in one process, on one executor: the composed mode.

The rclpy counterpart of a component container: the same two nodes, ``wrist_sim`` and
``quat_jt_controller``, built in one process and spun by one EventsExecutor, which the
simulator's stepping loop drives. A state is answered within the same thread, with no process
switch between the two, so the loop is faster and steadier than across processes, and in
lockstep (``publish_clock``) the experiment runs several times faster than real time.

    ros2 run quat_jt_controller composed --ros-args --params-file <share>/config/wrist_sim.yaml
        --params-file <share>/config/wrist_controller.yaml  (one line)

or ``ros2 launch quat_jt_controller wrist_demo.launch.py composed:=true``. The config files
are keyed ``/**``: each node takes the parameters it declares and ignores the others.
"""
from typing import Optional

from quat_jt_controller.control_law import GainsError
from quat_jt_controller.controller_node import QuatJtController
from quat_jt_controller.model import ModelError
from quat_jt_runtime import lifecycle
from wrist_sim.sim_node import WristSimNode
from wrist_sim.simulator import SimulatorError

NAME = 'composed'


def make_nodes() -> tuple[WristSimNode, QuatJtController]:
    """
    Build the simulator, then the controller (the simulator is destroyed if that fails).

    The controller runs no throwaway tick (``prewarm_lead``) here: in one process its caches
    stay warm, and the throwaway tick cost 8 points of CPU for no fewer missed ticks.
    """
    sim = WristSimNode()
    try:
        return sim, QuatJtController(prewarm=False)  # one process: its caches stay warm
    except BaseException:
        sim.destroy_node()
        raise


def main(args: Optional[list[str]] = None) -> None:
    """``ros2 run quat_jt_controller composed``."""
    lifecycle.run_node(make_nodes, NAME,
                       (SimulatorError, ModelError, GainsError, ValueError, FileNotFoundError),
                       lambda nodes, executor, keep_running: nodes[0].run(executor,
                                                                          keep_running), args)


if __name__ == '__main__':
    main()
