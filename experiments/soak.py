"""
Soak: both nodes for a long run, with the figures that show a leak, a drift or a fault.

Starts ``wrist_sim_node`` and ``controller_node`` (``config/wrist_sim.yaml`` and the product
``config/wrist_controller.yaml``, real time) on a
private loopback graph, then alternates two reachable goals every 30 s.
Every ``--report`` seconds (one minute by default; before a goal change due then) it prints
each process's resident memory, the joint-state and command rates seen here, the controller's
largest gap between two states, the simulator's watchdog trips so far and ``||e||``; at the end
the final ``||e||`` and the warnings and errors the nodes logged, counted by cause.

``--load N`` runs N busy processes beside the nodes (a loaded host, e.g. N = 2 on 2 cores gives
a load average near 4): the largest gaps then measured are what the watchdog timeouts must
tolerate (``state_timeout``, ``command_timeout``, ``max_state_age``).

``--churn S`` starts a short-lived ROS process every S seconds, as a user's ``ros2 topic echo``
would: it joins the graph, takes joint states for a second and leaves. Each report line then
also gives the simulator's largest period, from the stamps of its states (its publication
times, so this process's own delays do not count). Target (streamed-goals issue): under 10 ms
with a CLI process every 10 s.

``--echo`` makes each of those processes a ``ros2 topic echo --once`` instead: it joins the
next topic the nodes publish, in turn (``experiments/listener_churn.py``), takes one message
and leaves; the readers a writer has never seen are what once stalled the loop.

``--minimal`` runs the benchmark's minimal state/command pair (``experiments/minimal_pair.py``)
in place of the nodes, with no goals: the host's floor under the same churn, to compare the
simulator's largest period with.

``--thread-priority P`` gives both nodes (or the minimal pair) that ``thread_priority``; by
default they run at theirs (50, SCHED_FIFO); 0 runs them with normal scheduling, as before
that parameter existed.

    python -m experiments.soak [--duration 600] [--load 0] [--churn 10 [--echo]] [--minimal]
                               [--thread-priority P]
"""
import argparse
import collections
import json
import math
import multiprocessing
from pathlib import Path
import random
import re
import subprocess
import sys
import time
from typing import Optional

from diagnostic_msgs.msg import DiagnosticArray
from experiments import listener_churn
from experiments import local_ros
from experiments.probe import ProbeNode
from geometry_msgs.msg import PoseStamped
from quat_jt_controller import paper
from quat_jt_controller import quaternion as quat
from quat_jt_controller.model import RobotModel
from quat_jt_runtime.resources import default_urdf_xml
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

# The paper's goal and a second reachable one (the wrist's pose at these joint angles).
SECOND_GOAL_Q_RAD = (-0.6, 1.1, 0.4)
LOG_LINE = re.compile(r'^\[(WARN|ERROR|FATAL)\] \[[0-9.]+\] \[([^\]]+)\]: (.*)$')


def _burn(stop_at: float) -> None:
    x = 0
    while time.monotonic() < stop_at:
        x += 1


def rss_mb(pid: int) -> float:
    """Resident memory of a process (MB), from /proc."""
    for line in Path(f'/proc/{pid}/status').read_text().splitlines():
        if line.startswith('VmRSS:'):
            return int(line.split()[1]) / 1024.0
    return math.nan


def warnings_by_cause(text: str) -> collections.Counter:
    """Count WARN/ERROR/FATAL lines of a node log by their text without numbers."""
    counts: collections.Counter = collections.Counter()
    for line in text.splitlines():
        m = LOG_LINE.match(line.strip())
        if m:
            cause = re.sub(r'[-+]?\d+(\.\d+)?(e[-+]?\d+)?', '#', m.group(3))[:140]
            counts[f'{m.group(1)} [{m.group(2)}] {cause}'] += 1
    return counts


# A user's CLI process: joins the graph, takes joint states for a second, leaves.
CLI_LIKE = (
    'import sys, time\n'
    'import rclpy\n'
    'from sensor_msgs.msg import JointState\n'
    'rclpy.init()\n'
    "node = rclpy.create_node('cli_like_echo')\n"
    "node.create_subscription(JointState, '/joint_states', lambda m: None, 10)\n"
    'end = time.monotonic() + 1.0\n'
    'while time.monotonic() < end:\n'
    '    rclpy.spin_once(node, timeout_sec=0.05)\n'
    'node.destroy_node()\n'
    'rclpy.try_shutdown()\n')


def soak(duration_s: float, out: Path, load: int = 0, report_s: float = 60.0,
         goal_period_s: float = 30.0, churn_s: float = 0.0, minimal: bool = False,
         thread_priority: Optional[int] = None, echo: bool = False) -> dict:
    """Run the soak; print a line per report interval; return the figures."""
    out.mkdir(parents=True, exist_ok=True)
    domain_id = random.randint(1, 100)
    env = local_ros.isolated_env(out, domain_id)
    stats_file = out / 'sim_stats.json'
    stats_file.unlink(missing_ok=True)
    burners = [multiprocessing.Process(target=_burn, args=(time.monotonic() + duration_s + 60,),
                                       daemon=True) for _ in range(load)]
    for b in burners:
        b.start()
    priority = {} if thread_priority is None else {'thread_priority': thread_priority}
    if minimal:  # the host's floor: the same topics, no law, no physics
        flags = () if thread_priority is None else (f'--priority={thread_priority}',)
        ctrl = local_ros.spawn_node('minimal_pair', env, out, name='controller_node',
                                    args=('--role', 'controller') + flags)
        sim = local_ros.spawn_node('minimal_pair', env, out, name='wrist_sim_node',
                                   args=('--role', 'sim', '--duration', str(duration_s + 120.0),
                                         '--warmup', '0', '--stats', str(stats_file)) + flags)
    else:
        sim, ctrl = local_ros.spawn_wrist_pair(  # the product defaults, as a user runs them
            env, out, sim_params={'stats_file': str(stats_file), **priority},
            controller_params=priority, controller_config=local_ros.PRODUCT_CONTROLLER_CONFIG)
    probe = ProbeNode('soak_probe', domain_id)
    model = RobotModel(default_urdf_xml(), 'base_link', 'tool0')
    _, R2 = model.forward_kinematics(SECOND_GOAL_Q_RAD)
    goals = [paper.Q_DESIRED, quat.from_rotation_matrix(R2)]
    counts = {'states': 0, 'commands': 0}
    last_q: list = [None]
    max_period_us = [0.0]

    last_stamp = [0.0]
    max_sim_period_s = [0.0]

    def on_state(msg: JointState) -> None:
        counts['states'] += 1
        last_q[0] = msg
        stamp = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
        if last_stamp[0]:
            max_sim_period_s[0] = max(max_sim_period_s[0], stamp - last_stamp[0])
        last_stamp[0] = stamp

    def on_diag(msg: DiagnosticArray) -> None:
        for s in msg.status:
            if s.name.endswith('quat_jt_controller: control loop'):
                for kv in s.values:
                    if kv.key == 'period_max_us' and kv.value != 'nan':
                        max_period_us[0] = max(max_period_us[0], float(kv.value))

    node = probe.node
    node.create_subscription(JointState, '/joint_states', on_state, 100)
    node.create_subscription(Float64MultiArray, '/effort_controller/commands',
                             lambda _: counts.__setitem__('commands', counts['commands'] + 1),
                             100)
    node.create_subscription(DiagnosticArray, '/diagnostics', on_diag, 10)
    goal_pub = node.create_publisher(PoseStamped, '/quat_jt_controller/target_pose', 10)
    rows = []

    def error_norm(goal) -> float:
        if minimal:  # no law: no error to report
            return math.nan
        m = last_q[0]
        q = [m.position[list(m.name).index(j)] for j in model.joint_names]
        _, R = model.forward_kinematics(q)
        _, e = quat.orientation_error(quat.from_rotation_matrix(R), goal)
        return math.sqrt(sum(x * x for x in e))

    cli: Optional[subprocess.Popen] = None
    churned = 0
    try:
        deadline = time.monotonic() + 60.0
        while (counts['commands'] < 100
               or (not minimal and goal_pub.get_subscription_count() == 0)):
            if time.monotonic() > deadline or sim.poll() is not None or ctrl.poll() is not None:
                raise RuntimeError(f'the nodes did not start; logs in {out}')
            probe.executor.spin_once(timeout_sec=0.05)
        print(f'soak: {duration_s:.0f} s, {load} busy processes beside the nodes; logs in {out}',
              flush=True)
        print(f'{"t [s]":>6} {"sim RSS MB":>10} {"ctrl RSS MB":>11} {"states/s":>9} '
              f'{"cmds/s":>7} {"max state gap ms":>16} {"sim period max ms":>17} '
              f'{"sim watchdog trips":>18} {"||e||":>9}', flush=True)
        t0 = time.monotonic()
        next_goal, next_report, k_goal = t0, t0 + report_s, 0
        next_churn = t0 + churn_s if churn_s > 0.0 else math.inf
        window = dict(counts)
        goal = goals[0]
        while (now := time.monotonic()) < t0 + duration_s:
            for proc, name in ((sim, 'wrist_sim_node'), (ctrl, 'controller_node')):
                if proc.poll() is not None:
                    raise RuntimeError(f'{name} exited ({proc.returncode}); logs in {out}')
            if now >= next_report:
                trips = (out / 'wrist_sim_node.log').read_text(errors='replace').count(
                    'torque set to zero')
                row = {'t_s': now - t0, 'sim_rss_mb': rss_mb(sim.pid),
                       'controller_rss_mb': rss_mb(ctrl.pid),
                       'state_rate_hz': (counts['states'] - window['states']) / report_s,
                       'command_rate_hz': (counts['commands'] - window['commands']) / report_s,
                       'max_state_gap_ms': max_period_us[0] / 1e3,
                       'sim_period_max_ms': max_sim_period_s[0] * 1e3,
                       'cli_processes': churned, 'error_norm': error_norm(goal)}
                rows.append(row)
                print(f'{row["t_s"]:6.0f} {row["sim_rss_mb"]:10.1f} '
                      f'{row["controller_rss_mb"]:11.1f} {row["state_rate_hz"]:9.1f} '
                      f'{row["command_rate_hz"]:7.1f} {row["max_state_gap_ms"]:16.1f} '
                      f'{row["sim_period_max_ms"]:17.1f} {trips:>18} {row["error_norm"]:9.2e}',
                      flush=True)
                window = dict(counts)
                max_period_us[0] = 0.0
                max_sim_period_s[0] = 0.0
                next_report += report_s
            if now >= next_goal and not minimal:
                goal = goals[k_goal % 2]
                msg = PoseStamped()
                msg.header.frame_id = 'base_link'
                o = msg.pose.orientation
                o.x, o.y, o.z, o.w = quat.to_xyzw(goal)
                goal_pub.publish(msg)
                k_goal += 1
                next_goal += goal_period_s
            if now >= next_churn and (cli is None or cli.poll() is not None):
                topics = (list(listener_churn.TOPICS) if not minimal else
                          ['/joint_states', '/effort_controller/commands'])
                topic = topics[churned % len(topics)]
                argv = ([sys.executable, '-c', listener_churn.LISTENER, topic,
                         *listener_churn.TOPICS[topic]] if echo
                        else [sys.executable, '-c', CLI_LIKE])
                cli = subprocess.Popen(argv, env=env,
                                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
                churned += 1
                next_churn += churn_s
            probe.executor.spin_once(timeout_sec=0.05)
        final_error = error_norm(goal)
    finally:
        if cli is not None:
            cli.wait(10.0)
        local_ros.stop_nodes((sim, ctrl))
        probe.close()
        for b in burners:
            b.terminate()
    sim_stats = json.loads(stats_file.read_text()) if stats_file.exists() else {}
    warnings = warnings_by_cause((out / 'wrist_sim_node.log').read_text(errors='replace')
                                 + (out / 'controller_node.log').read_text(errors='replace'))
    return {'rows': rows, 'final_error': final_error, 'sim_stats': sim_stats,
            'cli_processes': churned,
            'warnings': dict(warnings)}


def main(argv: Optional[list] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--duration', type=float, default=600.0, help='seconds')
    parser.add_argument('--load', type=int, default=0, help='busy processes beside the nodes')
    parser.add_argument('--report', type=float, default=60.0, help='seconds per report line')
    parser.add_argument('--churn', type=float, default=0.0,
                        help='start a short-lived ROS process (as a CLI command) every S seconds')
    parser.add_argument('--echo', action='store_true',
                        help="each churn process echoes one message of the nodes' topics, "
                        'in turn')
    parser.add_argument('--minimal', action='store_true',
                        help="the benchmark's minimal pair in place of the nodes (the floor)")
    parser.add_argument('--thread-priority', type=int, default=None,
                        help="both nodes' thread_priority (default: theirs; 0: normal "
                        'scheduling)')
    parser.add_argument('--out', type=Path, default=Path('results/soak'))
    args = parser.parse_args(argv)
    r = soak(args.duration, args.out, args.load, min(args.report, args.duration),
             churn_s=args.churn, minimal=args.minimal, thread_priority=args.thread_priority,
             echo=args.echo)
    s = r['sim_stats']
    print(f'final ||e|| {r["final_error"]:.3e} (towards the last goal); simulator: '
          f'{s.get("watchdog_trips")} watchdog trips, {s.get("missed_deadlines")} late ticks, '
          f'command latency max {s.get("cmd_latency_us_max", math.nan) / 1e3:.1f} ms')
    print('warnings and errors logged, by cause:' if r['warnings'] else
          'no warnings or errors logged')
    for cause, n in sorted(r['warnings'].items(), key=lambda kv: -kv[1]):
        print(f'  {n:6d} x {cause}')
    (args.out / 'soak.json').write_text(json.dumps(r, indent=1))
    return 0


if __name__ == '__main__':
    sys.exit(main())
