"""
Goal-flood benchmark: goals must never delay a control tick.

Starts ``wrist_sim_node`` (real time, 1 kHz) and ``controller_node`` as separate processes on a
private loopback graph, lets them run, then publishes ``--rate`` goals per second on
``/quat_jt_controller/target_pose`` for ``--duration`` seconds. The goals are singular (rotations
about z that the wrist reaches only at q2 = 0, the costliest case for the A1/A2 check) and each
one differs from the last, so every goal is a new goal to validate, log and check. Meanwhile
this process records the arrival time of every effort command and prints, over the flood:

* commands per second in each 0.25 s window (the lowest window is the figure);
* the largest gap between two consecutive commands.

Targets (regulator-core issue): >= 990 commands/s in every 0.25 s window, no gap above 5 ms.
The times are taken where the commands arrive, in this process, which also publishes the flood:
its own scheduling delays count against the figures, so they are conservative. The same figures
as the simulator applied the commands (its own statistics over the flood's steps,
``loop_stats.fresh_command_figures``) are printed beside them: this process's delays do not
count there.

Each run first sends the flood's first goal and waits until the wrist is at rest there (the
wrist then barely moves during the flood), and each run also measures the same loop there for
the same time with no more goals (the control): what the host gives at that moment. A figure
short of the target by as much in the control is the host's.

It runs the product config (``config/wrist_controller.yaml``, what a user gets) and then the
paper's (``config/paper_wrist_controller.yaml``).

    python -m experiments.goal_flood [--rate 1000] [--duration 3] [--invalid]
"""
import argparse
import math
from pathlib import Path
import sys
import time
from typing import Optional

from experiments import local_ros
from experiments.probe import ProbeNode
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

CONTROLLER = 'quat_jt_controller'
WINDOW_S = 0.25
TARGET_RATE_HZ = 990.0
TARGET_GAP_MS = 5.0
FIRST_ANGLE_RAD = 0.8  # the flood's goals are Rz(0.8 + 1e-4 k)


def flood(rate_hz: float, duration_s: float, out: Path, invalid: bool = False,
          warmup_s: float = 2.0, config: str = local_ros.PAPER_CONTROLLER_CONFIG) -> dict:
    """Run the flood; return the figures (per-window rates, largest gap, counts)."""
    pair = local_ros.spawn_recorded_pair(
        out, sim_params={'stats_window_steps': int(duration_s * 1000)},
        controller_config=config)
    sim, ctrl = pair.sim, pair.controller
    probe = ProbeNode('goal_flood', pair.domain_id)
    arrivals: list[float] = []
    clock = time.perf_counter
    probe.node.create_subscription(Float64MultiArray, '/effort_controller/commands',
                                   lambda _: arrivals.append(clock()), 100, raw=True)
    pub = probe.node.create_publisher(PoseStamped, f'/{CONTROLLER}/target_pose', 100)
    speeds: list[float] = [math.inf]
    probe.node.create_subscription(JointState, '/joint_states', lambda m: speeds.__setitem__(
        0, max(map(abs, m.velocity), default=math.inf)), 10)
    goal = PoseStamped()
    goal.header.frame_id = 'base_link'

    def send(angle: float) -> None:
        o = goal.pose.orientation  # Rz(angle): singular for the wrist (q2 = 0)
        o.x, o.y, o.z, o.w = 0.0, 0.0, math.sin(angle / 2), math.cos(angle / 2)
        if invalid:
            o.w = math.nan
        pub.publish(goal)

    def spin_until(condition, timeout_s: float, what: str) -> None:
        deadline = time.monotonic() + timeout_s
        while not condition():
            for proc in (sim, ctrl):
                if proc.poll() is not None:
                    raise RuntimeError(f'a node exited ({proc.returncode}) while {what}; logs '
                                       f'in {out}')
            if time.monotonic() > deadline:
                raise TimeoutError(f'timed out {what}; logs in {out}')
            probe.executor.spin_once(timeout_sec=0.01)

    try:
        spin_until(lambda: len(arrivals) > 200 and pub.get_subscription_count() > 0, 60.0,
                   'waiting for the loop to run')
        # The flood's first goal first, in the control run too, until the wrist is at rest
        # there: both measure the loop at the same place, with the wrist still.
        send(FIRST_ANGLE_RAD)
        t_warm = clock() + warmup_s
        spin_until(lambda: clock() > t_warm and speeds[0] < 1e-3, warmup_s + 30.0,
                   'reaching the first goal')
        period = 1.0 / rate_hz if rate_hz > 0.0 else math.inf
        t0 = clock()
        t_end = t0 + duration_s
        next_goal = t0
        sent = 0
        while (now := clock()) < t_end:
            while rate_hz > 0.0 and now >= next_goal:
                send(FIRST_ANGLE_RAD + 1e-4 * sent)  # each goal new, the wrist barely moves
                sent += 1
                next_goal += period
            probe.executor.spin_once(timeout_sec=min(0.01, max(0.0, next_goal - clock())))
        spin_until(lambda: clock() > t_end + 0.05, 1.0, 'collecting the last commands')
    finally:
        sim_stats = pair.stop()
        probe.close()
    during = [t for t in arrivals if t0 <= t < t_end]
    windows = [sum(1 for t in during if t0 + k * WINDOW_S <= t < t0 + (k + 1) * WINDOW_S)
               / WINDOW_S for k in range(int(duration_s / WINDOW_S))]
    gaps_ms = [1e3 * (b - a) for a, b in zip(during, during[1:])]
    return {'goals_sent': sent, 'goal_rate_hz': sent / duration_s,
            'sim_fresh_rate_hz_min': sim_stats.get('fresh_rate_hz_min', math.nan),
            'sim_fresh_gap_ms_max': sim_stats.get('fresh_gap_ms_max', math.nan),
            'commands': len(during), 'window_rates_hz': windows,
            'min_window_rate_hz': min(windows) if windows else 0.0,
            'max_gap_ms': max(gaps_ms) if gaps_ms else math.inf,
            'controller_log': str(out / 'controller_node.log')}


def main(argv: Optional[list] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--rate', type=float, default=1000.0, help='goals per second')
    parser.add_argument('--duration', type=float, default=3.0, help='seconds of flood')
    parser.add_argument('--invalid', action='store_true', help='NaN goals instead')
    parser.add_argument('--out', type=Path, default=Path('results/goal_flood'))
    args = parser.parse_args(argv)
    kind = 'NaN' if args.invalid else 'singular, each distinct'
    for config in (local_ros.PRODUCT_CONTROLLER_CONFIG, local_ros.PAPER_CONTROLLER_CONFIG):
        out = args.out / Path(config).stem
        control = flood(0.0, args.duration, out / 'control', config=config)
        r = flood(args.rate, args.duration, out, args.invalid, config=config)
        ok_rate = r['min_window_rate_hz'] >= TARGET_RATE_HZ
        ok_gap = r['max_gap_ms'] <= TARGET_GAP_MS
        lines = Path(r['controller_log']).read_text(errors='replace').count('\n')
        print(f'{config}: goal flood, {r["goals_sent"]} {kind} goals in {args.duration} s '
              f'({r["goal_rate_hz"]:.0f}/s)')
        print(f'  commands during the flood: {r["commands"]}; per {WINDOW_S} s window: '
              + ', '.join(f'{w:.0f}' for w in r['window_rates_hz']) + ' /s')
        print(f'  lowest window {r["min_window_rate_hz"]:.0f} commands/s (target >= '
              f'{TARGET_RATE_HZ:.0f}: {"met" if ok_rate else "NOT met"}); largest gap '
              f'{r["max_gap_ms"]:.2f} ms (target <= {TARGET_GAP_MS}: '
              f'{"met" if ok_gap else "NOT met"})')
        print(f'  as the simulator applied them (its own statistics over the flood): lowest '
              f'window {r["sim_fresh_rate_hz_min"]:.0f} fresh commands/s, largest gap '
              f'{r["sim_fresh_gap_ms_max"]:.2f} ms (control: '
              f'{control["sim_fresh_rate_hz_min"]:.0f}/s, {control["sim_fresh_gap_ms_max"]:.2f} '
              'ms)')
        print(f'  controller log: {lines} lines in all ({r["controller_log"]})')
        print(f'  control, no goals, same duration: lowest window '
              f'{control["min_window_rate_hz"]:.0f} commands/s, largest gap '
              f'{control["max_gap_ms"]:.2f} ms')
    return 0


if __name__ == '__main__':
    sys.exit(main())
