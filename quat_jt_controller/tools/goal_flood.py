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
its own scheduling delays count against the figures, so they are conservative.

Each run also measures the same loop for the same time with no goals (the control): what the
host gives at that moment. A figure short of the target by as much in the control is the host's.

    python -m quat_jt_controller.tools.goal_flood [--rate 1000] [--duration 3] [--invalid]
"""
import argparse
import math
from pathlib import Path
import random
import sys
import time
from typing import Optional

from geometry_msgs.msg import PoseStamped
from quat_jt_controller.tools import local_ros
from quat_jt_controller.tools.probe import ProbeNode
from std_msgs.msg import Float64MultiArray

CONTROLLER = 'quat_jt_controller'
WINDOW_S = 0.25
TARGET_RATE_HZ = 990.0
TARGET_GAP_MS = 5.0


def flood(rate_hz: float, duration_s: float, out: Path, invalid: bool = False,
          warmup_s: float = 2.0) -> dict:
    """Run the flood; return the figures (per-window rates, largest gap, counts)."""
    out.mkdir(parents=True, exist_ok=True)
    domain_id = random.randint(1, 100)
    env = local_ros.isolated_env(out, domain_id)
    sim, ctrl = local_ros.spawn_wrist_pair(env, out)
    probe = ProbeNode('goal_flood', domain_id)
    arrivals: list[float] = []
    clock = time.perf_counter
    probe.node.create_subscription(Float64MultiArray, '/effort_controller/commands',
                                   lambda _: arrivals.append(clock()), 100, raw=True)
    pub = probe.node.create_publisher(PoseStamped, f'/{CONTROLLER}/target_pose', 100)
    goal = PoseStamped()
    goal.header.frame_id = 'base_link'

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
        t_warm = clock() + warmup_s
        spin_until(lambda: clock() > t_warm, warmup_s + 5.0, 'warming up')
        period = 1.0 / rate_hz if rate_hz > 0.0 else math.inf
        t0 = clock()
        t_end = t0 + duration_s
        next_goal = t0
        sent = 0
        while (now := clock()) < t_end:
            while rate_hz > 0.0 and now >= next_goal:
                angle = 0.8 + 1e-4 * sent  # Rz(angle): singular for the wrist (q2 = 0)
                o = goal.pose.orientation
                o.x, o.y, o.z, o.w = 0.0, 0.0, math.sin(angle / 2), math.cos(angle / 2)
                if invalid:
                    o.w = math.nan
                pub.publish(goal)
                sent += 1
                next_goal += period
            probe.executor.spin_once(timeout_sec=min(0.01, max(0.0, next_goal - clock())))
        spin_until(lambda: clock() > t_end + 0.05, 1.0, 'collecting the last commands')
    finally:
        for proc in (sim, ctrl):
            local_ros.stop_node(proc)
        probe.close()
    during = [t for t in arrivals if t0 <= t < t_end]
    windows = [sum(1 for t in during if t0 + k * WINDOW_S <= t < t0 + (k + 1) * WINDOW_S)
               / WINDOW_S for k in range(int(duration_s / WINDOW_S))]
    gaps_ms = [1e3 * (b - a) for a, b in zip(during, during[1:])]
    return {'goals_sent': sent, 'goal_rate_hz': sent / duration_s,
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
    control = flood(0.0, args.duration, args.out / 'control')
    r = flood(args.rate, args.duration, args.out, args.invalid)
    kind = 'NaN' if args.invalid else 'singular, each distinct'
    ok_rate = r['min_window_rate_hz'] >= TARGET_RATE_HZ
    ok_gap = r['max_gap_ms'] <= TARGET_GAP_MS
    lines = Path(r['controller_log']).read_text(errors='replace').count('\n')
    print(f'goal flood: {r["goals_sent"]} {kind} goals in {args.duration} s '
          f'({r["goal_rate_hz"]:.0f}/s)')
    print(f'commands during the flood: {r["commands"]}; per {WINDOW_S} s window: '
          + ', '.join(f'{w:.0f}' for w in r['window_rates_hz']) + ' /s')
    print(f'lowest window {r["min_window_rate_hz"]:.0f} commands/s (target >= '
          f'{TARGET_RATE_HZ:.0f}: {"met" if ok_rate else "NOT met"}); largest gap '
          f'{r["max_gap_ms"]:.2f} ms (target <= {TARGET_GAP_MS}: '
          f'{"met" if ok_gap else "NOT met"})')
    print(f'controller log: {lines} lines in all ({r["controller_log"]})')
    print(f'control, no goals, same duration: lowest window {control["min_window_rate_hz"]:.0f} '
          f'commands/s, largest gap {control["max_gap_ms"]:.2f} ms')
    return 0


if __name__ == '__main__':
    sys.exit(main())
