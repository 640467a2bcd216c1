"""
The Panda through a sequence of goals, without ROS: a redundant arm, its self-motion held.

The 7-DOF Franka Panda of pybullet_data (``config/panda_controller.yaml``, the start and the
friction of ``config/panda_sim.yaml``) is sent through ``GOALS_Q_RAD``: the flange's pose at each
of these joint configurations, one goal every ``--hold`` seconds. What runs is the node's tick
(``Regulator.update``, Eq. 24/32 + g(q) + the extensions, clamped to the effort limits) on the
PyBullet simulator core, sampled at 1 kHz with one tick of delay; each goal's q* comes from the
goal check (``inverse_kinematics.goal_configuration``, slid along the self-motion to the
posture nearest the arm) 0.1 s after the goal, as the node's worker gives it. NOT the nodes
over DDS.

It writes, to ``--out`` (default ``results/panda``): an MCAP with ``/joint_states``,
``/robot_description``, ``/tf_static`` and ``/tf`` (the arm and the goal frame), an animated GIF
and a still frame, and a figure of the position error, ||e||, the null-space speed
``||(I - J^+ J) qdot||`` (the self-motion: zero once the elbow is held) and the joint angles
against their limits. It prints, per goal, the time to reach 1 mm and ||e|| < 0.01, the final
errors, the largest joint speed over the goal's last 0.5 s and max_j |q_j - q*_j| at its end.

    python -m experiments.panda_demo [--out results/panda] [--hold 4] [--potential tanh]
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
from quat_jt_controller.regulator import Goal
from quat_jt_runtime.resources import config_parameters
from wrist_sim.quiet import c_output_silenced
from wrist_sim.simulator import RobotSimulator

PANDA_URDF = Path(pybullet_data.getDataPath()) / 'franka_panda' / 'panda.urdf'
# The goals: the flange's pose at these joint angles (the first is launch/panda_demo.launch.py's)
GOALS_Q_RAD = (
    (0.3, -0.5, 0.2, -2.0, 0.1, 1.8, 0.9),
    (-0.6, 0.2, -0.3, -1.7, 0.4, 2.2, 0.2),
    (0.8, 0.4, 0.5, -1.2, -0.6, 1.4, 1.5),
    (0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785),  # back to the ready pose
)
Q_STAR_AFTER_S = 0.1  # the goal-check worker's answer arrives after the goal
DELAY_TICKS = 1
POSITION_TOL_M, ORIENTATION_TOL = 1e-3, 0.01
SETTLED_WINDOW_S = 0.5
ANIMATION_FPS = 20.0
NULL_SPACE_EVERY = 10  # ticks between two null-space speeds (a 6 x 7 pseudo-inverse each)


@dataclass
class SequenceRun:
    t_s: np.ndarray
    q_rad: np.ndarray
    qdot_rad_s: np.ndarray
    effort_nm: np.ndarray
    position_error_m: np.ndarray
    orientation_error: np.ndarray
    goal_index: np.ndarray  # the goal in force at each sample
    null_t_s: np.ndarray
    null_speed_rad_s: np.ndarray  # ||(I - J^+ J) qdot||
    goals: list  # (p_d, q_d, R_d, q_star) per goal


def null_space_speed(model: RobotModel, q: np.ndarray, qdot: np.ndarray) -> float:
    """Return ||(I - J^+ J) qdot||: the part of the joint speed that moves no task coordinate."""
    J = np.array(model.kinematics(q.tolist())[2])
    return float(np.linalg.norm(qdot - np.linalg.pinv(J) @ (J @ qdot)))


def run(potential: str, hold_s: float) -> tuple[SequenceRun, RobotModel, str]:
    """Drive the Panda through GOALS_Q_RAD with the config's controller; return the run."""
    simp = config_parameters('panda_sim.yaml')
    urdf_xml = PANDA_URDF.read_text()
    regulator = controller_from_package_config('panda_controller.yaml', urdf_xml, potential)
    model, shaping = regulator.model, regulator.shaping
    with c_output_silenced((1, 2)):
        sim = RobotSimulator(urdf_xml, model.joint_names, dt_s=1.0 / simp['rate_hz'],
                             viscous_nm_s_per_rad=simp['viscous_friction'],
                             coulomb_nm=simp['coulomb_friction'],
                             initial_positions_rad=simp['initial_positions'],
                             enforce_velocity_limits=simp['enforce_velocity_limits'])
    dt_s = sim.dt_s
    per_goal = int(round(hold_s / dt_s))
    steps = per_goal * len(GOALS_Q_RAD)
    t = np.empty(steps)
    q, qdot, tau = (np.empty((steps, model.n)) for _ in range(3))
    pos, ori, which = np.empty(steps), np.empty(steps), np.empty(steps, dtype=int)
    null_t, null_v = [], []
    goals = []
    history = [(sim.q_rad.tolist(), sim.qdot_rad_s.tolist())] * (DELAY_TICKS + 1)
    try:
        for g, q_goal in enumerate(GOALS_Q_RAD):
            p_d, R_d = model.forward_kinematics(list(q_goal))
            q_d = quat.from_rotation_matrix(R_d)
            goal = Goal(tuple(q_d), tuple(p_d))
            regulator.set_goal(goal)
            q_star = goal_configuration(model, sim.q_rad.tolist(), q_d, p_d, cl.Task.POSE,
                                        shaping.joint_limit_margin_rad,
                                        q_preferred=shaping.preferred_configuration_rad or None,
                                        posture_weight=shaping.posture_weight)
            goals.append((p_d, q_d, R_d, q_star))
            for i in range(per_goal):
                k = g * per_goal + i
                if i == int(round(Q_STAR_AFTER_S / dt_s)):
                    regulator.set_goal_configuration(goal, q_star)
                q_now, qdot_now = history[-1 - DELAY_TICKS]
                applied = sim.step(regulator.update(q_now, qdot_now, dt_s).tau_nm)
                history.append((sim.q_rad.tolist(), sim.qdot_rad_s.tolist()))
                del history[0]
                t[k], q[k], qdot[k], tau[k], which[k] = sim.time_s, sim.q_rad, sim.qdot_rad_s, \
                    applied, g
                y = regulator.error(q[k].tolist())[0]
                pos[k], ori[k] = np.linalg.norm(y[:3]), np.linalg.norm(y[3:])
                if k % NULL_SPACE_EVERY == 0:
                    null_t.append(t[k])
                    null_v.append(null_space_speed(model, q[k], qdot[k]))
    finally:
        sim.close()
    return (SequenceRun(t, q, qdot, tau, pos, ori, which, np.array(null_t), np.array(null_v),
                        goals), model, urdf_xml)


def report(r: SequenceRun, hold_s: float) -> list[str]:
    """One line per goal: time to tolerance, final errors, final speed, distance to q*."""
    lines = []
    for g, (_, _, _, q_star) in enumerate(r.goals):
        mask = r.goal_index == g
        t0 = r.t_s[mask][0] - (r.t_s[1] - r.t_s[0])
        ok = (r.position_error_m[mask] < POSITION_TOL_M) & (
            r.orientation_error[mask] < ORIENTATION_TOL)
        bad = np.flatnonzero(~ok)
        within = (np.nan if not ok[-1] else
                  (r.t_s[mask][bad[-1] + 1] - t0 if bad.size else 0.0))
        last = r.t_s[mask] >= r.t_s[mask][-1] - SETTLED_WINDOW_S
        speed = float(np.abs(r.qdot_rad_s[mask][last]).max())
        away = (np.nan if q_star is None else
                float(np.abs(r.q_rad[mask][-1] - q_star).max()))
        lines.append(
            f'goal {g + 1}: within 1 mm and ||e|| < 0.01 after {within:.2f} s (of {hold_s:g}); '
            f'final {1e3 * r.position_error_m[mask][-1]:.3f} mm, ||e|| '
            f'{r.orientation_error[mask][-1]:.1e}; fastest joint over the last '
            f'{SETTLED_WINDOW_S:g} s {speed:.1e} rad/s; max_j |q_j - q*_j| {away:.1e} rad')
    return lines


def write_mcap(path: Path, r: SequenceRun, model: RobotModel, urdf_xml: str,
               hold_s: float) -> None:
    """Write /joint_states at 1 kHz and the replay topics, with the goal frame on /tf."""
    start_ns = time.time_ns()
    stamps_ns = start_ns + np.round(r.t_s * 1e9).astype(np.int64)
    log = McapLog(path)
    try:
        js = log.channel('/joint_states', 'sensor_msgs/msg/JointState')
        for k, stamp in enumerate(stamps_ns):
            log.write(js, cdr_joint_state(int(stamp), model.joint_names, r.q_rad[k],
                                          r.qdot_rad_s[k], r.effort_nm[k]), int(stamp))
        goals = [(int(start_ns + round(g * hold_s * 1e9)), model.base_link, tuple(p_d),
                  quat.to_xyzw(q_d)) for g, (p_d, q_d, _, _) in enumerate(r.goals)]
        write_robot_replay(log, urdf_xml, model.joint_names, stamps_ns, stamps_ns, r.q_rad,
                           moving_goals=goals)
    finally:
        log.close()


def plot(r: SequenceRun, model: RobotModel, path: Path, potential: str) -> None:
    """Position error, ||e||, null-space speed, joint angles against the limits."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    from experiments.plots import plot_angles

    fig, axes = plt.subplots(4, 1, figsize=(10, 13), sharex=True)
    axes[0].semilogy(r.t_s, 1e3 * r.position_error_m, color='tab:red')
    axes[0].axhline(1e3 * POSITION_TOL_M, color='k', ls=':', lw=0.8)
    axes[0].set_ylabel('||p_d - p|| [mm]')
    axes[0].set_title(f'Panda, {potential}: a goal every {r.t_s[-1] / len(r.goals):.0f} s '
                      '(sampled loop on the simulator core, no DDS)', fontsize=9)
    axes[1].semilogy(r.t_s, r.orientation_error, color='tab:red')
    axes[1].axhline(ORIENTATION_TOL, color='k', ls=':', lw=0.8)
    axes[1].set_ylabel('||e||')
    axes[2].semilogy(r.null_t_s, np.maximum(r.null_speed_rad_s, 1e-9), color='tab:purple')
    axes[2].set_ylabel('||(I - J+ J) qdot|| [rad/s]')
    axes[2].set_title('null-space (self-motion) speed: held once the goal is reached',
                      fontsize=9)
    plot_angles(axes[3], r.t_s, r.q_rad, model.position_lower, model.position_upper,
                model.joint_names, 'joint angles vs limits')
    for ax in axes:
        ax.grid(True, which='both', alpha=0.3)
        for g in range(1, len(r.goals)):
            ax.axvline(r.t_s[0] + g * r.t_s[-1] / len(r.goals), color='grey', lw=0.6)
    axes[-1].set_xlabel('t [s]')
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main(argv: Optional[list] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--out', type=Path, default=Path('results/panda'))
    parser.add_argument('--hold', type=float, default=4.0, help='simulated seconds per goal')
    parser.add_argument('--potential', choices=[p.value for p in cl.Potential], default='tanh')
    parser.add_argument('--no-animation', action='store_true', help='skip the GIF')
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    r, model, urdf_xml = run(args.potential, args.hold)
    print(f'[panda {args.potential}] {len(r.goals)} goals, {r.t_s[-1]:.1f} s simulated in '
          f'{time.perf_counter() - t0:.1f} s')
    for line in report(r, args.hold):
        print('  ' + line)
    mcap_path = args.out / f'panda_{args.potential}.mcap'
    write_mcap(mcap_path, r, model, urdf_xml, args.hold)
    print(f'MCAP {mcap_path}')
    figure = args.out / f'panda_{args.potential}.png'
    plot(r, model, figure, args.potential)
    print(f'Figure {figure}')
    if not args.no_animation:
        from experiments.animation import animate
        goal_of = (lambda i: (r.goals[r.goal_index[i]][0],
                              np.array(r.goals[r.goal_index[i]][2])))
        a = animate(urdf_xml, model.joint_names, r.t_s, r.q_rad,
                    args.out / f'panda_{args.potential}.gif', tip_link=model.tip_link,
                    base_link=model.base_link, goal=goal_of, fps=ANIMATION_FPS,
                    search_dirs=[pybullet_data.getDataPath()],
                    text=lambda i: [f'Panda {args.potential}, goal {r.goal_index[i] + 1}',
                                    f't = {r.t_s[i]:.2f} s',
                                    f'||p_d - p|| = {1e3 * r.position_error_m[i]:.2f} mm',
                                    f'||e|| = {r.orientation_error[i]:.3g}'],
                    still_at_s=args.hold * 0.25,
                    still_path=args.out / f'panda_{args.potential}_frame.png')
        print(f'Animation {a.path}: {a.frames} frames ({ANIMATION_FPS:g} fps of sim time) '
              f'rendered in {a.render_s:.1f} s, {a.size_bytes / 1e3:.0f} kB')
    return 0


if __name__ == '__main__':
    sys.exit(main())
