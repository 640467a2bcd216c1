"""
What the loop feels when the goal-check worker dies and is started again.

The controller node polls its ``GoalCheckWorker`` on a 50 ms timer of the executor its 1 kHz
loop runs on; after a worker's death and its back-off, that poll starts the next worker. For
each product config this process runs a 1 kHz loop of sleeps (SCHED_FIFO 50 where permitted,
as the node's executor), polls the worker every 50 ticks, kills the worker, and waits (the
back-off skipped) until the new one answers checks again. Printed, median / worst of the
rounds: the longest ``poll`` on the loop, how late the loop's wake-ups were, worst, from the
kill to the new worker's first answer, the time that took, and how late the loop is over as
long with nothing happening. The row "start on the loop" is the way a worker was started
again before the launcher: ``start_worker`` (a ``Popen``) called from the loop itself.

    python -m experiments.worker_restart_time [--rounds 5]
"""
import argparse
import os
import signal
import statistics
import sys
import time
from typing import Optional

from experiments import reach_experiment as rx
from experiments.redesign_time import loop, loop_scheduling
from quat_jt_controller.control_law import Task
from quat_jt_controller.goal_check import GoalCheckWorker, ModelSpec
from quat_jt_runtime.resources import config_parameters
from quat_jt_runtime.worker import RESTART_BACKOFF_S, start_worker

POLL_TICKS = 50  # the node's goal-check timer: 50 ms
READY_WITHIN_S = 60.0


def spec_of(name: str) -> ModelSpec:
    """Return the goal-check worker's model for a product config."""
    robot = rx.ROBOTS[name]
    values = config_parameters(robot.controller_config)
    return ModelSpec(rx.robot_urdf(robot), values['base_link'], values['tip_link'],
                     tuple(values['joints']), Task(values['task']))


def wait_ready(worker: GoalCheckWorker) -> None:
    """Poll (off any loop) until the worker answers checks."""
    deadline = time.monotonic() + READY_WITHIN_S
    while not worker.ready:
        if time.monotonic() > deadline:
            raise RuntimeError('the goal-check worker did not start')
        worker.poll()
        time.sleep(0.01)


def time_restart(spec: ModelSpec, rounds: int) -> dict:
    """Return per round: the longest poll (s), the worst lateness (s), the time to ready (s)."""
    now = [0.0]
    out = {'poll': [], 'late': [], 'ready': [], 'late_idle': []}
    worker = GoalCheckWorker(spec, clock=lambda: now[0])
    try:
        wait_ready(worker)
        for _ in range(rounds):
            ticks, longest = [0], [0.0]

            def tick() -> bool:
                ticks[0] += 1
                if ticks[0] % POLL_TICKS:
                    return False
                t0 = time.perf_counter()
                worker.poll()
                longest[0] = max(longest[0], time.perf_counter() - t0)
                if not worker.available:  # its death seen: skip the back-off
                    now[0] += RESTART_BACKOFF_S[-1]
                return worker.ready
            t0 = time.perf_counter()
            os.kill(worker.pid, signal.SIGKILL)
            out['late'].append(loop(READY_WITHIN_S, tick))
            out['ready'].append(time.perf_counter() - t0)
            if not worker.ready:
                raise RuntimeError('the goal-check worker did not start again')
            out['poll'].append(longest[0])
            out['late_idle'].append(loop(out['ready'][-1]))
    finally:
        worker.close()
    return out


def time_start_on_loop(rounds: int) -> dict:
    """Return per round: ``start_worker`` on the loop (s), the worst lateness around it (s)."""
    out = {'poll': [], 'late': [], 'ready': [], 'late_idle': []}
    for _ in range(rounds):
        ticks, procs, took = [0], [], [0.0]

        def tick() -> bool:
            ticks[0] += 1
            if ticks[0] == POLL_TICKS:
                t0 = time.perf_counter()
                procs.append(start_worker('quat_jt_controller.goal_check'))
                took[0] = time.perf_counter() - t0
            return ticks[0] >= 4 * POLL_TICKS
        out['late'].append(loop(READY_WITHIN_S, tick))
        out['poll'].append(took[0])
        out['ready'].append(0.0)  # not asked for: the worker gets no model
        for proc in procs:
            proc.stdin.close()  # it ends before its model: nothing sent
            proc.wait()
        out['late_idle'].append(loop(4 * POLL_TICKS * 1e-3))
    return out


def main(argv: Optional[list] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--rounds', type=int, default=5, help='restarts per config')
    args = parser.parse_args(argv)
    print(f'the loop at {loop_scheduling()}; {args.rounds} restarts per config, '
          'median / worst')
    print('| config | longest poll on the loop, ms | loop late from the kill to the first '
          'answer, ms | to the first answer, s | loop late without, ms |')
    print('|---|---|---|---|---|')
    rows = [('start on the loop (before)', lambda: time_start_on_loop(args.rounds))]
    for name in ('wrist', 'xarm6', 'panda'):
        spec = spec_of(name)
        rows.append((rx.ROBOTS[name].controller_config,
                     lambda spec=spec: time_restart(spec, args.rounds)))
    for label, run in rows:
        try:
            t = run()
        except RuntimeError as exc:
            print(f'{label}: {exc}', file=sys.stderr)
            return 1
        cells = [f'{statistics.median(v) * k:.2f} / {max(v) * k:.2f}' for v, k in (
            (t['poll'], 1e3), (t['late'], 1e3), (t['ready'], 1.0), (t['late_idle'], 1e3))]
        if not any(t['ready']):
            cells[2] = '-'
        print(f'| {label} | ' + ' | '.join(cells) + ' |')
    return 0


if __name__ == '__main__':
    sys.exit(main())
