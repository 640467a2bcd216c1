"""
The paper's experiment (Section 5) end to end: the real nodes over DDS, as a user runs them.

For each controller, quadratic (Eq. 37) and tanh (Eq. 38): start ``wrist_sim_node`` and
``controller_node`` as separate processes on a private loopback ROS graph with the package's
config files (gains Eq. 43-45, q(0) = 0, the simulated Coulomb friction), publish the corrected
goal of docs/errata.md (Eq. 40) on ``/quat_jt_controller/target_pose``, and record joint states,
commands and the controller's error to MCAP, with what a 3D viewer needs to replay the robot
(``/robot_description``, ``/tf_static`` with the goal frame, ``/tf``; ``experiments/robot_tf.py``).
Then write a CSV, a figure like the paper's Fig. 2 (||e|| against time, linear and log) with
the joint torques and angles against their URDF limits, an animated GIF of each run rendered
offscreen from the recorded joint states (``experiments/animation.py``) and print the comparison
table. ``--xarm6`` also runs the xArm6 demo goal (``experiments/xarm6_demo.py``, ROS-free),
``--panda`` the Panda's sequence of goals (``experiments/panda_demo.py``, ROS-free).

    python -m experiments.paper_experiment [--out results/paper] [--duration 6]
                                                        [--lockstep] [--composed]
                                                        [--no-animation] [--xarm6]
                                                        [--panda]

By default the simulator paces itself in real time, as the wrist would run. With ``--lockstep``
it publishes ``/clock`` and steps as soon as the command for its last state has arrived
(``publish_clock``), and the controller runs on that clock (``use_sim_time``): the result no
longer depends on how busy the machine is. Each run reports the simulator's timing health
(ticks without a fresh command, command-watchdog trips), and the product config's run when its
goal configuration q* came into force: the goal-check worker answers on wall time (not niced
on simulated time, but sharing the host), so on a host too busy for it q* may come late in
simulated time even in lockstep.
"""
import argparse
import csv
from dataclasses import dataclass
import math
from pathlib import Path
import sys
import time
from typing import Optional

from diagnostic_msgs.msg import DiagnosticArray
from experiments import local_ros
from experiments.plots import plot_angles, plot_torques
from experiments.robot_tf import write_robot_replay
import numpy as np
from quat_jt_controller import control_law as cl
from quat_jt_controller import paper
from quat_jt_controller import quaternion as quat
from quat_jt_controller.model import RobotModel
from quat_jt_controller.reference_sim import ClosedLoop
from quat_jt_runtime.params import history_qos
from quat_jt_runtime.resources import default_urdf_xml

POTENTIALS = ('quadratic', 'tanh')
EQUATION = {'quadratic': 'Eq. 37', 'tanh': 'Eq. 38'}
# A third run: the tanh law with the product defaults (designed gains, extensions).
EXTENDED = 'tanh_extended'
EQUATION[EXTENDED] = 'Eq. 38 + extensions, config/wrist_controller.yaml'
CONTROLLER = 'quat_jt_controller'  # node name; its private topics live under /<name>/
REACH_THRESHOLD = 0.05
ANIMATION_FPS = 25.0  # frames per second of simulated time
STILL_AT_S = 0.12  # the still frame saved next to each GIF: the wrist on its way
CHECK_PERIOD_S = 0.002  # how often the recorder looks at the recording (wall s)


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
    recording_wall_s: float  # wall time to record duration_s of (simulated) time after the goal
    missing_states: int  # states of the recorded span that did not reach the recorder
    # the first /diagnostics (1 a second, the controller's clock) after the goal that gave its
    # goal configuration q*, relative to the goal (s); None: none did (or no such term)
    q_star_seen_s: Optional[float] = None


def _stamp_s(stamp) -> float:
    return stamp.sec + 1e-9 * stamp.nanosec


def goal_frame(model: RobotModel) -> tuple[np.ndarray, np.ndarray]:
    """
    Return (p_base_m, R_base) of the goal frame drawn by the animation and the MCAP replay.

    Its orientation is the goal (Eq. 40 corrected); the orientation task sets no position, so it
    is placed where the tip is at the goal's joint angles.
    """
    p_m, _ = model.forward_kinematics(paper.Q_JOINT_DESIRED_RAD)
    return np.array(p_m), np.array(quat.to_rotation_matrix(paper.Q_DESIRED))


def _write_replay(mcap, model: RobotModel, raw_states: list) -> None:
    """Add /robot_description, /tf_static and /tf (from the recorded joint states) to ``mcap``."""
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import JointState

    if not raw_states:
        return
    states = [deserialize_message(d, JointState) for _, d in raw_states]
    order = [states[0].name.index(n) for n in model.joint_names]
    q = np.array([[s.position[i] for i in order] for s in states])
    stamps_ns = [s.header.stamp.sec * 1_000_000_000 + s.header.stamp.nanosec for s in states]
    p_goal, _ = goal_frame(model)
    write_robot_replay(mcap, default_urdf_xml(), model.joint_names,
                       [ns for ns, _ in raw_states], stamps_ns, q,
                       goal=(model.base_link, p_goal, quat.to_xyzw(paper.Q_DESIRED)))


def error_norm(model: RobotModel, q_rad) -> float:
    """||e|| (Eq. 10) of the wrist at joint angles ``q_rad`` towards the paper's goal."""
    p, R = model.forward_kinematics(q_rad)
    e, _ = cl.output_error(p, R, None, paper.Q_DESIRED, cl.Task.ORIENTATION)
    return math.sqrt(sum(c * c for c in e))


def run_once(potential: str, duration_s: float, out_dir: Path, model: RobotModel,
             lockstep: bool = False, progress=print, composed: bool = False,
             max_rtf: float = 0.0) -> Run:
    """
    Run one experiment: the two nodes over DDS, recorded by a node in this process.

    The nodes are two processes, or one ``composed`` process with ``composed``.
    """
    from rclpy.serialization import deserialize_message

    from experiments.probe import ProbeNode
    from geometry_msgs.msg import PoseStamped, Vector3Stamped
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    from experiments.mcap_log import McapLog

    work = out_dir / potential
    pair = local_ros.spawn_recorded_pair(
        work, sim_params={'publish_clock': lockstep, 'max_real_time_factor': max_rtf},
        controller_params={'potential': 'tanh' if potential == EXTENDED else potential,
                           'use_sim_time': lockstep},
        controller_config=(local_ros.PRODUCT_CONTROLLER_CONFIG if potential == EXTENDED
                           else local_ros.PAPER_CONTROLLER_CONFIG), composed=composed)
    sim, ctrl, domain_id = pair.sim, pair.controller, pair.domain_id
    probe = ProbeNode('paper_experiment_recorder', domain_id)
    node, executor = probe.node, probe.executor
    mcap = McapLog(work / f'{potential}.mcap')
    records: dict[str, list] = {'states': [], 'commands': [], 'errors': []}
    channels = {}

    def recorder(topic, type_name, key):
        channels[key] = mcap.channel(topic, type_name)
        append = records[key].append
        clock = time.time_ns

        def callback(data: bytes) -> None:  # as cheap as can be: lockstep runs fast
            append((clock(), data))
        return callback

    for topic, msg, type_name, key in (
            ('/joint_states', JointState, 'sensor_msgs/msg/JointState', 'states'),
            ('/effort_controller/commands', Float64MultiArray,
             'std_msgs/msg/Float64MultiArray', 'commands'),
            (f'/{CONTROLLER}/orientation_error', Vector3Stamped,
             'geometry_msgs/msg/Vector3Stamped', 'errors')):
        # KEEP_ALL (as the nodes publish on simulated time): in lockstep nothing is lost, the
        # simulation waits for this recorder instead.
        node.create_subscription(msg, topic, recorder(topic, type_name, key),
                                 history_qos(lockstep), raw=True)
    goal_pub = node.create_publisher(PoseStamped, f'/{CONTROLLER}/target_pose', 10)
    checks_ready = [False]  # the controller's goal-check worker has built its model
    q_stars: list[tuple[float, str]] = []  # (stamp, q*) of the goal statuses that give one

    def on_diagnostics(msg: DiagnosticArray) -> None:
        for status in msg.status:
            if not status.name.endswith(f'{CONTROLLER}: goal'):
                continue
            values = {kv.key: kv.value for kv in status.values}
            if values.get('goal_check') == 'available':
                checks_ready[0] = True
            if values.get('goal_configuration_rad'):
                q_stars.append((_stamp_s(msg.header.stamp), values['goal_configuration_rad']))
    node.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics, 10)
    goal = PoseStamped()
    goal.header.frame_id = 'base_link'
    (goal.pose.orientation.x, goal.pose.orientation.y, goal.pose.orientation.z,
     goal.pose.orientation.w) = quat.to_xyzw(paper.Q_DESIRED)

    def spin_until(condition, timeout_s: float, what: str) -> None:
        # The condition (a message to deserialise) and the process checks are looked at every
        # CHECK_PERIOD_S, not after every message: in lockstep this process shares the CPUs
        # with the nodes, and what it spends slows simulated time down.
        deadline = time.monotonic() + timeout_s
        while not condition():
            for proc, name in ((sim, 'wrist_sim_node'), (ctrl, 'controller_node')):
                if proc.poll() is not None:
                    raise RuntimeError(f'{name} exited ({proc.returncode}) while {what}; see '
                                       f'{work / (name + ".log")}')
            now = time.monotonic()
            if now > deadline:
                raise TimeoutError(f'timed out after {timeout_s} s {what}; logs in {work}')
            check_at = now + CHECK_PERIOD_S
            while (left := check_at - time.monotonic()) > 0.0:
                executor.spin_once(timeout_sec=left)

    def recorded_error_norm(raw: bytes) -> float:
        msg = deserialize_message(raw, Vector3Stamped)
        return math.sqrt(msg.vector.x ** 2 + msg.vector.y ** 2 + msg.vector.z ** 2)

    def last_error_norm() -> float:
        return recorded_error_norm(records['errors'][-1][1])

    looked_at = [0]  # errors recorded so far that goal_taken has seen

    def goal_taken() -> bool:
        """
        Return whether an error recorded since the last look is above 0.5 (the goal's).

        Every new one, not only the newest: in lockstep the transient can come and go between
        two looks while this process waits for a CPU.
        """
        rows = records['errors']
        new, looked_at[0] = rows[looked_at[0]:], len(rows)
        return any(recorded_error_norm(raw) > 0.5 for _, raw in new)

    def last_state_time_s() -> float:
        """Stamp of the newest joint state: wall time, or simulated time in lockstep."""
        return _stamp_s(deserialize_message(records['states'][-1][1], JointState).header.stamp)

    try:
        progress(f'[{potential}] starting wrist_sim_node and controller_node (domain '
                 f'{domain_id})')
        spin_until(lambda: len(records['states']) > 100 and len(records['commands']) > 100
                   and records['errors'], 60.0, 'waiting for the nodes to run')
        # The goal's q* comes from the worker (the product config's goal-configuration term):
        # in lockstep, a worker still starting would answer seconds of simulated time late.
        spin_until(lambda: checks_ready[0], 60.0, 'waiting for the goal check to be ready')
        # The goal must go out at once: in lockstep the simulation runs on while a goal waits
        # for discovery, so t = 0 below would come seconds of simulated time too early.
        spin_until(lambda: goal_pub.get_subscription_count() > 0, 60.0,
                   'waiting for the controller to subscribe to goals')
        # The controller holds q(0) until the goal arrives: ||e|| ~ 0 there, ~0.9 after.
        # t = 0 is the stamp of the last state before the goal was sent.
        t_goal_s = last_state_time_s()
        looked_at[0] = len(records['errors'])  # the held pose's errors, ~0, are not looked at
        held_q_star = q_stars[-1][1] if q_stars else None  # the held pose's, if any
        goal_pub.publish(goal)
        spin_until(goal_taken, 10.0, 'waiting for the goal to be taken')
        progress(f'[{potential}] goal sent ({EQUATION[potential]}), recording {duration_s} s'
                 f'{" of simulated time (lockstep)" if lockstep else ""}')
        report_at = 0.0
        t_recording = time.monotonic()
        while report_at <= duration_s:
            spin_until(lambda: last_state_time_s() - t_goal_s >= report_at, 10.0 + duration_s,
                       'recording')
            progress(f'[{potential}]   t = {report_at:4.1f} s   ||e|| = {last_error_norm():.4g}')
            report_at += 1.0
        recording_wall_s = time.monotonic() - t_recording
    finally:
        sim_stats = pair.stop()  # the sim first: its statistics end with the controller alive
        probe.close()
        try:
            # The MCAP is written after the run, in time order, so recording costs little.
            for ns, key, data in sorted((ns, key, data) for key, rows in records.items()
                                        for ns, data in rows):
                mcap.write(channels[key], data, ns)
            _write_replay(mcap, model, records['states'])
        finally:
            mcap.close()

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
               np.array([list(c) for _, c in cmds]), work / f'{potential}.mcap', sim_stats,
               recording_wall_s,
               int(round(duration_s / np.median(np.diff(t[keep])))) + 1 - int(keep.sum()),
               next((stamp - t_goal_s for stamp, q_star in q_stars
                     if stamp >= t_goal_s and q_star != held_q_star), None))


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


def plot(runs: list[Run], ideal: dict, path: Path, model: Optional[RobotModel] = None) -> None:
    """
    Plot Fig. 2 of the paper (||e|| against time, linear and log) and the joints of each run.

    With ``model``, two more rows: per run, the applied joint torques against the URDF effort
    limits and the joint angles against the URDF position limits.
    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    rows = 1 if model is None else 3
    fig, axes = plt.subplots(rows, 2, figsize=(11, 4.2 * rows), squeeze=False)
    colors = {'quadratic': 'tab:blue', 'tanh': 'tab:red', EXTENDED: 'tab:green'}
    for ax, log in zip(axes[0], (False, True)):
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
    axes[0][0].set_title('Norm of orientation error (cf. paper Fig. 2)')
    axes[0][1].set_title('log scale')
    axes[0][1].legend(fontsize=7, loc='lower left')
    if model is not None:
        for col, r in zip(range(2), runs):
            name = f'{r.potential} ({EQUATION[r.potential]})'
            plot_torques(axes[1][col], r.t_s, r.effort_nm, model.effort_limits,
                         model.joint_names, f'{name}: joint torques vs effort limits')
            plot_angles(axes[2][col], r.t_s, r.q_rad, model.position_lower,
                        model.position_upper, model.joint_names,
                        f'{name}: joint angles vs limits')
    fig.tight_layout()
    fig.savefig(path, dpi=120 if model is None else 100)
    plt.close(fig)


def animate_run(run: Run, model: RobotModel, fps: float = ANIMATION_FPS):
    """Render ``run`` (its recorded joint states) to ``<potential>.gif`` next to its MCAP."""
    from experiments.animation import animate

    label = f'{run.potential} ({EQUATION[run.potential]})'
    return animate(
        default_urdf_xml(), model.joint_names, run.t_s, run.q_rad,
        run.mcap_path.with_suffix('.gif'), tip_link=model.tip_link,
        base_link=model.base_link, goal=goal_frame(model), fps=fps,
        text=lambda i: [label, f't = {run.t_s[i]:.2f} s', f'||e|| = {run.error_norm[i]:.3g}'],
        still_at_s=STILL_AT_S,
        still_path=run.mcap_path.with_name(f'{run.potential}_frame.png'))


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
    parser.add_argument('--composed', action='store_true',
                        help='both nodes in one process on one executor (the composed mode)')
    parser.add_argument('--max-rtf', type=float, default=0.0,
                        help='lockstep: at most this many times real time (0 = as fast as it '
                             'goes); lower it if the recording reports missing states')
    parser.add_argument('--no-animation', action='store_true',
                        help='skip the GIFs rendered from the recorded joint states')
    parser.add_argument('--xarm6', action='store_true',
                        help='also run the xArm6 demo goal (experiments/xarm6_demo.py, ROS-free) '
                             'into <out>/xarm6')
    parser.add_argument('--panda', action='store_true',
                        help='also run the Panda through its sequence of goals '
                             '(experiments/panda_demo.py, ROS-free) into <out>/panda')
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    model = RobotModel(default_urdf_xml(), 'base_link', 'tool0')
    t_start = time.monotonic()
    runs = [run_once(p, args.duration, args.out, model, args.lockstep, composed=args.composed,
                     max_rtf=args.max_rtf) for p in POTENTIALS + (EXTENDED,)]
    ideal = {}
    for p in POTENTIALS:
        gains = cl.Gains.create(p, paper.KP, paper.KV, paper.LAMBDA, cl.Task.ORIENTATION, 3)
        traj = ClosedLoop(model, gains, cl.Task.ORIENTATION, paper.Q_DESIRED).run(
            [0.0, 0.0, 0.0], args.duration)
        ideal[p] = (traj.t_s, traj.error_norm)
    summaries = [summarize(r, model.effort_limits) for r in runs]
    write_csv(runs, args.out / 'paper_experiment.csv')
    plot(runs, ideal, args.out / 'fig2_error_norm.png', model)
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
    mode = 'composed (one process)' if args.composed else 'two processes'
    for r in runs:
        print(f'{r.potential}: {args.duration:g} s {"simulated" if args.lockstep else "real"} '
              f'time recorded in {r.recording_wall_s:.2f} s of wall time ({mode}): '
              f'{args.duration / r.recording_wall_s:.2f}x real time'
              + ('; recording complete' if not r.missing_states else
                 f'; RECORDING INCOMPLETE: {r.missing_states} states missing (this process '
                 'fell behind; rerun with --max-rtf)' if args.lockstep else
                 f'; {r.missing_states} ticks missing (late ticks the real-time loop skipped, '
                 'or states this process missed)'))
    for r in runs:  # the goal-check worker answers on wall time, the loop in lockstep does not
        if r.potential == EXTENDED:
            print(f'{r.potential}: the goal configuration q* '
                  + (f'in force by t = {r.q_star_seen_s:.2f} s (the first diagnostics of the '
                     'controller, once a second, that give it)'
                     if r.q_star_seen_s is not None else
                     f'not in force by {args.duration:g} s (the goal-check worker answered '
                     'late, or found none)'))
    print(f'\nFigure {args.out / "fig2_error_norm.png"}, CSV {args.out / "paper_experiment.csv"}, '
          f'MCAP {", ".join(str(r.mcap_path) for r in runs)}')
    if not args.no_animation:  # after the runs, from the recorded joint states
        for r in runs:
            a = animate_run(r, model)
            print(f'Animation {a.path}: {a.frames} frames ({ANIMATION_FPS:g} fps of sim time, '
                  f'320x240) rendered in {a.render_s:.1f} s, {a.size_bytes / 1e3:.0f} kB; '
                  f'still frame {a.still_path}')
    if args.xarm6:
        from experiments import xarm6_demo
        xarm6_demo.main(['--out', str(args.out / 'xarm6')]
                        + (['--no-animation'] if args.no_animation else []))
    if args.panda:
        from experiments import panda_demo
        panda_demo.main(['--out', str(args.out / 'panda')]
                        + (['--no-animation'] if args.no_animation else []))
    print(f'Done in {time.monotonic() - t_start:.0f} s.')
    return 0


if __name__ == '__main__':
    sys.exit(main())
