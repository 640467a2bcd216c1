"""
The paper's experiment (Section 5) end to end: the real nodes over DDS, as a user runs them.

For each controller, quadratic (Eq. 37) and tanh (Eq. 38): start ``wrist_sim_node`` and
``controller_node`` as separate processes on a private loopback ROS graph with the package's
config files (gains Eq. 43-45, q(0) = 0, the simulated Coulomb friction), publish the corrected
goal of docs/errata.md (Eq. 40) on ``/quat_jt_controller/target_pose``, and record joint states,
commands and the controller's error to MCAP. Then write a CSV, a figure like the paper's Fig. 2
(||e|| against time, linear and log) and print the comparison table.

    python -m quat_jt_controller.tools.paper_experiment [--out results/paper] [--duration 6]
                                                        [--lockstep]

By default the simulator paces itself in real time, as the wrist would run. With ``--lockstep``
it publishes ``/clock`` and steps as soon as the command for its last state has arrived
(``publish_clock``), and the controller runs on that clock (``use_sim_time``): the result no
longer depends on how busy the machine is. Each run reports the simulator's timing health
(ticks without a fresh command, command-watchdog trips).
"""
import argparse
import csv
from dataclasses import dataclass
import json
import math
from pathlib import Path
import random
import sys
import time
from typing import Optional

import numpy as np

from quat_jt_controller import control_law as cl
from quat_jt_controller import paper
from quat_jt_controller import quaternion as quat
from quat_jt_controller.model import RobotModel
from quat_jt_controller.reference_sim import ClosedLoop
from quat_jt_controller.resources import default_urdf_xml
from quat_jt_controller.tools import local_ros

POTENTIALS = ('quadratic', 'tanh')
EQUATION = {'quadratic': 'Eq. 37', 'tanh': 'Eq. 38'}
# Issue 10: a third run, the tanh law with the product defaults (designed gains, extensions).
EXTENDED = 'tanh_extended'
EQUATION[EXTENDED] = 'Eq. 38 + issue 10, config/wrist_controller.yaml'
CONTROLLER = 'quat_jt_controller'  # node name; its private topics live under /<name>/
REACH_THRESHOLD = 0.05


@dataclass
class Run:
    potential: str
    t_s: np.ndarray  # state stamps relative to the goal
    q_rad: np.ndarray
    qdot_rad_s: np.ndarray
    effort_nm: np.ndarray  # applied by the sim (after limits)
    error_norm: np.ndarray  # ||e|| from the measured q through the URDF model
    command_t_s: np.ndarray
    command_nm: np.ndarray
    mcap_path: Path
    sim_stats: dict  # the simulator's loop statistics (LoopStats.summary)


def _stamp_s(stamp) -> float:
    return stamp.sec + 1e-9 * stamp.nanosec


def error_norm(model: RobotModel, q_rad) -> float:
    """||e|| (Eq. 10) of the wrist at joint angles ``q_rad`` towards the paper's goal."""
    p, R = model.forward_kinematics(q_rad)
    e, _ = cl.output_error(p, R, None, paper.Q_DESIRED, cl.Task.ORIENTATION)
    return math.sqrt(sum(c * c for c in e))


def run_once(potential: str, duration_s: float, out_dir: Path, model: RobotModel,
             lockstep: bool = False, progress=print) -> Run:
    """One experiment: two node processes over DDS, recorded by a node in this process."""
    from rclpy.serialization import deserialize_message

    from quat_jt_controller.tools.probe import ProbeNode
    from geometry_msgs.msg import PoseStamped, Vector3Stamped
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    from quat_jt_controller.tools.mcap_log import McapLog

    work = out_dir / potential
    work.mkdir(parents=True, exist_ok=True)
    domain_id = random.randint(1, 100)
    env = local_ros.isolated_env(work, domain_id)
    stats_file = work / 'sim_stats.json'
    stats_file.unlink(missing_ok=True)
    sim, ctrl = local_ros.spawn_wrist_pair(
        env, work, sim_params={'stats_file': str(stats_file), 'publish_clock': lockstep},
        controller_params={'potential': 'tanh' if potential == EXTENDED else potential,
                           'use_sim_time': lockstep},
        controller_config=(local_ros.PRODUCT_CONTROLLER_CONFIG if potential == EXTENDED
                           else local_ros.PAPER_CONTROLLER_CONFIG))
    probe = ProbeNode('paper_experiment_recorder', domain_id)
    node, executor = probe.node, probe.executor
    mcap = McapLog(work / f'{potential}.mcap')
    records: dict[str, list] = {'states': [], 'commands': [], 'errors': []}
    channels = {}

    def recorder(topic, type_name, key):
        channels[topic] = mcap.channel(topic, type_name)
        ch = channels[topic]

        def callback(data: bytes) -> None:
            now = time.time_ns()
            mcap.write(ch, data, now)
            records[key].append((now, data))
        return callback

    for topic, msg, type_name, key in (
            ('/joint_states', JointState, 'sensor_msgs/msg/JointState', 'states'),
            ('/effort_controller/commands', Float64MultiArray,
             'std_msgs/msg/Float64MultiArray', 'commands'),
            (f'/{CONTROLLER}/orientation_error', Vector3Stamped,
             'geometry_msgs/msg/Vector3Stamped', 'errors')):
        node.create_subscription(msg, topic, recorder(topic, type_name, key), 1000, raw=True)
    goal_pub = node.create_publisher(PoseStamped, f'/{CONTROLLER}/target_pose', 10)
    goal = PoseStamped()
    goal.header.frame_id = 'base_link'
    (goal.pose.orientation.x, goal.pose.orientation.y, goal.pose.orientation.z,
     goal.pose.orientation.w) = quat.to_xyzw(paper.Q_DESIRED)

    def spin_until(condition, timeout_s: float, what: str) -> None:
        deadline = time.monotonic() + timeout_s
        while not condition():
            for proc, name in ((sim, 'wrist_sim_node'), (ctrl, 'controller_node')):
                if proc.poll() is not None:
                    raise RuntimeError(f'{name} exited ({proc.returncode}) while {what}; see '
                                       f'{work / (name + ".log")}')
            if time.monotonic() > deadline:
                raise TimeoutError(f'timed out after {timeout_s} s {what}; logs in {work}')
            executor.spin_once(timeout_sec=0.05)

    def last_error_norm() -> float:
        msg = deserialize_message(records['errors'][-1][1], Vector3Stamped)
        return math.sqrt(msg.vector.x ** 2 + msg.vector.y ** 2 + msg.vector.z ** 2)

    def last_state_time_s() -> float:
        """Stamp of the newest joint state: wall time, or simulated time in lockstep."""
        return _stamp_s(deserialize_message(records['states'][-1][1], JointState).header.stamp)

    try:
        progress(f'[{potential}] starting wrist_sim_node and controller_node (domain '
                 f'{domain_id})')
        spin_until(lambda: len(records['states']) > 100 and len(records['commands']) > 100
                   and records['errors'], 60.0, 'waiting for the nodes to run')
        # The controller holds q(0) until the goal arrives: ||e|| ~ 0 there, ~0.9 after.
        # t = 0 is the stamp of the last state before the goal was sent.
        t_goal_s = last_state_time_s()
        goal_pub.publish(goal)
        spin_until(lambda: last_error_norm() > 0.5, 10.0, 'waiting for the goal to be taken')
        progress(f'[{potential}] goal sent ({EQUATION[potential]}), recording {duration_s} s'
                 f'{" of simulated time (lockstep)" if lockstep else ""}')
        report_at = 0.0
        while report_at <= duration_s:
            spin_until(lambda: last_state_time_s() - t_goal_s >= report_at, 10.0 + duration_s,
                       'recording')
            progress(f'[{potential}]   t = {report_at:4.1f} s   ||e|| = {last_error_norm():.4g}')
            report_at += 1.0
    finally:
        for proc in (sim, ctrl):  # the sim first: its statistics end with the controller alive
            local_ros.stop_node(proc)
        probe.close()
        mcap.close()
    sim_stats = json.loads(stats_file.read_text()) if stats_file.exists() else {}

    names = list(model.joint_names)
    states = [deserialize_message(d, JointState) for _, d in records['states']]
    order = [states[0].name.index(n) for n in names]
    t = np.array([_stamp_s(s.header.stamp) for s in states]) - t_goal_s
    q = np.array([[s.position[i] for i in order] for s in states])
    qdot = np.array([[s.velocity[i] for i in order] for s in states])
    effort = np.array([[s.effort[i] for i in order] for s in states])
    err = np.array([error_norm(model, qi) for qi in q])
    cmds = [(ns, deserialize_message(d, Float64MultiArray).data) for ns, d in records['commands']]
    keep = (t >= 0.0) & (t <= duration_s)
    # Commands carry no stamp: place each at the state stamp of its arrival's recording time.
    state_ns = np.array([ns for ns, _ in records['states']])
    cmd_ns = np.array([ns for ns, _ in cmds])
    cmd_t = t[np.clip(np.searchsorted(state_ns, cmd_ns) - 1, 0, len(t) - 1)]
    return Run(potential, t[keep], q[keep], qdot[keep], effort[keep], err[keep], cmd_t,
               np.array([list(c) for _, c in cmds]), work / f'{potential}.mcap', sim_stats)


def summarize(run: Run, limits) -> dict:
    tail = run.t_s >= run.t_s[-1] - 0.5
    reached = np.nonzero(run.error_norm < REACH_THRESHOLD)[0]
    after_goal = run.command_t_s >= 0.0
    peak = np.abs(run.command_nm[after_goal]).max(axis=0)
    return {
        'potential': run.potential,
        'final_error': float(run.error_norm[tail].mean()),
        'paper_error': paper.FINAL_ERROR.get(run.potential, math.nan),
        'time_to_reach_s': float(run.t_s[reached[0]]) if reached.size else None,
        'peak_torque_nm': peak.tolist(),
        'saturated': bool(np.any(peak >= np.asarray(limits) * (1.0 - 1e-9))),
        'final_speed_rad_s': float(np.abs(run.qdot_rad_s[tail]).max()),
        'states': int(run.t_s.size),
        'stale_ticks_pct': 100.0 * run.sim_stats.get('window_stale_steps', float('nan'))
        / max(run.sim_stats.get('window_steps', 1), 1),
        'watchdog_trips': run.sim_stats.get('watchdog_trips'),
    }


def write_csv(runs: list[Run], path: Path) -> None:
    with open(path, 'w', newline='') as f:
        w = csv.writer(f)
        w.writerow(['potential', 't_s', 'error_norm', 'q1_rad', 'q2_rad', 'q3_rad',
                    'qdot1_rad_s', 'qdot2_rad_s', 'qdot3_rad_s', 'tau1_nm', 'tau2_nm',
                    'tau3_nm'])
        for r in runs:
            for k in range(r.t_s.size):
                w.writerow([r.potential, f'{r.t_s[k]:.6f}', f'{r.error_norm[k]:.6e}',
                            *(f'{v:.6f}' for v in r.q_rad[k]),
                            *(f'{v:.6f}' for v in r.qdot_rad_s[k]),
                            *(f'{v:.6f}' for v in r.effort_nm[k])])


def plot(runs: list[Run], ideal: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    colors = {'quadratic': 'tab:blue', 'tanh': 'tab:red', EXTENDED: 'tab:green'}
    for ax, log in zip(axes, (False, True)):
        for r in runs:
            ax.plot(r.t_s, r.error_norm, color=colors[r.potential],
                    label=f'{r.potential} ({EQUATION[r.potential]}), simulated wrist')
            if r.potential not in ideal:
                continue
            ax.axhline(paper.FINAL_ERROR[r.potential], color=colors[r.potential], ls=':',
                       lw=1, label=f'paper final {r.potential}')
            t_ref, e_ref = ideal[r.potential]
            ax.plot(t_ref, e_ref, color=colors[r.potential], ls='--', lw=1, alpha=0.6,
                    label=f'{r.potential}, ideal (no friction, no delay)')
        ax.set_xlabel('t [s]')
        ax.set_ylabel('||e||')
        if log:
            ax.set_yscale('log')
            ax.set_ylim(1e-5, 2.0)
        ax.grid(True, which='both', alpha=0.3)
    axes[0].set_title('Norm of orientation error (cf. paper Fig. 2)')
    axes[1].set_title('log scale')
    axes[1].legend(fontsize=7, loc='lower left')
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def table(summaries: list[dict], limits) -> str:
    lines = ['| controller | final ||e|| (sim) | paper | time to ||e|| < 0.05 | '
             'peak |tau| per joint [N m] | saturated (limits ' + '/'.join(
                 f'{v:g}' for v in limits) + ') |',
             '|---|---|---|---|---|---|']
    for s in summaries:
        reach = f'{s["time_to_reach_s"]:.3f} s' if s['time_to_reach_s'] is not None else 'never'
        lines.append(f'| {s["potential"]} ({EQUATION[s["potential"]]}) | '
                     f'{s["final_error"]:.4g} | {s["paper_error"]:.4g} | {reach} | '
                     + ', '.join(f'{v:.2f}' for v in s['peak_torque_nm'])
                     + f' | {"yes" if s["saturated"] else "no"} |')
    return '\n'.join(lines)


def main(argv: Optional[list] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--out', type=Path, default=Path('results/paper'))
    parser.add_argument('--duration', type=float, default=6.0,
                        help='seconds recorded after the goal, per controller')
    parser.add_argument('--lockstep', action='store_true',
                        help='simulated clock, sim and controller in lockstep (load-proof)')
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    model = RobotModel(default_urdf_xml(), 'base_link', 'tool0')
    t_start = time.monotonic()
    runs = [run_once(p, args.duration, args.out, model, args.lockstep)
            for p in POTENTIALS + (EXTENDED,)]
    ideal = {}
    for p in POTENTIALS:
        gains = cl.Gains.create(p, paper.KP, paper.KV, paper.LAMBDA, cl.Task.ORIENTATION, 3)
        traj = ClosedLoop(model, gains, cl.Task.ORIENTATION, paper.Q_DESIRED).run(
            [0.0, 0.0, 0.0], args.duration)
        ideal[p] = (traj.t_s, traj.error_norm)
    summaries = [summarize(r, model.effort_limits) for r in runs]
    write_csv(runs, args.out / 'paper_experiment.csv')
    plot(runs, ideal, args.out / 'fig2_error_norm.png')
    text = table(summaries, model.effort_limits)
    (args.out / 'summary.md').write_text(text + '\n')
    print()
    print(text)
    for s in summaries:
        health = (f'{s["stale_ticks_pct"]:.2f}% of sim ticks without a fresh command, '
                  f'{s["watchdog_trips"]} command-watchdog trips')
        if s['watchdog_trips']:
            health += ' -- DEGRADED: the machine was too busy for real time; try --lockstep'
        print(f'{s["potential"]}: {s["states"]} joint states, final max |qdot| '
              f'{s["final_speed_rad_s"]:.2e} rad/s; timing: {health}')
    print(f'\nFigure {args.out / "fig2_error_norm.png"}, CSV {args.out / "paper_experiment.csv"}, '
          f'MCAP {", ".join(str(r.mcap_path) for r in runs)}')
    print(f'Done in {time.monotonic() - t_start:.0f} s.')
    return 0


if __name__ == '__main__':
    sys.exit(main())
