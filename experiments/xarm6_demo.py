"""
The xArm6 demo goal, without ROS: full pose regulation (Section 4) on the simulator core.

The goal documented in ``launch/xarm6_demo.launch.py`` (the arm's pose at
q = (0.2, -0.4, -1.1, 0.2, 1.4, 0.3) rad, 0.10 m and 0.25 rad from the start), the gains of
``config/xarm6_controller.yaml`` and the start and friction of ``config/xarm6_sim.yaml``. What
runs is NOT the nodes over DDS: it is the sampled loop in one process, the same law (Eq. 24 /
32 with g(q), ``reference_sim.ClosedLoop.torque``) computed from each 1 kHz state of the same
PyBullet simulator (``wrist_sim.simulator.RobotSimulator``: friction, effort limits), applied
in the next step, as the nodes do when every command arrives in time.

For each potential it writes, to ``--out`` (default ``results/xarm6``): an MCAP with
``/joint_states`` and the replay topics (``/robot_description``, ``/tf_static`` with the goal
frame, ``/tf``), an animated GIF and one still frame rendered offscreen after the run, and one
figure: position error, ||e||, joint torques against the effort limits and joint angles against
the position limits.

    python -m experiments.xarm6_demo [--out results/xarm6] [--duration 5]
                                                  [--no-animation]
"""
import argparse
from dataclasses import dataclass
from pathlib import Path
import sys
import time
from typing import Optional

from experiments.mcap_log import cdr_joint_state, McapLog
from experiments.robot_tf import write_robot_replay
import numpy as np
import pybullet_data
from quat_jt_controller import control_law as cl
from quat_jt_controller import quaternion as quat
from quat_jt_controller.controller_config import controller_from_package_config
from quat_jt_controller.inverse_kinematics import goal_configuration
from quat_jt_controller.model import RobotModel
from quat_jt_controller.reference_sim import ClosedLoop
from quat_jt_runtime.resources import config_parameters
from wrist_sim.simulator import RobotSimulator

XARM6_URDF = Path(pybullet_data.getDataPath()) / 'xarm' / 'xarm6_robot.urdf'
# The reachable goal of launch/xarm6_demo.launch.py: the arm's pose at these joint angles.
Q_GOAL_RAD = (0.2, -0.4, -1.1, 0.2, 1.4, 0.3)
POTENTIALS = ('quadratic', 'tanh')
EQUATION = {'quadratic': 'Eq. 24', 'tanh': 'Eq. 32'}
ANIMATION_FPS = 25.0
STILL_AT_S = 0.3


@dataclass
class PoseRun:
    potential: str
    t_s: np.ndarray
    q_rad: np.ndarray
    qdot_rad_s: np.ndarray
    effort_nm: np.ndarray  # applied by the simulator (clamped to the effort limits)
    position_error_m: np.ndarray  # ||p_d - p|| (Eq. 9)
    orientation_error: np.ndarray  # ||e|| (Eq. 10)


def run(potential: str, duration_s: float, urdf_xml: str) -> tuple[PoseRun, RobotModel,
                                                                   tuple, tuple]:
    """Regulate the xArm6 to the goal with ``potential``; return the run, model and goal."""
    simp = config_parameters('xarm6_sim.yaml')
    # the config's gains and extensions, as the node runs them
    regulator = controller_from_package_config('xarm6_controller.yaml', urdf_xml, potential)
    model, gains, shaping = regulator.model, regulator.gains, regulator.shaping
    p_d, R_d = model.forward_kinematics(Q_GOAL_RAD)
    q_d = quat.from_rotation_matrix(R_d)
    # q*, as the node's goal-check worker gives it (docs/lyapunov.md, section 5).
    q_star = (goal_configuration(model, simp['initial_positions'], q_d, p_d, cl.Task.POSE,
                                 shaping.joint_limit_margin_rad)
              if shaping.configuration_on else None)
    loop = ClosedLoop(model, gains, cl.Task.POSE, q_d, p_d, shaping=shaping, q_star=q_star)
    steps = int(round(duration_s * simp['rate_hz']))
    t = np.empty(steps + 1)
    q, qdot, tau = (np.empty((steps + 1, model.n)) for _ in range(3))
    pos, ori = np.empty(steps + 1), np.empty(steps + 1)
    with RobotSimulator(urdf_xml, model.joint_names, dt_s=1.0 / simp['rate_hz'],
                        viscous_nm_s_per_rad=simp['viscous_friction'],
                        coulomb_nm=simp['coulomb_friction'],
                        initial_positions_rad=simp['initial_positions'],
                        enforce_velocity_limits=simp['enforce_velocity_limits'],
                        search_dirs=[pybullet_data.getDataPath()]) as sim:
        applied = np.zeros(model.n)
        for k in range(steps + 1):
            t[k], q[k], qdot[k], tau[k] = sim.time_s, sim.q_rad, sim.qdot_rad_s, applied
            y, _, _ = loop.error(q[k])
            pos[k], ori[k] = np.linalg.norm(y[:3]), np.linalg.norm(y[3:])
            if k < steps:
                applied = sim.step(loop.torque(q[k].tolist(), qdot[k].tolist()))
    goal = (tuple(p_d), q_d)
    return PoseRun(potential, t - t[0], q, qdot, tau, pos, ori), model, goal, R_d


def write_mcap(path: Path, r: PoseRun, model: RobotModel, urdf_xml: str, goal: tuple) -> None:
    """Write the run's /joint_states at 1 kHz and the replay topics to an MCAP file."""
    start_ns = time.time_ns()
    stamps_ns = start_ns + np.round(r.t_s * 1e9).astype(np.int64)
    log = McapLog(path)
    try:
        js = log.channel('/joint_states', 'sensor_msgs/msg/JointState')
        for k, stamp in enumerate(stamps_ns):
            log.write(js, cdr_joint_state(int(stamp), model.joint_names, r.q_rad[k],
                                          r.qdot_rad_s[k], r.effort_nm[k]), int(stamp))
        write_robot_replay(log, urdf_xml, model.joint_names, stamps_ns, stamps_ns, r.q_rad,
                           goal=(model.base_link, goal[0], quat.to_xyzw(goal[1])))
    finally:
        log.close()


def plot(runs: list[PoseRun], model: RobotModel, path: Path) -> None:
    """Position error, ||e||, torques against the effort limits, angles against the limits."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    from experiments.plots import plot_angles, plot_torques

    fig, axes = plt.subplots(3, 2, figsize=(11, 12.6), squeeze=False)
    colors = {'quadratic': 'tab:blue', 'tanh': 'tab:red'}
    for r in runs:
        label = f'{r.potential} ({EQUATION[r.potential]})'
        axes[0][0].semilogy(r.t_s, 1e3 * r.position_error_m, color=colors[r.potential],
                            label=label)
        axes[0][1].semilogy(r.t_s, r.orientation_error, color=colors[r.potential], label=label)
    axes[0][0].set_ylabel('||p_d - p|| [mm]')
    axes[0][0].set_title('xArm6 position error (sampled loop on the simulator core, no DDS)',
                         fontsize=9)
    axes[0][1].set_ylabel('||e||')
    axes[0][1].set_title('xArm6 orientation error', fontsize=9)
    for ax in axes[0]:
        ax.set_xlabel('t [s]')
        ax.grid(True, which='both', alpha=0.3)
        ax.legend(fontsize=8)
    for col, r in zip(range(2), runs):
        name = f'{r.potential} ({EQUATION[r.potential]})'
        plot_torques(axes[1][col], r.t_s, r.effort_nm, model.effort_limits, model.joint_names,
                     f'{name}: joint torques vs effort limits')
        plot_angles(axes[2][col], r.t_s, r.q_rad, model.position_lower, model.position_upper,
                    model.joint_names, f'{name}: joint angles vs limits')
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main(argv: Optional[list] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--out', type=Path, default=Path('results/xarm6'))
    parser.add_argument('--duration', type=float, default=5.0, help='simulated seconds per run')
    parser.add_argument('--no-animation', action='store_true', help='skip the GIFs')
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    urdf_xml = XARM6_URDF.read_text()
    runs = []
    for potential in POTENTIALS:
        t0 = time.perf_counter()
        r, model, goal, R_goal = run(potential, args.duration, urdf_xml)
        runs.append(r)
        mcap_path = args.out / f'xarm6_{potential}.mcap'
        write_mcap(mcap_path, r, model, urdf_xml, goal)
        print(f'[xarm6 {potential}] {args.duration:g} s simulated in '
              f'{time.perf_counter() - t0:.1f} s: final ||p_d - p|| = '
              f'{1e3 * r.position_error_m[-1]:.3f} mm, ||e|| = {r.orientation_error[-1]:.2e}, '
              f'peak |tau| = {np.abs(r.effort_nm).max():.1f} N m; MCAP {mcap_path}')
        if not args.no_animation:
            from experiments.animation import animate
            label = f'xArm6 {potential} ({EQUATION[potential]})'
            a = animate(urdf_xml, model.joint_names, r.t_s, r.q_rad,
                        args.out / f'xarm6_{potential}.gif', tip_link=model.tip_link,
                        base_link=model.base_link, goal=(goal[0], np.array(R_goal)),
                        fps=ANIMATION_FPS, search_dirs=[pybullet_data.getDataPath()],
                        text=lambda i, r=r, label=label: [
                            label, f't = {r.t_s[i]:.2f} s',
                            f'||p_d - p|| = {1e3 * r.position_error_m[i]:.2f} mm',
                            f'||e|| = {r.orientation_error[i]:.3g}'],
                        still_at_s=STILL_AT_S,
                        still_path=args.out / f'xarm6_{potential}_frame.png')
            print(f'Animation {a.path}: {a.frames} frames ({ANIMATION_FPS:g} fps of sim time, '
                  f'320x240) rendered in {a.render_s:.1f} s, {a.size_bytes / 1e3:.0f} kB')
    plot(runs, model, args.out / 'xarm6_errors.png')
    print(f'Figure {args.out / "xarm6_errors.png"}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
